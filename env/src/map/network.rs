//! [`Network`]: the parsed net plus the lookup tables built once at load time.
//!
//! `Network` owns its [`DrivableIndex`] (built once at load, read through
//! [`Network::drivable`]) so the index can never be out of step with the lanes it was built
//! from, and every user gets it with the net. The dependency still runs one way: the index is built from
//! the edge/lane/junction tables, never from `Network`; and the edge successor table that
//! routing reads is built here, so `route` (the routing methods on `Network`) depends on this
//! module and not the other way round.

use super::drivable::DrivableIndex;
use super::model::*;
use super::parse::{self, line_of, RawNet};
use crate::geom::{Aabb, Pose, Projection, Vec2};
use crate::{Error, Result};
use std::collections::{HashMap, HashSet};
use std::path::Path;

/// A SUMO road network with id lookups, the lane graph and the drivable-area index.
#[derive(Debug, Clone)]
pub struct Network {
    /// The file it was read from (as given).
    pub file: String,
    pub edges: Vec<Edge>,
    pub lanes: Vec<Lane>,
    pub junctions: Vec<Junction>,
    /// Unique connections (exact duplicates in the file are dropped).
    pub connections: Vec<Connection>,
    /// Every program in file order (a light may have several; the first one is the default).
    pub tl_logics: Vec<TlLogic>,
    pub roundabouts: Vec<Roundabout>,
    pub location: Location,
    edge_ids: HashMap<String, EdgeIdx>,
    lane_ids: HashMap<String, LaneIdx>,
    junction_ids: HashMap<String, JunctionIdx>,
    /// Connection indices grouped by from-lane / to-lane (CSR layout).
    from_off: Vec<usize>,
    from_list: Vec<usize>,
    to_off: Vec<usize>,
    to_list: Vec<usize>,
    tl_links: HashMap<String, Vec<TlLink>>,
    /// Successor normal edges of each normal edge: (edge, classes allowed through, via time).
    pub(crate) succ: Vec<Vec<(EdgeIdx, VClassSet, f64)>>,
    bounds: Aabb,
    drivable: DrivableIndex,
}

impl Network {
    /// Reads a SUMO `.net.xml` or gzip-compressed `.net.xml.gz`.
    pub fn from_file(path: &Path) -> Result<Network> {
        if !path.exists() {
            return Err(Error::map(path, "network file not found"));
        }
        let text = parse::read_text(path)?;
        Self::from_xml_str(path, &text)
    }

    /// Parses network XML held in memory; `origin` names it in error messages.
    pub fn from_xml_str(origin: &Path, text: &str) -> Result<Network> {
        let raw = parse::parse_net(origin, text)?;
        Self::build(origin, text, raw)
    }

    fn build(path: &Path, text: &str, raw: RawNet) -> Result<Network> {
        let RawNet {
            mut edges,
            edge_from_to,
            mut lanes,
            mut junctions,
            junction_lanes,
            connections: raw_conns,
            tl_logics,
            roundabouts: raw_rb,
            location,
        } = raw;
        let err = |msg: String| Error::map(path, msg);

        let mut edge_ids = HashMap::with_capacity(edges.len());
        for (i, e) in edges.iter().enumerate() {
            if edge_ids.insert(e.id.clone(), i).is_some() {
                return Err(err(format!("duplicate edge id \"{}\"", e.id)));
            }
        }
        let mut lane_ids = HashMap::with_capacity(lanes.len());
        for (i, l) in lanes.iter().enumerate() {
            if lane_ids.insert(l.id.clone(), i).is_some() {
                return Err(err(format!("duplicate lane id \"{}\"", l.id)));
            }
        }
        let mut junction_ids = HashMap::with_capacity(junctions.len());
        for (i, j) in junctions.iter().enumerate() {
            if junction_ids.insert(j.id.clone(), i).is_some() {
                return Err(err(format!("duplicate junction id \"{}\"", j.id)));
            }
        }

        // Lanes of each edge in index order; indices must be 0..n so `fromLane` can address them.
        for e in edges.iter_mut() {
            e.lanes.sort_by_key(|&l| lanes[l].index);
            for (k, &l) in e.lanes.iter().enumerate() {
                if lanes[l].index != k {
                    return Err(err(format!(
                        "edge \"{}\" lane \"{}\": attribute index = \"{}\": lane indices must be 0..{}",
                        e.id,
                        lanes[l].id,
                        lanes[l].index,
                        e.lanes.len()
                    )));
                }
            }
        }

        for (i, (from, to)) in edge_from_to.iter().enumerate() {
            let resolve = |key: &str, id: &Option<String>| -> Result<Option<JunctionIdx>> {
                match id {
                    None => Ok(None),
                    Some(j) => junction_ids.get(j).copied().map(Some).ok_or_else(|| {
                        err(format!("edge \"{}\": attribute {key} = \"{j}\": no such junction", edges[i].id))
                    }),
                }
            };
            let f = resolve("from", from)?;
            let t = resolve("to", to)?;
            edges[i].from = f;
            edges[i].to = t;
        }

        for (ji, (inc, int)) in junction_lanes.iter().enumerate() {
            let resolve = |key: &str, list: &str| -> Result<Vec<LaneIdx>> {
                list.split_ascii_whitespace()
                    .map(|id| {
                        lane_ids.get(id).copied().ok_or_else(|| {
                            err(format!(
                                "junction \"{}\": attribute {key}: lane \"{id}\" does not exist",
                                junctions[ji].id
                            ))
                        })
                    })
                    .collect()
            };
            let inc = resolve("incLanes", inc)?;
            let int = resolve("intLanes", int)?;
            for &l in &int {
                edges[lanes[l].edge].junction = Some(ji);
            }
            junctions[ji].inc_lanes = inc;
            junctions[ji].int_lanes = int;
        }
        // Internal edges not listed in intLanes, crossings and walking areas: ":<junction>_<n>".
        for e in edges.iter_mut() {
            if e.function != EdgeFunction::Normal && e.junction.is_none() {
                if let Some(stripped) = e.id.strip_prefix(':') {
                    if let Some(k) = stripped.rfind('_') {
                        e.junction = junction_ids.get(&stripped[..k]).copied();
                    }
                }
            }
        }

        // Connections: resolve, drop exact duplicates.
        let mut connections: Vec<Connection> = Vec::with_capacity(raw_conns.len());
        let mut seen: HashSet<(LaneIdx, LaneIdx, Option<LaneIdx>)> = HashSet::with_capacity(raw_conns.len());
        for rc in &raw_conns {
            let what = || {
                format!("line {}: connection from \"{}\" to \"{}\"", line_of(text, rc.pos), rc.from, rc.to)
            };
            let lane_of = |key: &str, edge: &str, key_lane: &str, idx: usize| -> Result<LaneIdx> {
                let ei = *edge_ids
                    .get(edge)
                    .ok_or_else(|| err(format!("{}: attribute {key} = \"{edge}\": no such edge", what())))?;
                edges[ei].lanes.get(idx).copied().ok_or_else(|| {
                    err(format!(
                        "{}: attribute {key_lane} = \"{idx}\": edge \"{edge}\" has {} lane(s)",
                        what(),
                        edges[ei].lanes.len()
                    ))
                })
            };
            let from_lane = lane_of("from", &rc.from, "fromLane", rc.from_lane)?;
            let to_lane = lane_of("to", &rc.to, "toLane", rc.to_lane)?;
            let via = match &rc.via {
                None => None,
                Some(v) => Some(
                    *lane_ids
                        .get(v)
                        .ok_or_else(|| err(format!("{}: attribute via = \"{v}\": no such lane", what())))?,
                ),
            };
            if !seen.insert((from_lane, to_lane, via)) {
                continue;
            }
            connections.push(Connection {
                from_lane,
                to_lane,
                via,
                tl: rc.tl.clone(),
                link_index: rc.link_index,
                dir: rc.dir,
                state: rc.state,
            });
        }
        let (from_off, from_list) = csr(lanes.len(), connections.iter().map(|c| c.from_lane));
        let (to_off, to_list) = csr(lanes.len(), connections.iter().map(|c| c.to_lane));

        let mut tl_links: HashMap<String, Vec<TlLink>> = HashMap::new();
        for c in &connections {
            if let (Some(tl), Some(li)) = (&c.tl, c.link_index) {
                tl_links.entry(tl.clone()).or_default().push(TlLink {
                    link_index: li,
                    from_lane: c.from_lane,
                    to_lane: c.to_lane,
                    via: c.via,
                });
            }
        }
        for v in tl_links.values_mut() {
            v.sort_by_key(|l| (l.link_index, l.from_lane, l.to_lane));
        }

        let mut roundabouts = Vec::with_capacity(raw_rb.len());
        for (nodes, redges) in &raw_rb {
            let nodes = nodes
                .split_ascii_whitespace()
                .map(|id| {
                    junction_ids.get(id).copied().ok_or_else(|| {
                        err(format!("roundabout: attribute nodes: junction \"{id}\" does not exist"))
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            let redges = redges
                .split_ascii_whitespace()
                .map(|id| {
                    edge_ids.get(id).copied().ok_or_else(|| {
                        err(format!("roundabout: attribute edges: edge \"{id}\" does not exist"))
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            roundabouts.push(Roundabout { nodes, edges: redges });
        }

        // Keep lane length sane when the attribute disagrees wildly with a degenerate shape.
        for l in lanes.iter_mut() {
            if l.length_m.is_nan() || l.length_m < 0.0 {
                l.length_m = l.shape.length();
            }
        }

        let mut bounds = Aabb::EMPTY;
        for l in &lanes {
            for p in l.shape.points() {
                bounds.include(*p);
            }
        }
        for j in &junctions {
            bounds.include(j.pos);
            for p in &j.shape {
                bounds.include(*p);
            }
        }

        let mut net = Network {
            file: path.display().to_string(),
            edges,
            lanes,
            junctions,
            connections,
            tl_logics,
            roundabouts,
            location,
            edge_ids,
            lane_ids,
            junction_ids,
            from_off,
            from_list,
            to_off,
            to_list,
            tl_links,
            succ: Vec::new(),
            bounds,
            drivable: DrivableIndex::default(),
        };
        net.succ = successors(&net);
        net.drivable = DrivableIndex::build(&net.edges, &net.lanes, &net.junctions);
        Ok(net)
    }

    pub fn edge_by_id(&self, id: &str) -> Option<EdgeIdx> {
        self.edge_ids.get(id).copied()
    }
    pub fn lane_by_id(&self, id: &str) -> Option<LaneIdx> {
        self.lane_ids.get(id).copied()
    }
    pub fn junction_by_id(&self, id: &str) -> Option<JunctionIdx> {
        self.junction_ids.get(id).copied()
    }
    /// Indices into [`Network::connections`] leaving `lane` (empty for an unknown index).
    pub fn connections_from_lane(&self, lane: LaneIdx) -> &[usize] {
        match (self.from_off.get(lane), self.from_off.get(lane + 1)) {
            (Some(&a), Some(&b)) => &self.from_list[a..b],
            _ => &[],
        }
    }
    /// Indices into [`Network::connections`] arriving on `lane`.
    pub fn connections_to_lane(&self, lane: LaneIdx) -> &[usize] {
        match (self.to_off.get(lane), self.to_off.get(lane + 1)) {
            (Some(&a), Some(&b)) => &self.to_list[a..b],
            _ => &[],
        }
    }
    /// Bounding box of every lane shape and junction outline.
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }
    /// The drivable-area index (built at load time).
    pub fn drivable(&self) -> &DrivableIndex {
        &self.drivable
    }
    /// Function of the edge a lane belongs to.
    pub fn lane_function(&self, lane: LaneIdx) -> EdgeFunction {
        self.edges[self.lanes[lane].edge].function
    }
    /// Pose at the end of the lane shape (where vehicles stop), heading of its last segment.
    /// Lane indices come from this network; an out-of-range index panics like slice indexing.
    pub fn stop_line(&self, lane: LaneIdx) -> Pose {
        let sh = &self.lanes[lane].shape;
        let s = sh.length();
        Pose::new(sh.point_at(s), sh.heading_at(s))
    }
    /// Pose on the lane centreline at arc length `s` (clamped to the shape).
    pub fn lane_position(&self, lane: LaneIdx, s: f64) -> Pose {
        let sh = &self.lanes[lane].shape;
        Pose::new(sh.point_at(s), sh.heading_at(s))
    }
    /// Normal edges reached from normal edge `e` by a connection (for any class), sorted by
    /// index; empty for other edges.
    pub fn successors(&self, e: EdgeIdx) -> impl Iterator<Item = EdgeIdx> + '_ {
        self.succ.get(e).into_iter().flatten().map(|&(to, _, _)| to)
    }
    /// The lane whose centreline passes nearest to `p` within `max_dist` (metres), with the
    /// projection on it: only lanes allowing `class` when given, junction-internal lanes only
    /// when `internal`. Ties go to the lane listed first in the file.
    pub fn nearest_lane(
        &self,
        p: Vec2,
        max_dist: f64,
        class: Option<VClass>,
        internal: bool,
    ) -> Option<(LaneIdx, Projection)> {
        let mut best: Option<(LaneIdx, Projection)> = None;
        for (i, lane) in self.lanes.iter().enumerate() {
            if class.is_some_and(|c| !lane.allow.contains(c))
                || (!internal && self.edges[lane.edge].function == EdgeFunction::Internal)
            {
                continue;
            }
            if let Some(pr) = lane.shape.project(p) {
                if pr.distance <= max_dist && best.is_none_or(|(_, b)| pr.distance < b.distance) {
                    best = Some((i, pr));
                }
            }
        }
        best
    }
    /// Ids of every traffic light that controls at least one connection, sorted.
    pub fn tl_ids(&self) -> Vec<&str> {
        let mut ids: Vec<&str> = self.tl_links.keys().map(String::as_str).collect();
        ids.sort_unstable();
        ids
    }
    /// Links controlled by traffic light `tl`, sorted by link index (empty if unknown).
    pub fn tl_links(&self, tl: &str) -> &[TlLink] {
        self.tl_links.get(tl).map(Vec::as_slice).unwrap_or(&[])
    }
    /// The first (default) program of traffic light `tl`.
    pub fn tl_logic(&self, tl: &str) -> Option<&TlLogic> {
        self.tl_logics.iter().find(|t| t.id == tl)
    }
}

/// Travel time of a lane at its speed limit (0.1 m/s floor keeps it finite).
pub(super) fn lane_time(l: &Lane) -> f64 {
    l.length_m / l.speed_mps.max(0.1)
}

/// Per normal edge: successor normal edges, the classes able to make that move (from lane,
/// first via lane and to lane all allow them) and the fastest via travel time.
fn successors(net: &Network) -> Vec<Vec<(EdgeIdx, VClassSet, f64)>> {
    let mut out = vec![Vec::new(); net.edges.len()];
    for (ei, e) in net.edges.iter().enumerate() {
        if e.function != EdgeFunction::Normal {
            continue;
        }
        let mut acc: HashMap<EdgeIdx, (VClassSet, f64)> = HashMap::new();
        for &l in &e.lanes {
            for &ci in net.connections_from_lane(l) {
                let c = &net.connections[ci];
                let to_edge = net.lanes[c.to_lane].edge;
                if net.edges[to_edge].function != EdgeFunction::Normal {
                    continue;
                }
                let mut set = net.lanes[l].allow.intersect(net.lanes[c.to_lane].allow);
                let mut t = 0.0;
                if let Some(v) = c.via {
                    set = set.intersect(net.lanes[v].allow);
                    t = lane_time(&net.lanes[v]);
                }
                let entry = acc.entry(to_edge).or_insert((VClassSet::NONE, f64::INFINITY));
                entry.0 = VClassSet(entry.0 .0 | set.0);
                entry.1 = entry.1.min(t);
            }
        }
        let mut v: Vec<_> = acc.into_iter().map(|(k, (s, t))| (k, s, t)).collect();
        v.sort_by_key(|x| x.0);
        out[ei] = v;
    }
    out
}

/// Groups item indices by key into offsets + flat list.
fn csr(n: usize, keys: impl Iterator<Item = usize> + Clone) -> (Vec<usize>, Vec<usize>) {
    let mut off = vec![0usize; n + 1];
    for k in keys.clone() {
        off[k + 1] += 1;
    }
    for i in 0..n {
        off[i + 1] += off[i];
    }
    let mut fill = off.clone();
    let mut list = vec![0usize; off[n]];
    for (i, k) in keys.enumerate() {
        list[fill[k]] = i;
        fill[k] += 1;
    }
    (off, list)
}
