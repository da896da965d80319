//! Routing over the lane graph: shortest edge routes, lane choice along a route and the
//! route centreline through junctions.

use super::model::*;
use super::network::{lane_time, Network};
use crate::geom::{Polyline, Vec2};
use crate::{Error, Result};
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};

/// Lane changes are drawn as a straight ramp of at most this length, centred on the edge.
const LANE_CHANGE_RAMP_M: f64 = 30.0;
/// Guard against malformed internal-lane chains that loop.
const MAX_VIA_CHAIN: usize = 16;

#[derive(PartialEq)]
struct QItem(f64, EdgeIdx);
impl Eq for QItem {}
impl PartialOrd for QItem {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for QItem {
    // Min-heap on cost, ties broken by edge index for determinism.
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.total_cmp(&self.0).then_with(|| o.1.cmp(&self.1))
    }
}

impl Network {
    /// Fastest time to drive edge `e` at the speed limit for class `vc` (`None` if no lane
    /// of the edge allows the class).
    fn edge_time(&self, e: EdgeIdx, vc: VClass) -> Option<f64> {
        self.edges[e]
            .lanes
            .iter()
            .map(|&l| &self.lanes[l])
            .filter(|l| l.allow.contains(vc))
            .map(lane_time)
            .min_by(f64::total_cmp)
    }

    /// Shortest route of normal edges from `from` to `to` (both included) for class `vclass`.
    ///
    /// Dijkstra with cost = travel time at the speed limit (lane length / lane speed of the
    /// fastest lane allowing the class, plus the fastest internal `via` lane), as SUMO's
    /// router does for an empty network. Successors follow connections whose from, via and to
    /// lanes allow the class. `None` if unreachable or if an edge is not a normal edge.
    pub fn edge_route(&self, from: EdgeIdx, to: EdgeIdx, vclass: VClass) -> Option<Vec<EdgeIdx>> {
        let n = self.edges.len();
        if from >= n || to >= n {
            return None;
        }
        if self.edges[from].function != EdgeFunction::Normal
            || self.edges[to].function != EdgeFunction::Normal
        {
            return None;
        }
        let start_cost = self.edge_time(from, vclass)?;
        self.edge_time(to, vclass)?;
        let mut dist = vec![f64::INFINITY; n];
        let mut prev = vec![usize::MAX; n];
        let mut heap = BinaryHeap::new();
        dist[from] = start_cost;
        heap.push(QItem(start_cost, from));
        while let Some(QItem(d, e)) = heap.pop() {
            if d > dist[e] {
                continue;
            }
            if e == to {
                break;
            }
            for &(s, set, via_t) in &self.succ[e] {
                if !set.contains(vclass) {
                    continue;
                }
                let Some(t) = self.edge_time(s, vclass) else { continue };
                let nd = d + via_t + t;
                if nd < dist[s] {
                    dist[s] = nd;
                    prev[s] = e;
                    heap.push(QItem(nd, s));
                }
            }
        }
        if !dist[to].is_finite() {
            return None;
        }
        let mut route = vec![to];
        let mut cur = to;
        while cur != from {
            cur = prev[cur];
            route.push(cur);
        }
        route.reverse();
        Some(route)
    }

    /// Internal lanes crossed by connection `ci`, in driving order (follows chains of internal
    /// lanes through internal junctions). Empty when the connection has no `via`.
    pub fn via_chain(&self, ci: usize) -> Vec<LaneIdx> {
        let c = &self.connections[ci];
        let mut chain = Vec::new();
        let mut cur = c.via;
        while let Some(v) = cur {
            if chain.len() >= MAX_VIA_CHAIN || chain.contains(&v) {
                break;
            }
            chain.push(v);
            cur = self
                .connections_from_lane(v)
                .iter()
                .map(|&k| &self.connections[k])
                .find(|k| k.to_lane == c.to_lane)
                .and_then(|k| k.via);
        }
        chain
    }

    /// [`Network::route_lanes_for`] for passenger cars.
    pub fn route_lanes(&self, edges: &[EdgeIdx], start_lane: Option<LaneIdx>) -> Result<Vec<LaneIdx>> {
        self.route_lanes_for(edges, start_lane, VClass::Passenger)
    }

    /// Lanes driven along a route of consecutive normal edges, internal `via` lanes included.
    ///
    /// Lane choice minimises the number of lane changes over the whole route (dynamic
    /// programming over lanes; ties go to keeping the lane, then to the rightmost lane).
    /// Where a lane change is needed on an edge, the lane arrived on and the lane left from
    /// both appear, consecutively. `start_lane` (if given) must lie on the first edge.
    /// Errors name the edges that are not connected for the class.
    pub fn route_lanes_for(
        &self,
        edges: &[EdgeIdx],
        start_lane: Option<LaneIdx>,
        vclass: VClass,
    ) -> Result<Vec<LaneIdx>> {
        let err = |m: String| Error::map(&self.file, m);
        if edges.is_empty() {
            return Err(err("route has no edges".into()));
        }
        for &e in edges {
            let edge = self.edges.get(e).ok_or_else(|| err(format!("route: edge index {e} out of range")))?;
            if edge.function != EdgeFunction::Normal {
                return Err(err(format!("route: edge \"{}\" is not a normal edge", edge.id)));
            }
            if !edge.lanes.iter().any(|&l| self.lanes[l].allow.contains(vclass)) {
                return Err(err(format!(
                    "route: edge \"{}\" has no lane allowing vehicle class {}",
                    edge.id,
                    vclass.sumo_name()
                )));
            }
        }
        // arrival[lane] = (cost, back pointer: (arrival lane on previous edge, driven lane, connection)).
        type Back = Option<(LaneIdx, LaneIdx, usize)>;
        let mut stages: Vec<Vec<(LaneIdx, f64, Back)>> = Vec::with_capacity(edges.len());
        let first: Vec<(LaneIdx, f64, Back)> = match start_lane {
            Some(l) => {
                let lane =
                    self.lanes.get(l).ok_or_else(|| err(format!("route: lane index {l} out of range")))?;
                if lane.edge != edges[0] {
                    return Err(err(format!(
                        "route: start lane \"{}\" is not on the first edge \"{}\"",
                        lane.id, self.edges[edges[0]].id
                    )));
                }
                vec![(l, 0.0, None)]
            }
            None => self.edges[edges[0]]
                .lanes
                .iter()
                .filter(|&&l| self.lanes[l].allow.contains(vclass))
                .map(|&l| (l, 1e-3 * self.lanes[l].index as f64, None))
                .collect(),
        };
        stages.push(first);
        for w in 0..edges.len() - 1 {
            let (e, next) = (edges[w], edges[w + 1]);
            let mut best: HashMap<LaneIdx, (f64, Back)> = HashMap::new();
            for &(a, ca, _) in &stages[w] {
                let ia = self.lanes[a].index as f64;
                for &b in &self.edges[e].lanes {
                    let lb = &self.lanes[b];
                    if b != a && !lb.allow.contains(vclass) {
                        continue;
                    }
                    let change = (ia - lb.index as f64).abs();
                    for &ci in self.connections_from_lane(b) {
                        let c = &self.connections[ci];
                        let lc = &self.lanes[c.to_lane];
                        if lc.edge != next || !lc.allow.contains(vclass) {
                            continue;
                        }
                        if c.via.is_some_and(|v| !self.lanes[v].allow.contains(vclass)) {
                            continue;
                        }
                        // Tie-breaks: rightmost driven lane, then rightmost arrival lane.
                        let cost = ca + change + 1e-3 * lb.index as f64 + 1e-6 * lc.index as f64;
                        let slot = best.entry(c.to_lane).or_insert((f64::INFINITY, None));
                        if cost < slot.0 {
                            *slot = (cost, Some((a, b, ci)));
                        }
                    }
                }
            }
            if best.is_empty() {
                return Err(err(format!(
                    "route: edge \"{}\" is not connected to edge \"{}\" for vehicle class {}",
                    self.edges[e].id,
                    self.edges[next].id,
                    vclass.sumo_name()
                )));
            }
            let mut stage: Vec<_> = best.into_iter().map(|(l, (c, b))| (l, c, b)).collect();
            stage.sort_by_key(|x| x.0);
            stages.push(stage);
        }
        // Backtrack from the cheapest arrival on the last edge.
        let last = stages.last().map(|s| s.as_slice()).unwrap_or(&[]);
        let mut cur = last
            .iter()
            .min_by(|x, y| x.1.total_cmp(&y.1).then(x.0.cmp(&y.0)))
            .map(|x| x.0)
            .ok_or_else(|| err("route: no lane to start on".into()))?;
        let mut rev: Vec<LaneIdx> = vec![cur];
        for w in (1..stages.len()).rev() {
            let back = stages[w].iter().find(|x| x.0 == cur).and_then(|x| x.2);
            let Some((a, b, ci)) = back else { break };
            for v in self.via_chain(ci).into_iter().rev() {
                rev.push(v);
            }
            rev.push(b);
            if a != b {
                rev.push(a);
            }
            cur = a;
        }
        rev.reverse();
        Ok(rev)
    }

    /// [`Network::route_polyline_for`] for passenger cars.
    pub fn route_polyline(&self, edges: &[EdgeIdx], start_lane: Option<LaneIdx>) -> Result<Polyline> {
        self.route_polyline_for(edges, start_lane, VClass::Passenger)
    }

    /// Centreline of a route: the shapes of [`Network::route_lanes_for`] joined end to end
    /// (through junctions along the internal lanes); a lane change is a straight ramp of up to
    /// 30 m centred on its edge.
    pub fn route_polyline_for(
        &self,
        edges: &[EdgeIdx],
        start_lane: Option<LaneIdx>,
        vclass: VClass,
    ) -> Result<Polyline> {
        let lanes = self.route_lanes_for(edges, start_lane, vclass)?;
        Ok(self.lanes_polyline(&lanes))
    }

    /// Joins lane shapes in order; consecutive lanes of one edge are a lane change.
    pub fn lanes_polyline(&self, lanes: &[LaneIdx]) -> Polyline {
        let mut pts: Vec<Vec2> = Vec::new();
        let mut i = 0;
        while i < lanes.len() {
            let a = &self.lanes[lanes[i]];
            match lanes.get(i + 1).map(|&b| &self.lanes[b]) {
                Some(b) if b.edge == a.edge => {
                    let len = a.shape.length().min(b.shape.length());
                    let ramp = (0.5 * len).min(LANE_CHANGE_RAMP_M);
                    let s1 = 0.5 * (len - ramp);
                    // The slice of `a` before the ramp, then `b` from the end of the ramp.
                    pts.extend_from_slice(a.shape.slice(0.0, s1).points());
                    pts.extend_from_slice(b.shape.slice(s1 + ramp, b.shape.length()).points());
                    i += 2;
                }
                _ => {
                    pts.extend_from_slice(a.shape.points());
                    i += 1;
                }
            }
        }
        Polyline::new(pts)
    }
}
