//! Meta-actions (docs/r4.md#action-levels), this project's extension of the protocol: a path
//! action crossed with a speed action, resolved on the lane graph into a waypoint plan that the
//! [`super::tracker`] drives.
//!
//! Path: the ego's lane is followed forward; at the end of a lane the connection taken is the
//! one whose next lane lies on the route (FOLLOW_LANE, and every junction after the first), or,
//! at the first junction ahead, the one of the asked direction (GO_STRAIGHT, TURN_LEFT,
//! TURN_RIGHT; the route's own connection when no such one exists). A turn the route does not
//! take leaves the route, which the score counts as a route deviation like any driver's.
//! CHANGE_LANE_LEFT / _RIGHT move to the neighbouring lane of the same edge over a ramp
//! ([`LANE_CHANGE_S`] seconds of travel, at least [`LANE_CHANGE_MIN_M`]); with no such lane the
//! lane is kept.
//!
//! Speed: the target `v*` is the ego speed (KEEP), `+ACCEL_STEP_MPS` (ACCELERATE, at most
//! [`MAX_META_SPEED_MPS`]), `−DECEL_STEP_MPS` (DECELERATE, at least 0) or 0 (STOP); the plan's
//! speed goes from the ego speed to `v*` at [`ACCEL_MPS2`] up, [`DECEL_MPS2`] down
//! ([`STOP_DECEL_MPS2`] for STOP) and then holds.

use crate::geom::{wrap_angle, Polyline, Pose, Vec2};
use crate::map::{EdgeFunction, LaneIdx, Network, TurnDir};
use serde::{Deserialize, Serialize};
use smallvec::SmallVec;

/// Path actions, numbered as the Gymnasium `MultiDiscrete([6, 4])` first component.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
pub enum PathAction {
    FollowLane = 0,
    ChangeLaneLeft = 1,
    ChangeLaneRight = 2,
    GoStraight = 3,
    TurnLeft = 4,
    TurnRight = 5,
}

/// Speed actions, numbered as the second component.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
pub enum SpeedAction {
    Keep = 0,
    Accelerate = 1,
    Decelerate = 2,
    Stop = 3,
}

impl PathAction {
    pub const ALL: [PathAction; 6] = [
        PathAction::FollowLane,
        PathAction::ChangeLaneLeft,
        PathAction::ChangeLaneRight,
        PathAction::GoStraight,
        PathAction::TurnLeft,
        PathAction::TurnRight,
    ];
    pub const fn name(self) -> &'static str {
        match self {
            PathAction::FollowLane => "FOLLOW_LANE",
            PathAction::ChangeLaneLeft => "CHANGE_LANE_LEFT",
            PathAction::ChangeLaneRight => "CHANGE_LANE_RIGHT",
            PathAction::GoStraight => "GO_STRAIGHT",
            PathAction::TurnLeft => "TURN_LEFT",
            PathAction::TurnRight => "TURN_RIGHT",
        }
    }
    pub fn from_index(i: i64) -> Option<PathAction> {
        usize::try_from(i).ok().and_then(|i| Self::ALL.get(i).copied())
    }
}

impl SpeedAction {
    pub const ALL: [SpeedAction; 4] =
        [SpeedAction::Keep, SpeedAction::Accelerate, SpeedAction::Decelerate, SpeedAction::Stop];
    pub const fn name(self) -> &'static str {
        match self {
            SpeedAction::Keep => "KEEP",
            SpeedAction::Accelerate => "ACCELERATE",
            SpeedAction::Decelerate => "DECELERATE",
            SpeedAction::Stop => "STOP",
        }
    }
    pub fn from_index(i: i64) -> Option<SpeedAction> {
        usize::try_from(i).ok().and_then(|i| Self::ALL.get(i).copied())
    }
}

/// One meta decision.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct MetaAction {
    pub path: PathAction,
    pub speed: SpeedAction,
}

/// Speed steps of the speed actions, m/s, and the plan's ramps, m/s².
pub const ACCEL_STEP_MPS: f64 = 2.0;
pub const DECEL_STEP_MPS: f64 = 2.0;
pub const ACCEL_MPS2: f64 = 2.5;
pub const DECEL_MPS2: f64 = 3.0;
pub const STOP_DECEL_MPS2: f64 = 6.0;
/// ACCELERATE never asks for more than this, m/s (the protocol's target-speed ceiling).
pub const MAX_META_SPEED_MPS: f64 = 30.0;
/// A lane change ramps over this many seconds of travel, and at least this far, m.
pub const LANE_CHANGE_S: f64 = 3.0;
pub const LANE_CHANGE_MIN_M: f64 = 12.0;
/// A lane counts as the ego's when within this of its centreline and this of its heading.
const LANE_MAX_OFFSET_M: f64 = 4.0;
const LANE_MAX_RAD: f64 = 1.2;
/// A next lane is "on the route" when its first metres lie this close to the route.
const ON_ROUTE_M: f64 = 1.5;
/// Added to a candidate lane's cost (m) when it leaves the route within 5 m.
const OFF_ROUTE_COST_M: f64 = 2.0;
/// A resolved path runs this far past the length asked for, m.
const PATH_MARGIN_M: f64 = 5.0;
/// Safety bound on lanes walked for one path.
const MAX_LANES: usize = 32;

/// The speed target and profile of a speed action: the distance travelled after each of `n`
/// steps of `dt` seconds, starting at `v` m/s.
pub fn speed_profile(speed: SpeedAction, v: f64, n: usize, dt: f64) -> Vec<f64> {
    let v = if v.is_finite() { v.max(0.0) } else { 0.0 };
    let (target, down) = match speed {
        SpeedAction::Keep => (v, DECEL_MPS2),
        SpeedAction::Accelerate => ((v + ACCEL_STEP_MPS).min(MAX_META_SPEED_MPS.max(v)), DECEL_MPS2),
        SpeedAction::Decelerate => ((v - DECEL_STEP_MPS).max(0.0), DECEL_MPS2),
        SpeedAction::Stop => (0.0, STOP_DECEL_MPS2),
    };
    // Integrate in fine steps so the ramp's corner is exact enough.
    let sub = 10;
    let h = dt / f64::from(sub);
    let (mut s, mut u) = (0.0, v);
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        for _ in 0..sub {
            let next = if u < target { (u + ACCEL_MPS2 * h).min(target) } else { (u - down * h).max(target) };
            s += 0.5 * (u + next) * h;
            u = next;
        }
        out.push(s);
    }
    out
}

/// The ego's lane: among the lanes containing the point (and, inside a junction, its internal
/// lanes), the one nearest in offset and heading; where lanes overlap (a junction's), one that
/// goes on along the route wins over one that leaves it ([`OFF_ROUTE_COST_M`]).
pub fn ego_lane(net: &Network, route: &Polyline, ego: &Pose) -> Option<(LaneIdx, f64)> {
    MetaResolver::new().ego_lane(net, route, ego)
}

fn ego_lane_with(
    net: &Network,
    ego: &Pose,
    near_route: &mut dyn FnMut(Vec2) -> bool,
) -> Option<(LaneIdx, f64)> {
    let mut lanes: SmallVec<[LaneIdx; 8]> = SmallVec::new();
    net.drivable().lanes_at(ego.pos, &mut lanes);
    if let Some(j) = net.drivable().junction_at(ego.pos) {
        for &l in &net.junctions[j].int_lanes {
            if !lanes.contains(&l) && net.lanes[l].is_drivable() {
                lanes.push(l);
            }
        }
    }
    let mut best: Option<(f64, LaneIdx, f64)> = None;
    for &l in &lanes {
        let shape = &net.lanes[l].shape;
        let Some(pr) = shape.project(ego.pos) else { continue };
        let dh = wrap_angle(shape.heading_at(pr.s) - ego.yaw).abs();
        let ahead = shape.point_at((pr.s + 5.0).min(shape.length()));
        let on = near_route(ahead);
        let cost = pr.distance + 4.0 * dh + if on { 0.0 } else { OFF_ROUTE_COST_M };
        if pr.distance <= LANE_MAX_OFFSET_M && dh <= LANE_MAX_RAD && best.is_none_or(|b| cost < b.0) {
            best = Some((cost, l, pr.s));
        }
    }
    if best.is_none() {
        let (l, pr) = net.drivable().nearest_lane(ego.pos, LANE_MAX_OFFSET_M)?;
        let dh = wrap_angle(net.lanes[l].shape.heading_at(pr.s) - ego.yaw).abs();
        return (dh <= LANE_MAX_RAD).then_some((l, pr.s));
    }
    best.map(|b| (b.1, b.2))
}

fn lane_on_route(net: &Network, route: &Polyline, lane: LaneIdx) -> bool {
    let shape = &net.lanes[lane].shape;
    let probe = shape.point_at(shape.length().min(3.0));
    route.project(probe).is_some_and(|p| p.distance <= ON_ROUTE_M)
}

/// Resolves meta-actions for one episode's route, remembering what does not change between
/// decisions (docs/r4.md#action-levels): whether each lane lies on the route (a pure function of
/// the lane and the route, computed once per lane), and the ego's progress along the route, so
/// that the route is searched only near the ego ([`ROUTE_WINDOW_BACK_M`], [`ROUTE_WINDOW_AHEAD_M`])
/// instead of along its whole length at every decision. Its state is a function of the decisions
/// so far: same seed and actions, same plans.
#[derive(Debug, Clone, Default)]
pub struct MetaResolver {
    /// Per lane: 0 not yet known, 1 off the route, 2 on it.
    on_route: Vec<u8>,
    /// Route progress at the last resolution, m.
    s_hint: Option<f64>,
    /// (points, length) of the route the memo belongs to.
    route_key: Option<(usize, u64)>,
}

/// The route is searched from this far behind the last progress to this far ahead of it, m.
const ROUTE_WINDOW_BACK_M: f64 = 30.0;
const ROUTE_WINDOW_AHEAD_M: f64 = 120.0;
/// Farther than this from the route in its window, the ego's progress is searched anew, m.
const ROUTE_LOST_M: f64 = 10.0;

impl MetaResolver {
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets the route (a new episode).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    fn sync(&mut self, net: &Network, route: &Polyline, ego: &Pose) {
        let key = (route.len(), route.length().to_bits());
        if self.route_key != Some(key) || self.on_route.len() != net.lanes.len() {
            self.on_route = vec![0; net.lanes.len()];
            self.s_hint = None;
            self.route_key = Some(key);
        }
        let windowed = self.s_hint.and_then(|h| {
            route
                .project_within(ego.pos, h - ROUTE_WINDOW_BACK_M, h + ROUTE_WINDOW_AHEAD_M)
                .filter(|p| p.distance <= ROUTE_LOST_M)
        });
        self.s_hint = windowed.or_else(|| route.project(ego.pos)).map(|p| p.s);
    }

    fn near_route(&self, route: &Polyline, p: Vec2) -> bool {
        let pr = match self.s_hint {
            Some(h) => route.project_within(p, h - ROUTE_WINDOW_BACK_M, h + ROUTE_WINDOW_AHEAD_M),
            None => route.project(p),
        };
        pr.is_some_and(|p| p.distance <= ON_ROUTE_M)
    }

    fn on_route(&mut self, net: &Network, route: &Polyline, lane: LaneIdx) -> bool {
        match self.on_route.get(lane) {
            Some(1) => false,
            Some(2) => true,
            _ => {
                let on = lane_on_route(net, route, lane);
                if let Some(m) = self.on_route.get_mut(lane) {
                    *m = if on { 2 } else { 1 };
                }
                on
            }
        }
    }

    /// [`ego_lane`] with the memo.
    pub fn ego_lane(&mut self, net: &Network, route: &Polyline, ego: &Pose) -> Option<(LaneIdx, f64)> {
        self.sync(net, route, ego);
        let me = &*self;
        ego_lane_with(net, ego, &mut |p| me.near_route(route, p))
    }

    /// [`resolve_path`] with the memo.
    pub fn resolve_path(
        &mut self,
        net: &Network,
        route: &Polyline,
        ego: &Pose,
        speed_mps: f64,
        action: PathAction,
        length_m: f64,
    ) -> Option<Polyline> {
        let (lane, s) = self.ego_lane(net, route, ego)?;
        let mut on = |l: LaneIdx| self.on_route(net, route, l);
        resolve_from(net, ego, lane, s, speed_mps, action, length_m, &mut on)
    }

    /// [`meta_waypoints`] with the memo.
    #[allow(clippy::too_many_arguments)]
    pub fn waypoints(
        &mut self,
        net: &Network,
        route: &Polyline,
        ego: &Pose,
        speed_mps: f64,
        action: MetaAction,
        n: usize,
        dt: f64,
    ) -> Vec<(f64, f64)> {
        let dist = speed_profile(action.speed, speed_mps, n, dt);
        let far = dist.last().copied().unwrap_or(0.0) + 10.0;
        match self.resolve_path(net, route, ego, speed_mps, action.path, far) {
            Some(path) => super::tracker::waypoints_along(&path, ego, &dist),
            None => dist.iter().map(|&d| (d, 0.0)).collect(),
        }
    }
}

fn dir_matches(action: PathAction, dir: TurnDir) -> bool {
    match action {
        PathAction::GoStraight => dir == TurnDir::Straight,
        PathAction::TurnLeft => matches!(dir, TurnDir::Left | TurnDir::PartLeft),
        PathAction::TurnRight => matches!(dir, TurnDir::Right | TurnDir::PartRight),
        _ => false,
    }
}

/// The lanes driven from `lane` on (`lane` first, internal lanes included) until `length_m` is
/// covered past `s0`: the route's connection at every lane end, except the first junction,
/// where `turn` (a GO_STRAIGHT / TURN_* action) picks the direction when it can.
fn walk(
    net: &Network,
    lane: LaneIdx,
    s0: f64,
    length_m: f64,
    turn: PathAction,
    on_route: &mut dyn FnMut(LaneIdx) -> bool,
) -> Vec<LaneIdx> {
    let mut out = vec![lane];
    let mut covered = net.lanes[lane].shape.length() - s0;
    let mut turn_pending =
        matches!(turn, PathAction::GoStraight | PathAction::TurnLeft | PathAction::TurnRight);
    let mut cur = lane;
    while covered < length_m && out.len() < MAX_LANES {
        let internal = net.lane_function(cur) == EdgeFunction::Internal;
        let conns = net.connections_from_lane(cur);
        if conns.is_empty() {
            break;
        }
        let next_lane = |c: usize| net.connections[c].via.unwrap_or(net.connections[c].to_lane);
        let mut chosen = None;
        if turn_pending && !internal {
            chosen = conns.iter().copied().find(|&c| dir_matches(turn, net.connections[c].dir));
            turn_pending = false;
        }
        let chosen = chosen
            .or_else(|| conns.iter().copied().find(|&c| on_route(net.connections[c].to_lane)))
            .or_else(|| conns.iter().copied().find(|&c| net.connections[c].dir == TurnDir::Straight))
            .unwrap_or(conns[0]);
        let next = next_lane(chosen);
        if out.contains(&next) {
            break;
        }
        covered += net.lanes[next].shape.length();
        out.push(next);
        cur = next;
    }
    out
}

/// The centreline of `lanes` from `s0` on the first, cut [`PATH_MARGIN_M`] past `length_m`
/// (the rest of a long lane would only be copied and searched for nothing).
fn lanes_path(net: &Network, lanes: &[LaneIdx], s0: f64, length_m: f64) -> Polyline {
    let mut pts: Vec<Vec2> = Vec::new();
    let mut left = length_m + PATH_MARGIN_M;
    for (i, &l) in lanes.iter().enumerate() {
        if left <= 0.0 {
            break;
        }
        let shape = &net.lanes[l].shape;
        let a = if i == 0 { s0.clamp(0.0, shape.length()) } else { 0.0 };
        let b = (a + left).min(shape.length());
        left -= b - a;
        for &p in shape.slice(a, b).points() {
            if pts.last().is_none_or(|q: &Vec2| q.dist(p) > 1e-3) {
                pts.push(p);
            }
        }
    }
    Polyline::new(pts)
}

/// The neighbouring lane (left: higher SUMO index) of a normal lane, if it exists and is drivable.
fn neighbour(net: &Network, lane: LaneIdx, left: bool) -> Option<LaneIdx> {
    let l = &net.lanes[lane];
    if net.lane_function(lane) != EdgeFunction::Normal {
        return None;
    }
    let idx = if left { l.index.checked_add(1)? } else { l.index.checked_sub(1)? };
    net.edges[l.edge].lanes.iter().copied().find(|&o| net.lanes[o].index == idx && net.lanes[o].is_drivable())
}

/// The world-frame path of a path action for the ego at `ego` moving at `speed_mps`, at least
/// `length_m` long (extended straight past a dead end); `None` off the lane graph. Each call
/// searches the whole route; [`MetaResolver`] does the same with a memo across decisions.
pub fn resolve_path(
    net: &Network,
    route: &Polyline,
    ego: &Pose,
    speed_mps: f64,
    action: PathAction,
    length_m: f64,
) -> Option<Polyline> {
    MetaResolver::new().resolve_path(net, route, ego, speed_mps, action, length_m)
}

#[allow(clippy::too_many_arguments)]
fn resolve_from(
    net: &Network,
    ego: &Pose,
    lane: LaneIdx,
    s: f64,
    speed_mps: f64,
    action: PathAction,
    length_m: f64,
    on_route: &mut dyn FnMut(LaneIdx) -> bool,
) -> Option<Polyline> {
    let length_m = length_m.max(1.0);
    let change = match action {
        PathAction::ChangeLaneLeft => neighbour(net, lane, true),
        PathAction::ChangeLaneRight => neighbour(net, lane, false),
        _ => None,
    };
    let path = match change {
        Some(side) => {
            let own =
                lanes_path(net, &walk(net, lane, s, length_m, PathAction::FollowLane, on_route), s, length_m);
            let s_side = net.lanes[side].shape.project(ego.pos).map_or(0.0, |p| p.s);
            let other = lanes_path(
                net,
                &walk(net, side, s_side, length_m, PathAction::FollowLane, on_route),
                s_side,
                length_m,
            );
            let v = if speed_mps.is_finite() { speed_mps.max(0.0) } else { 0.0 };
            let ramp = (LANE_CHANGE_S * v).max(LANE_CHANGE_MIN_M);
            // The ramp starts where the ego is, not on its lane's centre: a change asked again
            // halfway through goes on from there instead of swinging back first.
            let start = if ego.pos.is_finite() { ego.pos - extended(&own, 0.0) } else { Vec2::new(0.0, 0.0) };
            let n = (length_m.ceil() as usize).max(2);
            let pts = (0..=n)
                .map(|i| {
                    let d = length_m * i as f64 / n as f64;
                    let t = (d / ramp).clamp(0.0, 1.0);
                    let w = 0.5 - 0.5 * (std::f64::consts::PI * t).cos();
                    (extended(&own, d) + start).lerp(extended(&other, d), w)
                })
                .collect();
            Polyline::new(pts)
        }
        None => lanes_path(net, &walk(net, lane, s, length_m, action, on_route), s, length_m),
    };
    if path.len() < 2 || path.length() <= 0.0 {
        return None;
    }
    Some(path)
}

fn extended(p: &Polyline, s: f64) -> Vec2 {
    p.pose_extended(s).pos
}

/// The waypoint plan of a meta-action: `n` ego-frame points (x forward, y left) `dt` apart on
/// the resolved path (straight ahead along the ego heading off the lane graph). Each call
/// searches the whole route; [`MetaResolver::waypoints`] does the same with a memo.
pub fn meta_waypoints(
    net: &Network,
    route: &Polyline,
    ego: &Pose,
    speed_mps: f64,
    action: MetaAction,
    n: usize,
    dt: f64,
) -> Vec<(f64, f64)> {
    MetaResolver::new().waypoints(net, route, ego, speed_mps, action, n, dt)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speed_profiles() {
        let keep = speed_profile(SpeedAction::Keep, 10.0, 8, 0.5);
        assert!((keep[7] - 40.0).abs() < 1e-9);
        let stop = speed_profile(SpeedAction::Stop, 6.0, 8, 0.5);
        // 6 m/s at 6 m/s² stops after 1 s: 3 m.
        assert!((stop[7] - 3.0).abs() < 1e-6, "{stop:?}");
        let acc = speed_profile(SpeedAction::Accelerate, 0.0, 8, 0.5);
        // To 2 m/s at 2.5 m/s² (0.8 s, 0.8 m), then 3.2 s at 2 m/s.
        assert!((acc[7] - (0.8 + 6.4)).abs() < 1e-6, "{acc:?}");
        let dec = speed_profile(SpeedAction::Decelerate, 1.0, 2, 0.5);
        assert!(dec[1] < 0.2, "{dec:?}");
        assert!(speed_profile(SpeedAction::Keep, f64::NAN, 3, 0.5).iter().all(|d| *d == 0.0));
    }

    #[test]
    fn indices_round_trip() {
        for (i, a) in PathAction::ALL.iter().enumerate() {
            assert_eq!(PathAction::from_index(i as i64), Some(*a));
        }
        for (i, a) in SpeedAction::ALL.iter().enumerate() {
            assert_eq!(SpeedAction::from_index(i as i64), Some(*a));
        }
        assert_eq!(PathAction::from_index(6), None);
        assert_eq!(SpeedAction::from_index(-1), None);
    }
}
