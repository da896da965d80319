//! The `idm` traffic mode: reactive background traffic without SUMO, the `[traffic]` demand
//! driven by the Intelligent Driver Model along the lane graph (see `docs/traffic.md`, "IDM mode").
//!
//! Per tick (0.05 s), for each vehicle in key order:
//! * the nearest obstacle on its path ahead: other traffic, the scenario's actors, the ego (any
//!   body whose centre lies within the two half widths of the path, found on the path's local
//!   tangent), a red (or stoppable yellow) light's stop line, or a junction it must not enter yet
//!   (a vehicle on a crossing path inside it, or — on a minor link — one approaching it);
//! * IDM acceleration towards min(vType maxSpeed, speedFactor × lane speed) with that gap;
//! * semi-implicit Euler; the pose is the path point with a chord-smoothed heading.
//!
//! Deterministic: fixed iteration orders, the demand's seeded generator, no hash maps.

use super::lights::LightState;
use super::traffic::{TrafficAgent, TrafficFrame, TrafficInput, TrafficModel, SIGNAL_BRAKELIGHT};
use crate::geom::{Obb, Polyline, Pose, Vec2};
use crate::map::{EdgeFunction, JunctionIdx, LaneIdx, Network, VClass};
use crate::scenario::traffic::{DemandVehicle, FlowRate, LaneChoice, SpeedChoice, SplitMix, TrafficDemand};
use crate::scenario::{ResolvedScenario, PALETTE};
use crate::view::LightColor;
use crate::{Result, DT_S};
use std::sync::Arc;

/// Obstacles farther than this along the path are ignored, m.
const LOOKAHEAD_M: f64 = 80.0;
/// Bodies this close are also searched for along the path (bends), m.
const BEND_SEARCH_M: f64 = 30.0;
/// Junction checks start this far before the stop line, m.
const JUNCTION_LOOKAHEAD_M: f64 = 30.0;
/// On a minor link, vehicles this close to the junction (and moving) have the right of way, m.
const MINOR_YIELD_RADIUS_M: f64 = 30.0;
/// Hardest deceleration IDM may command, m/s².
const EMERGENCY_DECEL_MPS2: f64 = 9.0;

#[derive(Debug, Clone, Copy, PartialEq)]
enum StopKind {
    Light { link: usize, tl: usize },
    Junction { junction: JunctionIdx, minor: bool, exit_s: f64 },
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Stop {
    /// Arc length of the stop line on the path.
    s: f64,
    kind: StopKind,
}

#[derive(Debug)]
struct Route {
    path: Polyline,
    /// Arc length at each point of `path`.
    cum: Vec<f64>,
    /// (end arc length, lane) along the path.
    lanes: Vec<(f64, LaneIdx)>,
    stops: Vec<Stop>,
}

impl Route {
    fn build(map: &Network, lanes: &[LaneIdx], tl_ids: &[String]) -> Route {
        let path = map.lanes_polyline(lanes);
        let mut ends = Vec::with_capacity(lanes.len());
        let mut stops = Vec::new();
        let mut s = 0.0;
        let mut i = 0;
        while i < lanes.len() {
            let a = lanes[i];
            // A lane change on one edge appears as two consecutive lanes: one stretch.
            let skip_pair = lanes.get(i + 1).is_some_and(|&b| map.lanes[b].edge == map.lanes[a].edge);
            let lane = if skip_pair { lanes[i + 1] } else { a };
            s += map.lanes[lane].length_m;
            ends.push((s, lane));
            let next = if skip_pair { i + 2 } else { i + 1 };
            if let Some(&b) = lanes.get(next) {
                let internal = map.edges[map.lanes[b].edge].function == EdgeFunction::Internal;
                if internal && map.lane_function(lane) == EdgeFunction::Normal {
                    let conn = map
                        .connections_from_lane(lane)
                        .iter()
                        .map(|&c| &map.connections[c])
                        .find(|c| c.via == Some(b));
                    // Exit: the end of the chain of internal lanes.
                    let mut exit = s;
                    let mut k = next;
                    while let Some(&l) = lanes.get(k) {
                        if map.edges[map.lanes[l].edge].function != EdgeFunction::Internal {
                            break;
                        }
                        exit += map.lanes[l].length_m;
                        k += 1;
                    }
                    if let Some(c) = conn {
                        if let (Some(tl), Some(link)) = (&c.tl, c.link_index) {
                            if let Some(ti) = tl_ids.iter().position(|t| t == tl) {
                                stops.push(Stop { s, kind: StopKind::Light { link, tl: ti } });
                            }
                        }
                        if let Some(j) = map.edges[map.lanes[b].edge].junction {
                            let minor = matches!(c.state, 'm' | '=' | 's' | 'w' | 'g');
                            stops.push(Stop {
                                s,
                                kind: StopKind::Junction { junction: j, minor, exit_s: exit },
                            });
                        }
                    }
                }
            }
            i = next;
        }
        let mut cum = Vec::with_capacity(path.points().len());
        let mut acc = 0.0;
        for (k, p) in path.points().iter().enumerate() {
            if k > 0 {
                acc += p.dist(path.points()[k - 1]);
            }
            cum.push(acc);
        }
        Route { path, cum, lanes: ends, stops }
    }

    /// Arc length and distance of the point of the path within [s0, s0 + window] closest to `p`
    /// (for bodies around a bend, where the local tangent misses them).
    fn project_ahead(&self, p: Vec2, s0: f64, window: f64) -> Option<(f64, f64)> {
        let pts = self.path.points();
        let k0 = self.cum.partition_point(|&c| c <= s0).saturating_sub(1);
        let mut best: Option<(f64, f64)> = None;
        for k in k0..pts.len().saturating_sub(1) {
            if self.cum[k] > s0 + window {
                break;
            }
            let (t, d2) = crate::geom::closest_on_segment(p, pts[k], pts[k + 1]);
            let s = self.cum[k] + t * (self.cum[k + 1] - self.cum[k]);
            if s >= s0 && best.is_none_or(|(_, bd)| d2 < bd) {
                best = Some((s, d2));
            }
        }
        best.map(|(s, d2)| (s, d2.sqrt()))
    }

    fn lane_at(&self, s: f64) -> LaneIdx {
        let i = self.lanes.partition_point(|&(end, _)| end < s).min(self.lanes.len().saturating_sub(1));
        self.lanes[i].1
    }
}

#[derive(Debug)]
struct Veh {
    key: u64,
    vtype: usize,
    route: Arc<Route>,
    /// Arc length of the centre.
    s: f64,
    v: f64,
    braking: bool,
    pose: Pose,
}

#[derive(Debug, Clone)]
struct FlowState {
    next_s: f64,
    count: u32,
}

/// The `idm` reactive traffic model.
#[derive(Debug)]
pub struct IdmTraffic {
    map: Arc<Network>,
    /// The demand of the running episode (`canonical` varied by the episode seed).
    demand: TrafficDemand,
    canonical: TrafficDemand,
    ego_start: Vec2,
    tl_ids: Vec<String>,
    lights: LightState,
    vehicles: Vec<Veh>,
    /// Vehicles waiting to depart (explicit and random), sorted by departure time.
    pending: Vec<DemandVehicle>,
    flows: Vec<FlowState>,
    rng: SplitMix,
    next_key: u64,
    time_s: f64,
    bodies: Vec<(Vec2, f64, f64, f64)>,
}

impl IdmTraffic {
    pub fn new(scenario: &ResolvedScenario) -> Result<IdmTraffic> {
        let map = scenario.map.clone();
        Ok(IdmTraffic {
            tl_ids: map.tl_ids().into_iter().map(str::to_string).collect(),
            lights: LightState::with_programs(&map, &scenario.lights),
            demand: scenario.traffic.clone(),
            canonical: scenario.traffic.clone(),
            ego_start: scenario.ego.start.pos,
            map,
            vehicles: Vec::new(),
            pending: Vec::new(),
            flows: Vec::new(),
            rng: SplitMix::new(0),
            next_key: 0,
            time_s: 0.0,
            bodies: Vec::new(),
        })
    }

    fn route_for(&self, v: &DemandVehicle) -> Option<Route> {
        let vc = self.demand.vtypes[v.vtype].vclass;
        let start = match v.depart_lane {
            LaneChoice::Index(i) => self.map.edges[v.edges[0]].lanes.get(i as usize).copied(),
            LaneChoice::Named(_) => None,
        };
        let lanes = self.map.route_lanes_for(&v.edges, start, vc).ok()?;
        Some(Route::build(&self.map, &lanes, &self.tl_ids))
    }

    /// Departs every due vehicle whose departure spot is free (others wait, in order).
    /// `ego` = (pose, length, width, speed).
    fn depart(&mut self, ego: (Pose, f64, f64, f64), actors: &[crate::view::ActorView]) {
        let t = self.time_s;
        // Flows produce pending vehicles as their departure times come.
        for (fi, f) in self.demand.flows.iter().enumerate() {
            let st = &mut self.flows[fi];
            while st.next_s <= t + 1e-9 && st.next_s < f.end_s && f.number.is_none_or(|n| st.count < n) {
                let due = st.next_s;
                let go = match f.rate {
                    FlowRate::PerHour(vph) => {
                        st.next_s += 3600.0 / vph;
                        true
                    }
                    FlowRate::Probability(p) => {
                        st.next_s += 1.0;
                        self.rng.unit() < p
                    }
                };
                if go {
                    st.count += 1;
                    self.pending.push(DemandVehicle {
                        id: format!("{}.{}", f.id, st.count - 1),
                        vtype: f.vtype,
                        edges: f.edges.clone(),
                        depart_s: due,
                        depart_lane: f.depart_lane.clone(),
                        depart_pos_m: f.depart_pos_m,
                        depart_speed: f.depart_speed.clone(),
                        speed_factor: f.speed_factor,
                    });
                }
            }
        }
        let mut i = 0;
        while i < self.pending.len() {
            if self.pending[i].depart_s > t + 1e-9 {
                i += 1;
                continue;
            }
            let d = &self.pending[i];
            let Some(route) = self.route_for(d) else {
                self.pending.remove(i); // unroutable for its class: dropped, as SUMO does
                continue;
            };
            let vt = &self.demand.vtypes[d.vtype];
            let s = d.depart_pos_m.unwrap_or(0.0).max(0.5 * vt.length_m).min(route.path.length());
            let pose = path_pose(&route.path, s, vt.length_m);
            let clear = vt.length_m + vt.min_gap_m;
            // As SUMO does, a vehicle is inserted only where its body (with its minimum gap
            // all round) is free of the ego, the scenario's actors and other traffic; else it
            // waits for the space.
            let me = Obb {
                pose,
                half_length: 0.5 * vt.length_m + vt.min_gap_m,
                half_width: 0.5 * vt.width_m + 0.3,
            };
            let overlaps = |c: Vec2, yaw: f64, l: f64, w: f64| {
                me.overlaps(&Obb { pose: Pose::new(c, yaw), half_length: 0.5 * l, half_width: 0.5 * w })
            };
            let blocked = pose.pos.dist(ego.0.pos) < clear + 2.5
                || overlaps(ego.0.pos, ego.0.yaw, ego.1, ego.2)
                || actors.iter().any(|a| overlaps(a.pose.pos, a.pose.yaw, a.length_m, a.width_m))
                || self.vehicles.iter().any(|o| {
                    let t = &self.demand.vtypes[o.vtype];
                    o.pose.pos.dist(pose.pos) < clear + 0.5 * t.length_m
                        || overlaps(o.pose.pos, o.pose.yaw, t.length_m, t.width_m)
                });
            if blocked {
                i += 1;
                continue;
            }
            let lane = route.lane_at(s);
            let v0 = desired_speed(vt.max_speed_mps, vt.speed_factor, self.map.lanes[lane].speed_mps);
            let v = match d.depart_speed {
                SpeedChoice::Value(x) => x.min(v0),
                SpeedChoice::Named(ref n) if n == "random" => self.rng.unit() * v0,
                SpeedChoice::Named(_) => v0,
            };
            // Never faster than it can stop behind whatever stands ahead on its path.
            let bodies = std::iter::once((ego.0, ego.1, ego.2, ego.3))
                .chain(actors.iter().map(|a| (a.pose, a.length_m, a.width_m, a.speed_mps)))
                .chain(self.vehicles.iter().map(|o| {
                    let t = &self.demand.vtypes[o.vtype];
                    (o.pose, t.length_m, t.width_m, o.v)
                }));
            let mut room = f64::INFINITY;
            for (bp, bl, bw, bv) in bodies {
                if bp.pos.dist(pose.pos) > LOOKAHEAD_M {
                    continue;
                }
                if let Some((sp, lat)) = route.project_ahead(bp.pos, s, LOOKAHEAD_M) {
                    if sp > s && lat <= 0.5 * (vt.width_m + bw) + 0.2 {
                        let gap = sp - s - 0.5 * (vt.length_m + bl) - vt.min_gap_m;
                        room = room.min(gap + bv * bv / (2.0 * vt.decel_mps2));
                    }
                }
            }
            let v = v.min((2.0 * vt.decel_mps2 * room.max(0.0)).sqrt());
            let d = self.pending.remove(i);
            self.vehicles.push(Veh {
                key: self.next_key,
                vtype: d.vtype,
                route: Arc::new(route),
                s,
                v,
                braking: false,
                pose,
            });
            self.next_key += 1;
        }
    }

    /// One 0.05 s step of every vehicle; `ego` and `actors` are obstacles.
    fn step(&mut self, ego: (Pose, f64, f64, f64), actors: &[crate::view::ActorView]) {
        self.time_s += DT_S;
        self.lights.update(self.time_s);
        self.depart(ego, actors);
        // Bodies: (centre, half length, half width, speed) of everything that can block a path.
        self.bodies.clear();
        self.bodies.push((ego.0.pos, 0.5 * ego.1, 0.5 * ego.2, ego.3));
        for a in actors {
            self.bodies.push((a.pose.pos, 0.5 * a.length_m, 0.5 * a.width_m, a.speed_mps));
        }
        let first_traffic = self.bodies.len();
        for o in &self.vehicles {
            let t = &self.demand.vtypes[o.vtype];
            self.bodies.push((o.pose.pos, 0.5 * t.length_m, 0.5 * t.width_m, o.v));
        }
        let headings: Vec<f64> = std::iter::once(ego.0.yaw)
            .chain(actors.iter().map(|a| a.pose.yaw))
            .chain(self.vehicles.iter().map(|o| o.pose.yaw))
            .collect();
        let mut accels = Vec::with_capacity(self.vehicles.len());
        for (vi, me) in self.vehicles.iter().enumerate() {
            let vt = &self.demand.vtypes[me.vtype];
            let (half_l, half_w) = (0.5 * vt.length_m, 0.5 * vt.width_m);
            let front = me.s + half_l;
            let mut gap = f64::INFINITY;
            let mut lead_v = 0.0;
            let fwd = me.pose.forward();
            for (bi, &(p, bl, bw, bv)) in self.bodies.iter().enumerate() {
                if bi == first_traffic + vi {
                    continue;
                }
                let d = p - me.pose.pos;
                let dist2 = d.norm_sq();
                if dist2 > LOOKAHEAD_M * LOOKAHEAD_M {
                    continue;
                }
                let mut along = d.dot(fwd);
                let straight =
                    along > 0.0 && me.route.path.point_at(me.s + along).dist(p) <= half_w + bw + 0.2;
                if !straight {
                    // Around a bend: project onto the path ahead (near bodies only).
                    if dist2 > BEND_SEARCH_M * BEND_SEARCH_M {
                        continue;
                    }
                    match me.route.project_ahead(p, me.s, BEND_SEARCH_M + 10.0) {
                        Some((sp, lat)) if sp > me.s && lat <= half_w + bw + 0.2 => along = sp - me.s,
                        _ => continue,
                    }
                }
                let g = along - half_l - bl;
                if g < gap {
                    gap = g;
                    // A body crossing the path counts as standing still.
                    let aligned = (headings[bi] - me.pose.yaw).cos() > 0.7;
                    lead_v = if aligned { bv } else { 0.0 };
                }
            }
            // Stops: lights and junctions ahead.
            for st in me.route.stops.iter().filter(|st| st.s >= front - 0.5) {
                let dist = st.s - front;
                if dist > LOOKAHEAD_M {
                    break;
                }
                let hold = match st.kind {
                    StopKind::Light { link, tl } => match self.lights.link_color(&self.tl_ids[tl], link) {
                        Some(LightColor::Red) => true,
                        Some(LightColor::Yellow) => me.v * me.v / (2.0 * vt.decel_mps2) < dist,
                        _ => false,
                    },
                    StopKind::Junction { junction, minor, exit_s: _ } => {
                        dist <= JUNCTION_LOOKAHEAD_M
                            && self.junction_busy(junction, minor, vi, first_traffic, &headings, me.pose.yaw)
                    }
                };
                if hold && dist < gap {
                    gap = dist.max(0.0);
                    lead_v = 0.0;
                }
                if hold {
                    break;
                }
            }
            let lane = me.route.lane_at(me.s);
            let v0 = desired_speed(vt.max_speed_mps, vt.speed_factor, self.map.lanes[lane].speed_mps);
            accels.push(idm(me.v, v0, gap, lead_v, vt.accel_mps2, vt.decel_mps2, vt.tau_s, vt.min_gap_m));
        }
        for (me, a) in self.vehicles.iter_mut().zip(&accels) {
            let v = (me.v + a * DT_S).max(0.0);
            me.braking = *a < -0.5 && me.v > 0.0;
            me.v = v;
            me.s += v * DT_S;
            let len = self.demand.vtypes[me.vtype].length_m;
            me.pose = path_pose(&me.route.path, me.s.min(me.route.path.length()), len);
        }
        // Arrived vehicles leave.
        self.vehicles.retain(|me| me.s < me.route.path.length());
    }

    /// Whether a vehicle must not enter `junction` now: someone on a crossing path is inside
    /// it, or (minor link) someone is approaching it.
    fn junction_busy(
        &self,
        junction: JunctionIdx,
        minor: bool,
        me: usize,
        first_traffic: usize,
        headings: &[f64],
        yaw: f64,
    ) -> bool {
        let centre = self.map.junctions[junction].pos;
        let drivable = self.map.drivable();
        for (bi, &(p, _, _, v)) in self.bodies.iter().enumerate() {
            if bi == first_traffic + me {
                continue;
            }
            let crossing = (headings[bi] - yaw).cos() < 0.7;
            if !crossing {
                continue;
            }
            if drivable.junction_at(p) == Some(junction) {
                return true;
            }
            if minor && v > 1.0 && p.dist(centre) < MINOR_YIELD_RADIUS_M {
                let towards = (centre - p).dot(Vec2::new(headings[bi].cos(), headings[bi].sin())) > 0.0;
                if towards {
                    return true;
                }
            }
        }
        false
    }

    fn frame(&self, out: &mut TrafficFrame) {
        for me in &self.vehicles {
            let t = &self.demand.vtypes[me.vtype];
            out.agents.push(TrafficAgent {
                key: me.key,
                kind: t.kind,
                length_m: t.length_m,
                width_m: t.width_m,
                height_m: t.height_m,
                color: t.color.unwrap_or(PALETTE[me.key as usize % PALETTE.len()]),
                emergency: t.vclass == VClass::Emergency,
                pose: me.pose,
                speed_mps: me.v,
                signals: if me.braking { SIGNAL_BRAKELIGHT } else { 0 },
            });
        }
    }
}

fn desired_speed(max_speed: f64, factor: f64, lane_speed: f64) -> f64 {
    max_speed.min(factor * lane_speed).max(0.1)
}

/// IDM acceleration (Treiber et al. 2000) with the free-road exponent 4.
#[allow(clippy::too_many_arguments)]
fn idm(v: f64, v0: f64, gap: f64, lead_v: f64, a: f64, b: f64, tau: f64, s0: f64) -> f64 {
    let free = 1.0 - (v / v0).powi(4);
    let acc = if gap.is_finite() {
        let dv = v - lead_v;
        let s_star = s0 + (v * tau + v * dv / (2.0 * (a * b).sqrt())).max(0.0);
        let g = gap.max(0.05);
        a * (free - (s_star / g).powi(2))
    } else {
        a * free
    };
    acc.max(-EMERGENCY_DECEL_MPS2)
}

fn path_pose(path: &Polyline, s: f64, length: f64) -> Pose {
    let h = (0.25 * length).clamp(0.25, 2.0);
    let len = path.length();
    let a = path.point_at((s - h).max(0.0));
    let b = path.point_at((s + h).min(len));
    let d = b - a;
    let yaw = if d.norm_sq() > 1e-12 { d.angle() } else { path.heading_at(s) };
    Pose::new(path.point_at(s), yaw)
}

impl TrafficModel for IdmTraffic {
    fn start(&mut self, input: &TrafficInput<'_>, seed: u64, out: &mut TrafficFrame) -> Result<()> {
        self.vehicles.clear();
        self.next_key = 0;
        self.demand = self.canonical.varied(input.variation_seed);
        self.rng = crate::scenario::traffic::seeded_rng(seed, 0x1D_0000);
        self.time_s = -self.demand.warmup_s - DT_S;
        let mut pending = self.demand.vehicles.clone();
        pending.extend(self.demand.random_trips(&self.map, seed, self.ego_start, 20.0));
        pending.sort_by(|a, b| a.depart_s.total_cmp(&b.depart_s));
        self.pending = pending;
        self.flows = self.demand.flows.iter().map(|f| FlowState { next_s: f.begin_s, count: 0 }).collect();
        let e = input.ego;
        // The ego stands at its start during the warm-up (its initial speed applies from
        // t = 0): traffic queues behind a standing car, not one it expects to drive away.
        let ego = (e.pose, e.length_m, e.width_m, 0.0);
        // Warm-up (the ego standing at its start), ending at t = 0.
        while self.time_s < -1e-9 {
            self.step(ego, input.actors);
        }
        self.time_s = 0.0;
        self.frame(out);
        Ok(())
    }

    fn tick(&mut self, input: &TrafficInput<'_>, out: &mut TrafficFrame) -> Result<()> {
        let e = input.ego;
        self.step((e.pose, e.length_m, e.width_m, e.speed_mps), input.actors);
        self.frame(out);
        Ok(())
    }

    fn name(&self) -> &str {
        "idm"
    }
}
