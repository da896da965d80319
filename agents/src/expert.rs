//! The privileged expert autopilot for R4.
//!
//! It sees the world state (ego, other actors, lights, the full route) but acts through exactly the
//! interface a VLM gets: one `(steer, target_speed_mps)` decision every 5 ticks (4 Hz), passed
//! through the protocol's actuation bridge (steer clipped to [-1, 1] and rate-limited to ±0.12 per
//! decision; target speed turned into throttle/brake by a P-law). So it is scored on the same
//! routes and interface as the models it is compared with.
//!
//! * Lateral: the base law is pure pursuit from the rear axle (where the bicycle's velocity is
//!   along the heading, so `tan δ = L κ` holds exactly), evaluated on the pose predicted half a
//!   hold ahead and kept inside the window from which the steer needed at each of the next
//!   decisions stays reachable under the rate limit (pre-steering before curves). The command is
//!   then chosen among the steers reachable from the last one by simulating the ego's bicycle
//!   model under each, followed by the base law, and keeping the best-tracking one.
//! * Longitudinal: the minimum of cruise, the speed limit, a curve-speed profile (lateral
//!   acceleration and steer-rate bounds, braked into at a comfortable deceleration; the swing
//!   from the wheel as it is now to the steer needed ahead must fit in the time to get there;
//!   no acceleration while the wheel is still turned), stops before actors in or predicted into
//!   the route corridor (unless the ego clears the spot well before they arrive, timed with the
//!   curve profile, or can no longer stop short of their path and still clears it), stops
//!   before red / yellow lights on the route, and a time-headway law behind a lead vehicle.
//!   Actors are extrapolated on straight lines over 3 s (cross traffic over 6 s, so that going
//!   ahead of it is decided before the conflict zone); a braking vehicle heading for a red /
//!   yellow stop line stops there; vehicles coming up from behind or beside the ego follow
//!   their lane when a lane-following predictor is given (a straight line would cut them across
//!   every bend of the route and hold the ego in a stream of traffic). A vehicle behind the ego
//!   is never a lead: in the ego's lane it is not braked for, in a lane the ego merges into it
//!   is yielded to unless the ego is ahead by a gap it does not close.
//! * Stall guard: the protocol ends an episode after 5 s below 1 km/h, so when held at rest by a
//!   light, a standing actor or a crawling lead the expert creeps a few centimetres every few
//!   seconds.
//! * Optional local planner: with a drivable-area oracle, a static obstacle blocking the route is
//!   passed by offsetting the pursuit path laterally into free same-direction drivable space;
//!   the pass is abandoned while the ego is short of the obstacle if it sets off along the lane.
//!
//! State: the expert assumes each [`Expert::act`] output reaches the bridge (one call per
//! decision); [`Expert::reset`] at every episode start.

use dh_env::drive::{MetaAction, PathAction, SpeedAction};
use dh_env::geom::{wrap_angle, Polyline, Pose, Projection, Vec2};
use dh_env::map::{LaneIdx, Network};
use dh_env::view::{ActorKind, ActorView, LightColor, TrafficLightView};
use dh_env::world::{step_bicycle, Control, EgoState, VehicleParams, World};
use smallvec::SmallVec;

/// Tuning of the expert. Defaults are the values the closed-loop tests were tuned with.
#[derive(Debug, Clone, PartialEq)]
pub struct ExpertParams {
    /// Speed on a free straight road, m/s.
    pub cruise_speed_mps: f64,
    /// Lateral acceleration allowed in curves, m/s²: `v ≤ √(a_lat / κ)`.
    pub max_lat_accel_mps2: f64,
    /// Deceleration used to plan stops and curve entries, m/s².
    pub comfort_decel_mps2: f64,
    /// Pure-pursuit lookahead `Ld = lookahead_base_m + lookahead_gain_s · v`, clamped to
    /// `[lookahead_min_m, lookahead_max_m]`.
    pub lookahead_base_m: f64,
    pub lookahead_gain_s: f64,
    pub lookahead_min_m: f64,
    pub lookahead_max_m: f64,
    /// The pose used for steering is predicted this far ahead (≈ half the 0.25 s hold).
    pub steer_preview_s: f64,
    /// Ego kinematic bicycle: wheelbase, rear axle → reference (centre), road-wheel angle at
    /// |steer| = 1.
    pub wheelbase_m: f64,
    pub rear_to_center_m: f64,
    pub max_wheel_angle_rad: f64,
    /// Bridge: maximum steer change per decision, and the decision period.
    pub steer_rate_per_decision: f64,
    pub decision_period_s: f64,
    /// Decisions ahead over which steer reachability is enforced (pre-steering).
    pub presteer_decisions: usize,
    /// Decisions simulated when choosing the steer among the reachable ones (0 = plain base law),
    /// and the weight (m) of the heading error against the lateral error in that rollout.
    pub rollout_decisions: usize,
    pub rollout_heading_weight_m: f64,
    /// Steer-rate curve bound uses this fraction of the bridge's steer rate (headroom for
    /// tracking corrections).
    pub steer_rate_usage: f64,
    /// Extra clearance beyond the two half widths for an actor to count as in the corridor, m.
    pub corridor_margin_m: f64,
    /// Gap kept to a stopped obstacle / lead vehicle (front bumper to its nearest point), m.
    pub stop_gap_m: f64,
    /// Front bumper stops this far before a red light's stop line, m.
    pub light_stop_margin_m: f64,
    /// Yellow is run through when stopping would need more than this deceleration, m/s².
    pub yellow_max_decel_mps2: f64,
    /// A red is run through only when stopping before its line would need more than this
    /// deceleration (the light turned while the ego was committed), m/s².
    pub red_commit_decel_mps2: f64,
    /// Time headway behind a lead vehicle, s.
    pub time_headway_s: f64,
    /// Actor motion is extrapolated (constant speed and heading) over this horizon, sampled at
    /// `prediction_step_s`.
    pub prediction_horizon_s: f64,
    pub prediction_step_s: f64,
    /// Longer horizon for vehicles crossing the ego's heading (a junction's cross traffic):
    /// whether to go ahead of one has to be decided before the conflict zone, while the
    /// crossing takes the ego several seconds, s.
    pub crossing_horizon_s: f64,
    /// A predicted (not current) corridor intrusion only matters if the ego could be there no
    /// later than this after it (earlier passages are clear).
    pub conflict_slack_s: f64,
    /// A predicted intrusion is ignored when the ego, at its current speed, has cleared that
    /// spot at least this long before the actor gets there, s.
    pub pass_margin_s: f64,
    /// Acceleration assumed when estimating how soon the ego reaches a conflict point, m/s².
    pub arrival_accel_mps2: f64,
    /// Protocol: speed < 1 km/h for more than 100 ticks ends the episode (blocked). After
    /// `stall_guard_s` at rest the expert creeps (one decision at `creep_speed_mps`) toward the
    /// light or standing actor holding it, down to `creep_min_gap_m` before it (twice that for
    /// pedestrians). Lights are therefore first approached to `light_stop_margin_m`.
    pub stall_guard_s: f64,
    pub creep_speed_mps: f64,
    pub creep_min_gap_m: f64,
    /// Local planner: lateral offsets tried (absolute values, m, ascending), ramp length per m/s
    /// of speed and its minimum, m.
    pub avoid_offsets_m: Vec<f64>,
    /// Longest cluster of standing obstacles passed in one detour, m.
    pub avoid_max_length_m: f64,
    /// Gap kept behind a standing obstacle that may have to be passed (room for the ramp), m.
    pub avoid_stop_gap_m: f64,
    /// A vehicle seen standing this long (and not just before a signal) counts as parked, s.
    pub parked_after_s: f64,
    pub avoid_ramp_per_mps: f64,
    pub avoid_ramp_min_m: f64,
}

impl Default for ExpertParams {
    fn default() -> Self {
        Self {
            cruise_speed_mps: 12.0,
            max_lat_accel_mps2: 2.5,
            comfort_decel_mps2: 2.5,
            lookahead_base_m: 3.0,
            lookahead_gain_s: 0.55,
            lookahead_min_m: 3.5,
            lookahead_max_m: 15.0,
            steer_preview_s: 0.125,
            wheelbase_m: 2.9,
            rear_to_center_m: 1.45,
            max_wheel_angle_rad: 35f64.to_radians(),
            steer_rate_per_decision: 0.12,
            decision_period_s: 0.25,
            presteer_decisions: 8,
            steer_rate_usage: 0.7,
            rollout_decisions: 10,
            rollout_heading_weight_m: 2.0,
            corridor_margin_m: 0.5,
            stop_gap_m: 3.5,
            light_stop_margin_m: 4.0,
            yellow_max_decel_mps2: 3.5,
            red_commit_decel_mps2: 6.5,
            time_headway_s: 1.5,
            prediction_horizon_s: 3.0,
            prediction_step_s: 0.5,
            crossing_horizon_s: 6.0,
            conflict_slack_s: 1.5,
            pass_margin_s: 1.0,
            arrival_accel_mps2: 2.5,
            stall_guard_s: 3.5,
            creep_speed_mps: 0.8,
            creep_min_gap_m: 1.0,
            avoid_offsets_m: vec![1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0],
            avoid_max_length_m: 40.0,
            avoid_stop_gap_m: 11.0,
            parked_after_s: 3.0,
            avoid_ramp_per_mps: 2.0,
            avoid_ramp_min_m: 10.0,
        }
    }
}

impl ExpertParams {
    /// Checks every value is finite and in range; the error names the field and value.
    pub fn validate(&self) -> dh_env::Result<()> {
        let positive = [
            ("cruise_speed_mps", self.cruise_speed_mps),
            ("max_lat_accel_mps2", self.max_lat_accel_mps2),
            ("comfort_decel_mps2", self.comfort_decel_mps2),
            ("lookahead_min_m", self.lookahead_min_m),
            ("lookahead_max_m", self.lookahead_max_m),
            ("wheelbase_m", self.wheelbase_m),
            ("max_wheel_angle_rad", self.max_wheel_angle_rad),
            ("steer_rate_per_decision", self.steer_rate_per_decision),
            ("decision_period_s", self.decision_period_s),
            ("steer_rate_usage", self.steer_rate_usage),
            ("prediction_step_s", self.prediction_step_s),
            ("arrival_accel_mps2", self.arrival_accel_mps2),
            ("yellow_max_decel_mps2", self.yellow_max_decel_mps2),
            ("red_commit_decel_mps2", self.red_commit_decel_mps2),
            ("avoid_ramp_min_m", self.avoid_ramp_min_m),
            ("avoid_max_length_m", self.avoid_max_length_m),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(dh_env::Error::config(field, v, "must be a finite number > 0"));
            }
        }
        let non_negative = [
            ("lookahead_base_m", self.lookahead_base_m),
            ("lookahead_gain_s", self.lookahead_gain_s),
            ("steer_preview_s", self.steer_preview_s),
            ("rear_to_center_m", self.rear_to_center_m),
            ("corridor_margin_m", self.corridor_margin_m),
            ("stop_gap_m", self.stop_gap_m),
            ("light_stop_margin_m", self.light_stop_margin_m),
            ("time_headway_s", self.time_headway_s),
            ("prediction_horizon_s", self.prediction_horizon_s),
            ("crossing_horizon_s", self.crossing_horizon_s),
            ("conflict_slack_s", self.conflict_slack_s),
            ("pass_margin_s", self.pass_margin_s),
            ("stall_guard_s", self.stall_guard_s),
            ("creep_speed_mps", self.creep_speed_mps),
            ("creep_min_gap_m", self.creep_min_gap_m),
            ("avoid_ramp_per_mps", self.avoid_ramp_per_mps),
            ("avoid_stop_gap_m", self.avoid_stop_gap_m),
            ("parked_after_s", self.parked_after_s),
            ("rollout_heading_weight_m", self.rollout_heading_weight_m),
        ];
        for (field, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(dh_env::Error::config(field, v, "must be a finite number ≥ 0"));
            }
        }
        if self.lookahead_min_m > self.lookahead_max_m {
            return Err(dh_env::Error::config(
                "lookahead_min_m",
                self.lookahead_min_m,
                format!("must not exceed lookahead_max_m = {}", self.lookahead_max_m),
            ));
        }
        if self.max_wheel_angle_rad >= std::f64::consts::FRAC_PI_2 {
            return Err(dh_env::Error::config(
                "max_wheel_angle_rad",
                self.max_wheel_angle_rad,
                "must be < π/2",
            ));
        }
        if self.rear_to_center_m > self.wheelbase_m {
            return Err(dh_env::Error::config(
                "rear_to_center_m",
                self.rear_to_center_m,
                format!("must not exceed wheelbase_m = {}", self.wheelbase_m),
            ));
        }
        if let Some(bad) = self.avoid_offsets_m.iter().find(|o| !(o.is_finite() && **o > 0.0)) {
            return Err(dh_env::Error::config("avoid_offsets_m", bad, "offsets must be finite and > 0"));
        }
        Ok(())
    }
}

/// Everything the expert sees at one decision (world frame; the ego is not among `actors`).
#[derive(Clone, Copy)]
pub struct ExpertInput<'a> {
    pub ego: &'a ActorView,
    /// The full ego route (lane centrelines through junctions), start to destination.
    pub route: &'a Polyline,
    pub actors: &'a [ActorView],
    pub lights: &'a [TrafficLightView],
    /// Legal speed on the ego's lane, if known.
    pub speed_limit_mps: Option<f64>,
    /// Optional drivable-area oracle: `drivable(point, heading)` is true if the point lies on a
    /// drivable lane whose travel direction agrees with `heading` (radians), or inside a
    /// junction. Enables the local planner that passes static obstacles (never through
    /// oncoming lanes); without it the expert stops before them. See [`network_drivable`].
    pub drivable: Option<&'a dyn Fn(Vec2, f64) -> bool>,
    /// Optional lane-following predictor: `follow_lane(pos, yaw, d)` is the pose `d` metres on
    /// along the lane a vehicle at `pos` heading `yaw` is following, or `None` when it follows
    /// none (it is then predicted on a straight line). See [`network_lane_follower`].
    pub follow_lane: Option<&'a dyn Fn(Vec2, f64, f64) -> Option<Pose>>,
}

impl std::fmt::Debug for ExpertInput<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ExpertInput")
            .field("ego", self.ego)
            .field("route_len_m", &self.route.length())
            .field("actors", &self.actors.len())
            .field("lights", &self.lights.len())
            .field("speed_limit_mps", &self.speed_limit_mps)
            .field("drivable", &self.drivable.is_some())
            .field("follow_lane", &self.follow_lane.is_some())
            .finish()
    }
}

/// What limited the target speed at this decision (for logs and tests).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SpeedReason {
    Cruise,
    SpeedLimit,
    Curve,
    /// An actor in (or predicted in) the route corridor ahead; stop before it.
    Obstacle {
        actor_id: u32,
    },
    /// Following a vehicle moving along the route.
    Lead {
        actor_id: u32,
    },
    /// A red or yellow light whose stop line is on the route ahead.
    Light,
    /// No usable route or ego state: stand still.
    NoRoute,
}

/// The expert's decision, in the protocol's action space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExpertAction {
    /// In [-1, 1], negative = left; already within ±`steer_rate_per_decision` of the previous one,
    /// so the bridge applies it unchanged.
    pub steer: f64,
    /// In [0, 30] m/s.
    pub target_speed_mps: f64,
    pub reason: SpeedReason,
    /// Lateral offset of the pursued path from the route at the ego (m, > 0 = left), non-zero
    /// while passing an obstacle.
    pub path_offset_m: f64,
}

/// A committed lateral detour around a static obstacle: offset `o` reached over
/// `[s0, s1]`, held to `s2`, returned to zero at `s3` (route arc lengths).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Detour {
    offset: f64,
    s0: f64,
    s1: f64,
    s2: f64,
    s3: f64,
}

impl Detour {
    fn offset_at(&self, s: f64) -> f64 {
        let blend = |t: f64| 0.5 - 0.5 * (std::f64::consts::PI * t.clamp(0.0, 1.0)).cos();
        if s <= self.s0 || s >= self.s3 {
            0.0
        } else if s < self.s1 {
            self.offset * blend((s - self.s0) / (self.s1 - self.s0).max(1e-6))
        } else if s <= self.s2 {
            self.offset
        } else {
            self.offset * (1.0 - blend((s - self.s2) / (self.s3 - self.s2).max(1e-6)))
        }
    }
}

/// A speed constraint: the front bumper must be at speed ≤ `v_at` when reaching arc `s_stop`.
#[derive(Debug, Clone, Copy)]
struct StopPoint {
    s_stop: f64,
    v_at: f64,
    reason: SpeedReason,
    /// How far the front may creep when stalled (lights and standing actors, not moving
    /// traffic): arc of the closest allowed front position.
    creep_limit: Option<f64>,
}

/// The expert. Keeps the last steer (the bridge's rate-limit reference), the route progress hint,
/// time spent at rest and a committed detour.
#[derive(Debug, Clone)]
pub struct Expert {
    params: ExpertParams,
    last_steer: f64,
    s_hint: Option<f64>,
    rest_time_s: f64,
    detour: Option<Detour>,
    /// (actor id, seconds seen standing still), sorted by id.
    stationary: Vec<(u32, f64)>,
    /// Allowed speed per metre ahead of `envelope_s0` (curves only), from the last decision.
    envelope: Vec<f64>,
    envelope_s0: f64,
    /// The bicycle poses are predicted with ([`step_bicycle`], the world's own model): the
    /// world's ego when given ([`Expert::set_vehicle`]), else `params`' steering geometry.
    bicycle: VehicleParams,
    /// The meta level's lane-graph resolution (the env's own, with its memo for the route).
    meta: dh_env::drive::meta::MetaResolver,
}

/// Route point at arc `s`, extrapolated along the end headings beyond the ends.
fn route_point(route: &Polyline, s: f64) -> Vec2 {
    let len = route.length();
    if s > len {
        route.point_at(len) + Vec2::from_angle(route.heading_at(len)) * (s - len)
    } else if s < 0.0 {
        route.point_at(0.0) + Vec2::from_angle(route.heading_at(0.0)) * s
    } else {
        route.point_at(s)
    }
}

/// Margin by which a committed ego (too close to stop short of a crossing actor's path) must
/// clear that path before the actor arrives to go on instead of braking, s.
const COMMITTED_MARGIN_S: f64 = 0.3;

/// Steer swings below this (from the current steer to one needed ahead) do not bound the
/// speed: pure pursuit's corner cutting absorbs them.
const STATE_BOUND_MIN_SWING: f64 = 0.15;

/// A vehicle heading at least this far from the ego's heading (either way) is cross traffic, rad.
const CROSSING_MIN_RAD: f64 = 0.6;

/// The bound from the current steer never asks for less than this, m/s.
const STATE_BOUND_FLOOR_MPS: f64 = 2.0;

/// Straight extensions added before the start and after the end of the route, m.
const ROUTE_EXTENSION_BEFORE_M: f64 = 20.0;
const ROUTE_EXTENSION_AFTER_M: f64 = 80.0;

fn extend_route(route: &Polyline) -> Polyline {
    let pts = route.points();
    let len = route.length();
    let mut out = Vec::with_capacity(pts.len() + 2);
    out.push(pts[0] - Vec2::from_angle(route.heading_at(0.0)) * ROUTE_EXTENSION_BEFORE_M);
    out.extend_from_slice(pts);
    out.push(pts[pts.len() - 1] + Vec2::from_angle(route.heading_at(len)) * ROUTE_EXTENSION_AFTER_M);
    Polyline::new(out)
}

/// Route direction at `s`, averaged over ±1 m so vertices do not make it jump.
fn route_heading(route: &Polyline, s: f64) -> f64 {
    (route_point(route, s + 1.0) - route_point(route, s - 1.0)).angle()
}

/// Projection of `p` onto the segments of `route` overlapping arcs [s_lo, s_hi].
fn project_window(route: &Polyline, p: Vec2, s_lo: f64, s_hi: f64) -> Option<Projection> {
    let pts = route.points();
    let cum = route.cumulative();
    if pts.len() < 2 {
        return route.project(p);
    }
    let first = cum.partition_point(|&c| c < s_lo).saturating_sub(1);
    let mut best: Option<(f64, usize, f64)> = None;
    for i in first..pts.len() - 1 {
        if cum[i] > s_hi {
            break;
        }
        let (t, d2) = dh_env::geom::closest_on_segment(p, pts[i], pts[i + 1]);
        if best.is_none_or(|b| d2 < b.0) {
            best = Some((d2, i, t));
        }
    }
    let (d2, i, t) = best?;
    let (a, b) = (pts[i], pts[i + 1]);
    let distance = d2.sqrt();
    let side = (b - a).cross(p - a);
    Some(Projection {
        s: cum[i] + t * (cum[i + 1] - cum[i]),
        distance,
        lateral: if side >= 0.0 { distance } else { -distance },
        segment: i,
        point: a.lerp(b, t),
    })
}

impl Expert {
    /// Builds an expert; the parameters are checked by [`ExpertParams::validate`].
    pub fn new(params: ExpertParams) -> dh_env::Result<Self> {
        params.validate()?;
        let bicycle = VehicleParams {
            wheelbase_m: params.wheelbase_m,
            rear_axle_to_center_m: params.rear_to_center_m,
            max_steer_deg: params.max_wheel_angle_rad.to_degrees(),
            ..VehicleParams::default()
        };
        Ok(Self {
            params,
            bicycle,
            last_steer: 0.0,
            s_hint: None,
            rest_time_s: 0.0,
            detour: None,
            stationary: Vec::new(),
            envelope: Vec::new(),
            envelope_s0: 0.0,
            meta: dh_env::drive::meta::MetaResolver::new(),
        })
    }

    pub fn params(&self) -> &ExpertParams {
        &self.params
    }

    /// Forgets the episode: the bridge's steer reference restarts at 0 as the protocol says.
    pub fn reset(&mut self) {
        self.last_steer = 0.0;
        self.s_hint = None;
        self.rest_time_s = 0.0;
        self.detour = None;
        self.stationary.clear();
        self.envelope.clear();
        self.meta.reset();
    }

    /// One decision. Never panics; degenerate input (empty route, non-finite ego state) yields
    /// a stop with the steer held.
    pub fn act(&mut self, input: &ExpertInput<'_>) -> ExpertAction {
        let ego = input.ego;
        let ok = ego.pose.pos.is_finite() && ego.pose.yaw.is_finite() && ego.speed_mps.is_finite();
        let finite_route = input.route.points().iter().all(|p| p.is_finite());
        if input.route.len() < 2 || input.route.length() <= 0.0 || !ok || !finite_route {
            return ExpertAction {
                steer: self.last_steer,
                target_speed_mps: 0.0,
                reason: SpeedReason::NoRoute,
                path_offset_m: 0.0,
            };
        }
        // The episode ends 8 m before the route end, but lookaheads and rollouts reach past it:
        // extend the route straight on at both ends so projections there stay meaningful
        // (arc lengths below are on the extended route).
        let ext = extend_route(input.route);
        // A malformed ego size falls back to a passenger car's so every length below is finite.
        let mut ego_fixed = *ego;
        if !(ego.length_m.is_finite() && ego.length_m > 0.0 && ego.width_m.is_finite() && ego.width_m > 0.0) {
            ego_fixed.length_m = 4.9;
            ego_fixed.width_m = 2.0;
        }
        let ego = &ego_fixed;
        let input = &ExpertInput { route: &ext, ego, ..*input };
        let route = input.route;
        let v = ego.speed_mps.max(0.0);
        let s_ego = self.progress(route, ego.pose.pos, v);
        self.s_hint = Some(s_ego);
        if v < 0.3 {
            self.rest_time_s += self.params.decision_period_s;
        } else {
            self.rest_time_s = 0.0;
        }
        self.observe_actors(input.actors);
        if self.detour.is_some_and(|d| s_ego - ego.length_m > d.s3) {
            self.detour = None;
        }
        if self.detour.is_some_and(|d| self.pass_target_moved_off(input, &d, s_ego)) {
            self.detour = None;
        }

        let (target, reason) = self.target_speed(input, s_ego, v);
        let steer = self.steer(input, s_ego, v.max(target.min(v + 1.0)).max(1.0));
        self.last_steer = steer;
        ExpertAction {
            steer,
            target_speed_mps: if target.is_finite() { target.clamp(0.0, 30.0) } else { 0.0 },
            reason,
            path_offset_m: self.detour.map_or(0.0, |d| d.offset_at(s_ego)),
        }
    }

    /// Something standing in the lane that the detour passes has set off along it (a cyclist
    /// at the kerb, a car that looked parked) while the ego is still short of it: the pass is
    /// abandoned and the ego falls back into its lane behind it.
    fn pass_target_moved_off(&self, input: &ExpertInput<'_>, d: &Detour, s_ego: f64) -> bool {
        let route = input.route;
        let s_front = s_ego + input.ego.length_m * 0.5;
        if s_front >= d.s1 {
            return false;
        }
        let half_ego = input.ego.width_m * 0.5 + self.params.corridor_margin_m;
        input.actors.iter().any(|a| {
            a.speed_mps > 0.5
                && project_window(route, a.pose.pos, s_front, d.s2).is_some_and(|pr| {
                    pr.s > s_front + 1e-6
                        && pr.s < d.s2 - 1e-6
                        && pr.lateral.abs() < half_ego + a.width_m * 0.5
                        && wrap_angle(a.pose.yaw - route_heading(route, pr.s)).abs() < 0.8
                })
        })
    }

    /// Arc length of the ego on the route: a windowed projection around the last progress (so
    /// self-overlapping routes do not make it jump), global on the first call.
    fn progress(&self, route: &Polyline, p: Vec2, v: f64) -> f64 {
        let global = || route.project(p).map_or(0.0, |pr| pr.s);
        match self.s_hint {
            None => global(),
            Some(h) => match project_window(route, p, h - 5.0, h + 10.0 + 2.0 * v) {
                Some(pr) if pr.distance < 8.0 => pr.s,
                _ => global(),
            },
        }
    }

    /// Lateral offset of the pursued path at arc `s`.
    fn offset_at(&self, s: f64) -> f64 {
        self.detour.map_or(0.0, |d| d.offset_at(s))
    }

    /// A point of the pursued path (the route shifted by the detour offset).
    fn path_point(&self, route: &Polyline, s: f64) -> Vec2 {
        let o = self.offset_at(s);
        let p = route_point(route, s);
        if o == 0.0 {
            p
        } else {
            p + Vec2::from_angle(route_heading(route, s)).perp() * o
        }
    }

    fn lookahead(&self, v: f64) -> f64 {
        let p = &self.params;
        (p.lookahead_base_m + p.lookahead_gain_s * v).clamp(p.lookahead_min_m, p.lookahead_max_m)
    }

    fn steer_to_wheel(&self, steer: f64) -> f64 {
        -steer.clamp(-1.0, 1.0) * self.params.max_wheel_angle_rad
    }

    /// Steer command (unclipped to the rate window) that pure pursuit asks for from `pose`.
    fn pursuit(&self, route: &Polyline, pose: Pose, s_rear: f64, v: f64) -> f64 {
        let p = &self.params;
        let rear = pose.pos - pose.forward() * p.rear_to_center_m;
        let ld = self.lookahead(v);
        // Lookahead point at arc distance Ld from the rear axle's projection; the chord is used.
        let target = self.path_point(route, s_rear + ld);
        let d = target - rear;
        let chord = d.norm().max(1e-3);
        let alpha = wrap_angle(d.angle() - pose.yaw);
        let kappa = 2.0 * alpha.sin() / chord;
        let delta = (p.wheelbase_m * kappa).atan();
        (-delta / p.max_wheel_angle_rad).clamp(-1.0, 1.0)
    }

    /// The ego's pose after `t` seconds at constant speed and steer: the world's kinematic
    /// bicycle ([`step_bicycle`]) in steps of at most one tick, the speed held at `v`.
    fn predict_pose(&self, pose: Pose, v: f64, steer: f64, t: f64) -> Pose {
        let control = Control { throttle: 0.0, brake: 0.0, steer: steer.clamp(-1.0, 1.0) };
        let n = ((t / 0.05).ceil() as usize).clamp(1, 100);
        let dt = t / n as f64;
        let mut out = pose;
        for _ in 0..n {
            out = step_bicycle(&self.bicycle, &EgoState::new(out, v), &control, dt).pose;
        }
        out.yaw = wrap_angle(out.yaw);
        out
    }

    /// The base lateral law: pure pursuit from the pose predicted `steer_preview_s` ahead, kept
    /// inside the pre-steer reachability window and the bridge's rate limit around `last`.
    /// `v` is the ego speed, `v_plan` the speed the lookahead is sized for.
    fn base_steer(&self, route: &Polyline, pose: Pose, v: f64, v_plan: f64, s_hint: f64, last: f64) -> f64 {
        let p = &self.params;
        let rate = p.steer_rate_per_decision;
        let pose = self.predict_pose(pose, v, last, p.steer_preview_s);
        let rear = pose.pos - pose.forward() * p.rear_to_center_m;
        let s_rear = project_window(route, rear, s_hint - 10.0, s_hint + 10.0).map_or(s_hint, |pr| pr.s);
        let mut u = self.pursuit(route, pose, s_rear, v_plan);
        // Pre-steer: how the steer an on-path car needs changes over the next decisions, added to
        // the current pursuit command, must stay reachable from this one under the rate limit.
        let on_path = |s: f64| {
            let yaw = (self.path_point(route, s + 1.0) - self.path_point(route, s - 1.0)).angle();
            let pos = self.path_point(route, s) + Vec2::from_angle(yaw) * p.rear_to_center_m;
            self.pursuit(route, Pose::new(pos, yaw), s, v_plan)
        };
        let u0 = on_path(s_rear);
        let (mut lo, mut hi) = (-1.0f64, 1.0f64);
        for k in 1..=p.presteer_decisions {
            let s_k = s_rear + v_plan * p.decision_period_s * k as f64;
            let u_k = (u + on_path(s_k) - u0).clamp(-1.0, 1.0);
            let reach = rate * k as f64;
            lo = lo.max(u_k - reach);
            hi = hi.min(u_k + reach);
        }
        u = if lo <= hi { u.clamp(lo, hi) } else { 0.5 * (lo + hi) };
        let u = u.clamp(last - rate, last + rate).clamp(-1.0, 1.0);
        if u.is_finite() {
            u
        } else {
            last
        }
    }

    /// Tracking cost of holding `first` for one decision, then following the base law, over
    /// `rollout_decisions` decisions at the current speed: squared lateral and (scaled) heading
    /// errors against the pursued path, sampled every 2 ticks.
    fn rollout_cost(&self, route: &Polyline, ego: Pose, v: f64, v_plan: f64, s_ego: f64, first: f64) -> f64 {
        let p = &self.params;
        const SUB: usize = 2;
        let dt = p.decision_period_s / SUB as f64;
        let (mut pose, mut s_hint, mut u) = (ego, s_ego, first);
        let mut cost = 0.0;
        let half_len = p.wheelbase_m * 0.5 + 0.85;
        let mut v = v;
        for k in 0..p.rollout_decisions {
            if k > 0 {
                u = self.base_steer(route, pose, v, v_plan.min(v.max(1.0)), s_hint, u);
            }
            for _ in 0..SUB {
                // The car slows for bends ahead as the speed planner will make it.
                let i = (s_hint + half_len - self.envelope_s0).max(0.0) as usize;
                if let Some(cap) = self.envelope.get(i).or(self.envelope.last()) {
                    v = v.min(cap.max(1.0));
                }
                pose = self.predict_pose(pose, v, u, dt);
                let Some(pr) = project_window(route, pose.pos, s_hint - 5.0, s_hint + 5.0 + 2.0 * v * dt)
                else {
                    return f64::INFINITY;
                };
                s_hint = pr.s;
                let lat = pr.lateral - self.offset_at(pr.s);
                let dh = wrap_angle(pose.yaw - route_heading(route, pr.s));
                // Beyond 0.5 m the error grows steeply: swinging wide into the next lane to
                // ease a bend is worse than cutting it a little.
                let excess = (lat.abs() - 0.5).max(0.0);
                cost += lat * lat + 20.0 * excess * excess + (p.rollout_heading_weight_m * dh.sin()).powi(2);
            }
        }
        cost
    }

    fn steer(&self, input: &ExpertInput<'_>, s_ego: f64, v_plan: f64) -> f64 {
        let p = &self.params;
        let route = input.route;
        let v = input.ego.speed_mps.max(0.0);
        let last = self.last_steer;
        let base = self.base_steer(route, input.ego.pose, v, v_plan, s_ego, last);
        if p.rollout_decisions == 0 || v < 0.5 {
            return base;
        }
        // Rollout improvement of the base law: try the reachable steers around the last one and
        // keep the one whose continuation tracks the path best; ties favour the base command.
        let rate = p.steer_rate_per_decision;
        let mut best = (self.rollout_cost(route, input.ego.pose, v, v_plan, s_ego, base) * 0.98, base);
        for i in -3i32..=3 {
            let u = (last + rate * i as f64 / 3.0).clamp(-1.0, 1.0);
            let c = self.rollout_cost(route, input.ego.pose, v, v_plan, s_ego, u);
            if c < best.0 {
                best = (c, u);
            }
        }
        best.1
    }

    /// Signed path curvature at arc `s` (heading change over ±w; > 0 = left).
    fn curvature(&self, route: &Polyline, s: f64) -> f64 {
        const W: f64 = 2.5;
        let h0 = (self.path_point(route, s) - self.path_point(route, s - W)).angle();
        let h1 = (self.path_point(route, s + W) - self.path_point(route, s)).angle();
        wrap_angle(h1 - h0) / W
    }

    /// Highest speed at which the steer needed around arc `s` is reachable in time and the
    /// lateral acceleration stays bounded.
    /// Also stores the braking envelope (allowed speed per metre ahead of the front) for the
    /// steering rollout.
    fn curve_speed_profile(&mut self, route: &Polyline, s_front: f64, v: f64) -> (f64, bool) {
        let p = self.params.clone();
        let horizon = (v * v / (2.0 * p.comfort_decel_mps2) + 25.0).clamp(30.0, 150.0);
        let ds = 1.0;
        let n = (horizon / ds) as usize;
        let kappa_max = p.max_wheel_angle_rad.tan() / p.wheelbase_m;
        let steer_of = |k: f64| ((p.wheelbase_m * k).atan() / p.max_wheel_angle_rad).clamp(-1.0, 1.0);
        let mut best = f64::INFINITY;
        // Signed, for the bound from the current steer below.
        let ks: Vec<f64> = (0..=n)
            .map(|i| self.curvature(route, s_front + i as f64 * ds).clamp(-kappa_max, kappa_max))
            .collect();
        let rate = p.steer_rate_usage * p.steer_rate_per_decision / p.decision_period_s;
        let rate_full = p.steer_rate_per_decision / p.decision_period_s;
        // The current steer in the curvature's sign convention (> 0 = left).
        let u_now = -self.last_steer;
        let half_len = p.wheelbase_m * 0.5 + 1.0;
        let mut envelope = Vec::with_capacity(ks.len());
        const SPAN: usize = 4;
        for (i, &k) in ks.iter().enumerate() {
            let d = i as f64 * ds;
            let mut v_here = (p.max_lat_accel_mps2 / k.abs().max(1e-6)).sqrt();
            // Steer-rate bound: the steer change over the last SPAN metres must be doable in the
            // time it takes to drive them.
            if i >= SPAN {
                // On magnitudes: signed, a polyline's vertex kinks read as reverse bends.
                let du = (steer_of(k).abs() - steer_of(ks[i - SPAN]).abs()).abs();
                if du > 1e-3 {
                    v_here = v_here.min(rate * SPAN as f64 * ds / du);
                }
            }
            let room = (d - v * p.decision_period_s).max(0.0);
            best = best.min((v_here * v_here + 2.0 * p.comfort_decel_mps2 * room).sqrt());
            // From the wheel as it is now: the swing to the steer needed d metres on must fit in
            // the time it takes to get there (centre to front plus d). Lagging into a tight bend
            // or out of one into a reverse bend (a roundabout exit) otherwise carries the car
            // out of its lane before the rate-limited wheel catches up.
            // On curvature averaged over ±3 m (a polyline's vertex kinks are no bends), and never
            // below a floor: crawling with the wheel at lock only turns the car on the spot.
            let lo = i.saturating_sub(3);
            let hi = (i + 3).min(ks.len() - 1);
            let k_avg = ks[lo..=hi].iter().sum::<f64>() / (hi - lo + 1) as f64;
            let du = (steer_of(k_avg) - u_now).abs();
            if du > STATE_BOUND_MIN_SWING {
                best = best.min((rate_full * (d + half_len) / du).max(STATE_BOUND_FLOOR_MPS));
            }
            envelope.push(v_here);
        }
        for i in (0..envelope.len().saturating_sub(1)).rev() {
            envelope[i] = envelope[i].min((envelope[i + 1].powi(2) + 2.0 * p.comfort_decel_mps2 * ds).sqrt());
        }
        self.envelope = envelope;
        self.envelope_s0 = s_front;
        (best, best.is_finite())
    }

    fn target_speed(&mut self, input: &ExpertInput<'_>, s_ego: f64, v: f64) -> (f64, SpeedReason) {
        let p = self.params.clone();
        let route = input.route;
        let ego = input.ego;
        let s_front = s_ego + ego.length_m * 0.5;
        let mut target = p.cruise_speed_mps;
        let mut reason = SpeedReason::Cruise;
        if let Some(lim) = input.speed_limit_mps.filter(|l| l.is_finite() && *l > 0.0) {
            if lim < target {
                target = lim;
                reason = SpeedReason::SpeedLimit;
            }
        }
        let (mut v_curve, finite) = self.curve_speed_profile(route, s_front, v);
        // While the wheel is still turned (e.g. recovering after a sharp bend) the car drives on
        // that curvature: do not accelerate past the lateral limit for it.
        let delta = self.steer_to_wheel(self.last_steer).abs();
        let kappa_now =
            (p.rear_to_center_m / p.wheelbase_m * delta.tan()).atan().sin() / p.rear_to_center_m.max(0.1);
        v_curve =
            v_curve.min((p.max_lat_accel_mps2 / kappa_now.max(1e-6)).sqrt().max(v.min(p.cruise_speed_mps)));
        if finite && v_curve < target {
            target = v_curve;
            reason = SpeedReason::Curve;
        }

        let mut stops = self.actor_constraints(input, s_ego, v);
        stops.extend(self.light_constraints(input, s_front, v));
        let hold = v * p.decision_period_s;
        let mut binding: Option<StopPoint> = None;
        for st in &stops {
            let d = st.s_stop - s_front - hold;
            let mut allowed = (st.v_at * st.v_at + 2.0 * p.comfort_decel_mps2 * d.max(0.0)).sqrt();
            if st.v_at < 0.5 && allowed < 0.6 {
                allowed = 0.0;
            }
            if allowed < target {
                target = allowed;
                reason = st.reason;
                binding = Some(*st);
            }
        }
        // Stall guard against the protocol's blocked timeout while waiting at rest.
        if target < p.creep_speed_mps && self.rest_time_s >= p.stall_guard_s {
            if let Some(limit) = binding.and_then(|b| b.creep_limit) {
                // One creep decision moves the ego by a few centimetres: enough to reset the
                // protocol's at-rest counter.
                if limit - s_front > 0.3 {
                    target = p.creep_speed_mps;
                }
            }
        }
        (target.max(0.0), reason)
    }

    /// Stop constraints from red / yellow lights whose stop line lies on the route ahead.
    fn light_constraints(&self, input: &ExpertInput<'_>, s_front: f64, v: f64) -> Vec<StopPoint> {
        let p = &self.params;
        let route = input.route;
        let mut out = Vec::new();
        let horizon = v * v / (2.0 * p.comfort_decel_mps2) + 60.0;
        for light in input.lights {
            if !matches!(light.color, LightColor::Red | LightColor::Yellow) {
                continue;
            }
            let pos = light.stop_line.pos;
            if !pos.is_finite() {
                continue;
            }
            let Some(pr) = project_window(route, pos, s_front - 3.0, s_front + horizon) else { continue };
            let tol = (0.6 * light.lane_width_m).clamp(1.0, 2.0);
            if pr.distance > tol {
                continue;
            }
            if wrap_angle(route_heading(route, pr.s) - light.stop_line.yaw).abs() > 0.7 {
                continue;
            }
            let d_line = pr.s - s_front;
            if d_line < -0.5 {
                continue; // already over the line: clear the junction
            }
            if light.color == LightColor::Yellow {
                let need = v * v / (2.0 * (d_line - p.light_stop_margin_m).max(0.1));
                if need > p.yellow_max_decel_mps2 {
                    continue;
                }
            } else {
                // A red that appears when even hard braking cannot stop the front before the
                // line (after yellow was run through): clear the junction rather than stop in it.
                let reach = (d_line - v * p.decision_period_s).max(0.05);
                if v * v / (2.0 * reach) > p.red_commit_decel_mps2 {
                    continue;
                }
            }
            out.push(StopPoint {
                s_stop: pr.s - p.light_stop_margin_m,
                v_at: 0.0,
                reason: SpeedReason::Light,
                creep_limit: Some(pr.s - p.creep_min_gap_m.min(p.light_stop_margin_m)),
            });
        }
        out
    }

    /// Corridor test of one footprint against the pursued path: the nearest arc it occupies.
    fn corridor_hit(
        &self,
        route: &Polyline,
        corners: &[Vec2; 4],
        s_lo: f64,
        s_hi: f64,
        half: f64,
    ) -> Option<f64> {
        let mut s_min = f64::INFINITY;
        let (mut left, mut right, mut inside) = (false, false, false);
        for c in corners {
            let pr = project_window(route, *c, s_lo, s_hi)?;
            // Only points that project inside the window (not onto its clamped ends) count.
            if pr.s <= s_lo + 1e-6 || pr.s >= s_hi - 1e-6 {
                continue;
            }
            let lat = pr.lateral - self.offset_at(pr.s);
            s_min = s_min.min(pr.s);
            if lat.abs() < half {
                inside = true;
            }
            if lat > 0.0 && lat < 8.0 {
                left = true;
            } else if lat <= 0.0 && lat > -8.0 {
                right = true;
            }
        }
        ((inside || (left && right)) && s_min.is_finite()).then_some(s_min)
    }

    /// Stop / follow constraints from actors in (or predicted in) the corridor ahead; plans a
    /// detour around a blocking static obstacle when a drivable oracle is given.
    fn actor_constraints(&mut self, input: &ExpertInput<'_>, s_ego: f64, v: f64) -> Vec<StopPoint> {
        let p = self.params.clone();
        let route = input.route;
        let ego = input.ego;
        let s_front = s_ego + ego.length_m * 0.5;
        let s_rear = s_ego - ego.length_m * 0.5;
        let horizon = v * v / (2.0 * p.comfort_decel_mps2) + v * p.time_headway_s + 40.0;
        let s_lo = s_rear - 0.5;
        let s_hi = s_front + horizon;
        let half_ego = ego.width_m * 0.5 + p.corridor_margin_m;
        let ego_lat =
            project_window(route, ego.pose.pos, s_ego - 3.0, s_ego + 3.0).map_or(0.0, |pr| pr.lateral);
        let steps = (p.prediction_horizon_s / p.prediction_step_s).floor() as usize;
        let mut out = Vec::new();
        let mut blocking_static: Vec<(f64, &ActorView)> = Vec::new();
        for a in input.actors {
            if !(a.pose.pos.is_finite() && a.pose.yaw.is_finite() && a.speed_mps.is_finite()) {
                continue;
            }
            let reach = horizon
                + a.speed_mps.abs() * p.prediction_horizon_s.max(p.crossing_horizon_s)
                + a.length_m
                + 10.0;
            if a.pose.pos.dist(ego.pose.pos) > reach {
                continue;
            }
            let moving = a.speed_mps.abs() > 0.2;
            let is_vehicle = !a.kind.is_static() && a.kind != ActorKind::Pedestrian;
            let fwd = Vec2::from_angle(a.pose.yaw);
            let behind = is_vehicle && moving && self.coming_up_behind(route, a, s_lo, s_hi, s_front);
            let crossing = is_vehicle && a.speed_mps > 3.0 && {
                let rel = wrap_angle(a.pose.yaw - ego.pose.yaw).abs();
                (CROSSING_MIN_RAD..=std::f64::consts::PI - CROSSING_MIN_RAD).contains(&rel)
            };
            let steps_here = if crossing {
                steps.max((p.crossing_horizon_s / p.prediction_step_s).floor() as usize)
            } else {
                steps
            };
            let last = if moving { steps_here } else { 0 };
            let travel_cap = if is_vehicle && moving { self.red_stop_travel(input, a) } else { None };
            for k in 0..=last {
                let t = k as f64 * p.prediction_step_s;
                let travel = travel_cap.map_or(a.speed_mps * t, |c| (a.speed_mps * t).min(c));
                let mut fp = a.footprint();
                // A vehicle coming up from behind or beside us along a lane is predicted along
                // it: a straight line would make one in the next lane cut across every bend of
                // our route and stop us for good in a stream of traffic. Others go straight.
                match input.follow_lane.filter(|_| k > 0 && behind) {
                    Some(follow) => match follow(a.pose.pos, a.pose.yaw, travel) {
                        Some(pose) => fp.pose = pose,
                        None => fp.pose.pos += fwd * travel,
                    },
                    None => fp.pose.pos += fwd * travel,
                }
                let Some(s_hit) = self.corridor_hit(route, &fp.corners(), s_lo, s_hi, half_ego) else {
                    continue;
                };
                if s_hit + a.length_m.max(a.width_m) < s_front {
                    continue; // beside or behind the ego: not ours to stop for
                }
                let d = (s_hit - s_front).max(0.0);
                if k > 0
                    && s_hit < s_front
                    && behind
                    && self.detour.is_none()
                    && self.right_behind(route, a, s_lo, s_hi, s_front - ego.length_m, half_ego)
                {
                    // A vehicle coming up right behind us in our lane (its front behind our rear),
                    // predicted to reach our corridor only beside or behind our front: braking
                    // cannot avoid that (the ego would only stay there longer); it has to keep
                    // its distance. Not while passing an obstacle (then the ego is the one
                    // changing lanes), nor for one in another lane (a merge: the ego yields).
                    continue;
                }
                if k > 0 {
                    let v_max = p.cruise_speed_mps.max(v);
                    let t_acc = ((v_max - v) / p.arrival_accel_mps2).max(0.0);
                    let d_acc = v * t_acc + 0.5 * p.arrival_accel_mps2 * t_acc * t_acc;
                    let t_arr = if d <= d_acc {
                        (-v + (v * v + 2.0 * p.arrival_accel_mps2 * d).sqrt()) / p.arrival_accel_mps2
                    } else {
                        t_acc + (d - d_acc) / v_max.max(0.1)
                    };
                    if t + p.conflict_slack_s < t_arr {
                        continue;
                    }
                    // Braking for an actor that would only get there after the ego has cleared
                    // the spot would leave the ego standing in its way: keep going.
                    if v > 2.0 {
                        let extent = a.length_m.max(a.width_m) + 2.0 * p.corridor_margin_m;
                        let t_clear = self.time_to_drive(d + extent + ego.length_m, v);
                        if t >= t_clear + p.pass_margin_s {
                            break;
                        }
                        // Committed: the ego can no longer stop short of the actor's path (braking
                        // would leave it standing there) and still clears it before the actor
                        // arrives: go on.
                        let room = s_hit - p.stop_gap_m - s_front - v * p.decision_period_s;
                        if room < v * v / (2.0 * p.comfort_decel_mps2) && t >= t_clear + COMMITTED_MARGIN_S {
                            break;
                        }
                    }
                }
                let along = wrap_angle(a.pose.yaw - route_heading(route, s_hit.max(s_front)));
                let v_along = a.speed_mps * along.cos();
                if is_vehicle && along.abs() < 0.8 && v_along > 0.5 && behind {
                    // Not a lead but a vehicle behind us: braking for it would only bring it onto
                    // us. In our lane it has to keep its distance; in the lane we merge into, once
                    // we are ahead of it by a gap it does not close at the speed we will drive
                    // over the next ~3 s (a bend may still slow us), we go on; otherwise yield.
                    if let Some(pr) = project_window(route, a.pose.pos, s_lo - 60.0, s_hi) {
                        let gap_behind = s_rear - (pr.s + a.length_m * 0.5);
                        // Our lane: the pursued path's, or where the ego is now (partly in the
                        // next lane during a detour or a merge, it is in that vehicle's way).
                        let reach_lat = half_ego + a.width_m * 0.5;
                        let in_our_lane = (pr.lateral - self.offset_at(pr.s)).abs() < reach_lat
                            || (pr.lateral - ego_lat).abs() < reach_lat;
                        let n = (3.0 * v).ceil() as usize + 1;
                        let v_min = self.envelope.iter().take(n).fold(v, |m, &e| m.min(e));
                        if gap_behind > 0.0
                            && (in_our_lane || gap_behind > 1.0 + 2.0 * (v_along - v_min).max(0.0))
                        {
                            break;
                        }
                    }
                }
                if is_vehicle && along.abs() < 0.8 && v_along > 0.5 {
                    // Lead vehicle: gap from its current rear to our front.
                    let s_now = project_window(route, a.pose.pos, s_lo, s_hi).map_or(s_hit, |pr| pr.s);
                    let gap = s_now - a.length_m * 0.5 - s_front;
                    let free = gap - p.stop_gap_m;
                    let v_follow = if free <= 0.0 {
                        0.0
                    } else {
                        let by_brake = (v_along * v_along + 2.0 * p.comfort_decel_mps2 * free).sqrt();
                        let by_headway =
                            if p.time_headway_s > 0.0 { free / p.time_headway_s } else { f64::INFINITY };
                        by_brake.min(by_headway.max(v_along.min(free)))
                    };
                    // Expressed as a stop point reached at speed v_follow right now. Queued
                    // close behind a crawling lead, the ego may creep up to it.
                    out.push(StopPoint {
                        s_stop: s_front + v * p.decision_period_s,
                        v_at: v_follow,
                        reason: SpeedReason::Lead { actor_id: a.id },
                        creep_limit: Some(s_now - a.length_m * 0.5 - p.creep_min_gap_m),
                    });
                } else {
                    if k == 0 && !moving {
                        blocking_static.push((s_hit, a));
                    }
                    // Something that may have to be passed: stop far enough back to leave room
                    // for the detour ramp.
                    let passable = input.drivable.is_some()
                        && k == 0
                        && !moving
                        && a.kind != ActorKind::Pedestrian
                        && !self.light_near(input, s_hit);
                    let gap = if passable { p.stop_gap_m.max(p.avoid_stop_gap_m) } else { p.stop_gap_m };
                    out.push(StopPoint {
                        s_stop: s_hit - gap,
                        v_at: 0.0,
                        reason: SpeedReason::Obstacle { actor_id: a.id },
                        creep_limit: (k == 0 && !moving).then(|| {
                            // Keep twice the gap from a person who may step towards the car.
                            let keep = if a.kind == ActorKind::Pedestrian { 2.0 } else { 1.0 };
                            s_hit - (keep * p.creep_min_gap_m).min(p.stop_gap_m)
                        }),
                    });
                }
                break;
            }
        }
        if let Some(drivable) = input.drivable {
            if self.detour.is_none() {
                if let Some(&(s_hit, _)) = blocking_static
                    .iter()
                    // Static objects, and vehicles that look parked (see `is_parked`).
                    .filter(|(s, a)| a.kind.is_static() || self.is_parked(input, a, *s))
                    .min_by(|x, y| x.0.total_cmp(&y.0))
                {
                    if s_hit - s_front < 40.0 + v * 3.0 {
                        self.detour = self.plan_detour(input, drivable, s_ego, v, s_hit);
                    }
                }
            }
            if self.detour.is_some() {
                return self.recheck_with_detour(input, s_ego, out);
            }
        }
        out
    }

    /// Time for the front to cover `dist` metres at the current speed `v`, slowing where the
    /// curve envelope of this decision asks for less (a turn across traffic is driven slower
    /// than the approach, so the current speed alone would promise a clearance that the turn
    /// does not keep).
    fn time_to_drive(&self, dist: f64, v: f64) -> f64 {
        let n = dist.max(0.0).ceil() as usize;
        let mut t = 0.0;
        for i in 0..n {
            let step = (dist - i as f64).min(1.0);
            let cap = self.envelope.get(i).copied().unwrap_or(f64::INFINITY);
            t += step / v.min(cap).max(0.5);
        }
        t
    }

    /// How far a braking vehicle's centre travels before its front stops at the red / yellow
    /// stop line it is heading for (its brake lights on and the stop comfortably possible):
    /// it is not predicted through the junction on a straight line. `None` when no such line.
    fn red_stop_travel(&self, input: &ExpertInput<'_>, a: &ActorView) -> Option<f64> {
        if !a.braking {
            return None;
        }
        let fwd = Vec2::from_angle(a.pose.yaw);
        let mut cap: Option<f64> = None;
        for light in input.lights {
            if !matches!(light.color, LightColor::Red | LightColor::Yellow)
                || !light.stop_line.pos.is_finite()
            {
                continue;
            }
            if wrap_angle(light.stop_line.yaw - a.pose.yaw).abs() > 0.5 {
                continue;
            }
            let rel = light.stop_line.pos - a.pose.pos;
            let ahead = rel.dot(fwd) - a.length_m * 0.5;
            let lateral = rel.dot(fwd.perp()).abs();
            if ahead < -0.5 || lateral > (0.6 * light.lane_width_m).max(1.0) {
                continue;
            }
            if a.speed_mps * a.speed_mps / (2.0 * ahead.max(0.1)) > 4.5 {
                continue;
            }
            let travel = (ahead + 0.5).max(0.0);
            cap = Some(cap.map_or(travel, |c: f64| c.min(travel)));
        }
        cap
    }

    /// A vehicle driving our way whose centre is behind our front.
    fn coming_up_behind(&self, route: &Polyline, a: &ActorView, s_lo: f64, s_hi: f64, s_front: f64) -> bool {
        a.speed_mps > 0.0
            && project_window(route, a.pose.pos, s_lo, s_hi).is_some_and(|pr| {
                pr.s < s_front && wrap_angle(a.pose.yaw - route_heading(route, pr.s)).abs() < 0.8
            })
    }

    /// The front of vehicle `a` is behind arc `s_rear` and its centre within the corridor
    /// (half width `half_ego` plus its own half width) of the route.
    fn right_behind(
        &self,
        route: &Polyline,
        a: &ActorView,
        s_lo: f64,
        s_hi: f64,
        s_rear: f64,
        half_ego: f64,
    ) -> bool {
        project_window(route, a.pose.pos, s_lo - a.length_m, s_hi).is_some_and(|pr| {
            pr.s + a.length_m * 0.5 < s_rear && pr.lateral.abs() < half_ego + a.width_m * 0.5
        })
    }

    /// A signal head on the route within 5 m before to 40 m after arc `s` (a standing vehicle
    /// there may be queuing for it).
    fn light_near(&self, input: &ExpertInput<'_>, s: f64) -> bool {
        input.lights.iter().any(|l| {
            l.stop_line.pos.is_finite()
                && project_window(input.route, l.stop_line.pos, s - 5.0, s + 40.0)
                    .is_some_and(|pr| pr.distance < 2.0 && pr.s > s - 5.0 + 1e-6 && pr.s < s + 40.0 - 1e-6)
        })
    }

    /// A vehicle standing still for `parked_after_s` of the expert's observation, with no
    /// signal head just beyond it, is treated as parked (passable like a static object).
    fn is_parked(&self, input: &ExpertInput<'_>, a: &ActorView, s_hit: f64) -> bool {
        !a.kind.is_static()
            && a.kind != ActorKind::Pedestrian
            && self.stationary_s(a.id) >= self.params.parked_after_s
            && !self.light_near(input, s_hit)
    }

    fn stationary_s(&self, id: u32) -> f64 {
        self.stationary.binary_search_by_key(&id, |e| e.0).map_or(0.0, |i| self.stationary[i].1)
    }

    /// Updates how long each actor has been seen standing still (ids sorted, deterministic).
    fn observe_actors(&mut self, actors: &[ActorView]) {
        let dt = self.params.decision_period_s;
        let mut next: Vec<(u32, f64)> = actors
            .iter()
            .filter(|a| a.speed_mps.is_finite() && a.speed_mps.abs() < 0.1)
            .map(|a| (a.id, self.stationary_s(a.id) + dt))
            .collect();
        next.sort_by_key(|e| e.0);
        next.dedup_by_key(|e| e.0);
        self.stationary = next;
    }

    /// With a detour in force, obstacles off the shifted corridor no longer constrain speed.
    fn recheck_with_detour(
        &self,
        input: &ExpertInput<'_>,
        s_ego: f64,
        stops: Vec<StopPoint>,
    ) -> Vec<StopPoint> {
        let p = &self.params;
        let route = input.route;
        let ego = input.ego;
        let s_front = s_ego + ego.length_m * 0.5;
        let half_ego = ego.width_m * 0.5 + p.corridor_margin_m;
        stops
            .into_iter()
            .filter(|st| match st.reason {
                SpeedReason::Obstacle { actor_id } => {
                    let Some(a) = input.actors.iter().find(|a| a.id == actor_id) else { return true };
                    if a.speed_mps.abs() > 0.2 {
                        return true;
                    }
                    self.corridor_hit(
                        route,
                        &a.footprint().corners(),
                        s_front - ego.length_m - 1.0,
                        s_front + 200.0,
                        half_ego,
                    )
                    .is_some()
                }
                _ => true,
            })
            .collect()
    }

    /// Finds the smallest lateral offset whose shifted path keeps the ego footprint on drivable
    /// ground and clear of every actor along the pass.
    fn plan_detour(
        &self,
        input: &ExpertInput<'_>,
        drivable: &dyn Fn(Vec2, f64) -> bool,
        s_ego: f64,
        v: f64,
        s_hit: f64,
    ) -> Option<Detour> {
        let p = &self.params;
        let route = input.route;
        let ego = input.ego;
        let half_ego = ego.width_m * 0.5 + p.corridor_margin_m;
        // Extent of the blocking cluster along the route (obstacles close together pass as one).
        let mut spans: Vec<(f64, f64)> = input
            .actors
            .iter()
            .filter(|a| a.speed_mps.abs() < 0.05)
            .filter_map(|a| {
                let corners = a.footprint().corners();
                let sh = self.corridor_hit(route, &corners, s_ego - 5.0, s_hit + 60.0, half_ego + 4.0)?;
                let far = corners
                    .iter()
                    .filter_map(|c| project_window(route, *c, sh - 5.0, sh + 30.0))
                    .map(|pr| pr.s)
                    .fold(sh, f64::max);
                (sh >= s_hit - 1.0).then_some((sh, far))
            })
            .collect();
        spans.sort_by(|x, y| x.0.total_cmp(&y.0));
        let (s_start, mut s_end) = (s_hit, s_hit);
        for (sh, far) in spans {
            if sh <= s_end + 10.0 {
                s_end = s_end.max(far);
            }
        }
        if s_end - s_start > p.avoid_max_length_m {
            return None; // a long line of standing things (a queue?): wait instead
        }
        let ramp = (p.avoid_ramp_per_mps * v.max(4.0)).max(p.avoid_ramp_min_m);
        // The offset must be reached when the front is 1 m short of the first obstacle.
        let s1 = s_start - ego.length_m * 0.5 - 1.0;
        let s0 = (s1 - ramp).max(s_ego);
        if s1 - s0 < 0.8 * p.avoid_ramp_min_m {
            return None;
        }
        let s2 = s_end + ego.length_m * 0.5 + 2.0;
        let s3 = s2 + ramp;
        for &mag in &p.avoid_offsets_m {
            for sign in [1.0, -1.0] {
                let d = Detour { offset: sign * mag, s0, s1, s2, s3 };
                if self.detour_clear(input, drivable, &d) {
                    return Some(d);
                }
            }
        }
        None
    }

    fn detour_clear(
        &self,
        input: &ExpertInput<'_>,
        drivable: &dyn Fn(Vec2, f64) -> bool,
        d: &Detour,
    ) -> bool {
        let route = input.route;
        let margin = self.params.corridor_margin_m;
        let half_w = input.ego.width_m * 0.5;
        let half_l = input.ego.length_m * 0.5;
        // Moving traffic in the lane the detour uses (from 50 m behind its start to 30 m past
        // its end): wait for a gap.
        // How far back such traffic matters: what a vehicle at its speed covers while the ego,
        // at its own (at least 2 m/s), drives the detour.
        let v_ego = input.ego.speed_mps.max(2.0);
        for a in input.actors.iter().filter(|a| a.speed_mps.abs() > 0.2) {
            let back = 50f64.max(a.speed_mps.abs() * (d.s3 - d.s0) / v_ego);
            if let Some(pr) = project_window(route, a.pose.pos, d.s0 - back, d.s3 + 30.0) {
                // Traffic already ahead and driving on along the route leaves the gap; the lead
                // law follows it if the ego catches up.
                let along = a.speed_mps * wrap_angle(a.pose.yaw - route_heading(route, pr.s)).cos();
                let leaving = pr.s > d.s0 + input.ego.length_m && along > 3.0;
                if !leaving && (pr.lateral - d.offset).abs() < half_w + 0.5 * a.width_m + 1.0 {
                    return false;
                }
            }
        }
        let mut s = d.s0;
        while s <= d.s3 {
            let o = d.offset_at(s);
            let base = route_point(route, s);
            let dir = Vec2::from_angle(route_heading(route, s));
            let n = dir.perp();
            let c = base + n * o;
            // Footprint edges (with a small inset) must stay on drivable lanes.
            for e in [-(half_w - 0.2), 0.0, half_w - 0.2] {
                if !drivable(c + n * e, dir.angle()) {
                    return false;
                }
            }
            for a in input.actors {
                if a.speed_mps.abs() > 0.2 {
                    continue;
                }
                // Actor corners, edge midpoints and centre against the ego rectangle + margin.
                let k = a.footprint().corners();
                let probes = [
                    k[0],
                    k[1],
                    k[2],
                    k[3],
                    k[0].lerp(k[1], 0.5),
                    k[1].lerp(k[2], 0.5),
                    k[2].lerp(k[3], 0.5),
                    k[3].lerp(k[0], 0.5),
                    a.pose.pos,
                ];
                for q in probes {
                    let rel = q - c;
                    if rel.dot(dir).abs() < half_l + margin && rel.dot(n).abs() < half_w + margin {
                        return false;
                    }
                }
            }
            s += 1.0;
        }
        true
    }
}

/// Lanes whose direction differs from the travel heading by more than this are oncoming.
const SAME_DIRECTION_MAX_RAD: f64 = 1.0;

/// The drivable-area oracle of a road network for [`ExpertInput::drivable`]: a point is usable
/// when a passenger lane containing it runs within ~57° of the travel heading, or when it lies
/// inside a junction outline.
pub fn network_drivable(net: &Network) -> impl Fn(Vec2, f64) -> bool + '_ {
    move |p: Vec2, heading: f64| {
        let idx = net.drivable();
        let mut lanes: SmallVec<[LaneIdx; 8]> = SmallVec::new();
        idx.lanes_at(p, &mut lanes);
        let along = lanes.iter().any(|&l| {
            let shape = &net.lanes[l].shape;
            shape.project(p).is_some_and(|pr| {
                wrap_angle(shape.heading_at(pr.s) - heading).abs() <= SAME_DIRECTION_MAX_RAD
            })
        });
        along || idx.junction_at(p).is_some()
    }
}

/// A vehicle counts as following a lane when it is within this distance of the lane's
/// centreline and heads along it within this angle (a lane change or a turn does not).
const FOLLOW_MAX_OFFSET_M: f64 = 1.0;
const FOLLOW_MAX_RAD: f64 = 0.1;

/// The lane-following predictor of a road network for [`ExpertInput::follow_lane`]: the lane
/// containing the point whose direction best matches the heading (within `FOLLOW_MAX_RAD`),
/// followed `d` metres on, straight on past its end.
pub fn network_lane_follower(net: &Network) -> impl Fn(Vec2, f64, f64) -> Option<Pose> + '_ {
    move |p: Vec2, yaw: f64, d: f64| {
        let mut lanes: SmallVec<[LaneIdx; 8]> = SmallVec::new();
        net.drivable().lanes_at(p, &mut lanes);
        let mut best: Option<(f64, LaneIdx, f64)> = None;
        for &l in &lanes {
            let shape = &net.lanes[l].shape;
            let Some(pr) = shape.project(p) else { continue };
            let dh = wrap_angle(shape.heading_at(pr.s) - yaw).abs();
            if pr.distance < FOLLOW_MAX_OFFSET_M && dh < FOLLOW_MAX_RAD && best.is_none_or(|b| dh < b.0) {
                best = Some((dh, l, pr.s));
            }
        }
        let (_, l, s) = best?;
        let shape = &net.lanes[l].shape;
        let (len, s1) = (shape.length(), s + d);
        if s1 <= len {
            Some(Pose::new(shape.point_at(s1), shape.heading_at(s1)))
        } else {
            let h = shape.heading_at(len);
            Some(Pose::new(shape.point_at(len) + Vec2::from_angle(h) * (s1 - len), h))
        }
    }
}

/// Speed limit of the drivable lane nearest to `p` (within 3 m), m/s.
pub fn network_speed_limit(net: &Network, p: Vec2) -> Option<f64> {
    net.drivable().nearest_lane(p, 3.0).map(|(l, _)| net.lanes[l].speed_mps)
}

impl Expert {
    /// Takes the steering geometry (wheelbase, rear axle → centre, maximum road-wheel angle)
    /// from the world's ego vehicle parameters. Values that would fail validation are ignored.
    pub fn set_vehicle(&mut self, v: &VehicleParams) {
        let mut p = self.params.clone();
        p.wheelbase_m = v.wheelbase_m;
        p.rear_to_center_m = v.rear_axle_to_center_m;
        p.max_wheel_angle_rad = v.max_steer_deg.to_radians();
        if p.validate().is_ok() {
            self.params = p;
            self.bicycle = *v;
        }
    }

    /// One decision from a live [`World`]: its ego (and its steering geometry, see
    /// [`Expert::set_vehicle`]), actors and lights, the lane speed limit and the map's
    /// drivable-area oracle. `route` is the scenario's ego route.
    pub fn act_in_world(&mut self, world: &World, route: &Polyline) -> ExpertAction {
        self.set_vehicle(world.vehicle_params());
        let net = world.map();
        let ego = *world.ego();
        let oracle = network_drivable(net);
        let follower = network_lane_follower(net);
        let input = ExpertInput {
            ego: &ego,
            route,
            actors: world.actors(),
            lights: world.lights(),
            speed_limit_mps: network_speed_limit(net, ego.pose.pos),
            drivable: Some(&oracle),
            follow_lane: Some(&follower),
        };
        self.act(&input)
    }
}

impl From<ExpertAction> for dh_env::drive::bridge::Decision {
    fn from(a: ExpertAction) -> Self {
        Self { steer: a.steer, target_speed_mps: a.target_speed_mps }
    }
}

/// The expert's plan at the `waypoints` and `meta` levels (docs/r4.md#action-levels): the same
/// decision, exposed as the plan those levels take, so `--agent expert` at every level measures
/// what the interface and its tracker cost.
impl Expert {
    /// Takes the wheel as it is (the waypoint tracker, not the bridge, steers at the plan
    /// levels): the expert's speed bounds read the current steer.
    fn sync_steer(&mut self, world: &World) {
        let wheel = world.ego_state().steer_angle_rad;
        let max = self.params.max_wheel_angle_rad;
        if wheel.is_finite() && max > 0.0 {
            self.last_steer = (-wheel / max).clamp(-1.0, 1.0);
        }
    }

    /// The pursued path (route plus any detour offset) sampled every metre from the ego's
    /// progress for `length_m`, world frame.
    fn pursued_path(&self, route: &Polyline, length_m: f64) -> Polyline {
        let ext = extend_route(route);
        let s0 = self.s_hint.unwrap_or(0.0);
        let n = (length_m.ceil() as usize).max(2);
        Polyline::new((0..=n).map(|i| self.path_point(&ext, s0 + length_m * i as f64 / n as f64)).collect())
    }

    /// `n` ego-frame waypoints (x forward, y left) `dt` s apart: the pursued path, at the
    /// distances the decision's target speed gives under the protocol's bridge pedals and the
    /// ego's longitudinal model (what the control level would drive).
    pub fn waypoints_in_world(
        &mut self,
        world: &World,
        route: &Polyline,
        n: usize,
        dt: f64,
    ) -> Vec<(f64, f64)> {
        self.sync_steer(world);
        let a = self.act_in_world(world, route);
        let ego = world.ego();
        let params = world.vehicle_params();
        let (mut v, mut s) = (ego.speed_mps.max(0.0), 0.0);
        let sub = ((dt / dh_env::DT_S).round() as usize).max(1);
        let h = dt / sub as f64;
        let mut dist = Vec::with_capacity(n);
        for _ in 0..n {
            for _ in 0..sub {
                let (throttle, brake) = dh_env::drive::bridge::pedals(a.target_speed_mps, v);
                let acc =
                    dh_env::world::longitudinal_accel(params, &Control { throttle, brake, steer: 0.0 }, v);
                let next = (v + acc * h).clamp(0.0, params.max_speed_mps);
                s += v * h;
                v = next;
            }
            dist.push(s);
        }
        if !ego.pose.pos.is_finite() || self.s_hint.is_none() {
            return dist.iter().map(|&d| (d, 0.0)).collect();
        }
        let path = self.pursued_path(route, s + 20.0);
        dh_env::drive::tracker::waypoints_along(&path, &ego.pose, &dist)
    }

    /// The meta-action closest to the decision: the speed action from the target against the
    /// ego speed, and the path action whose lane-graph path (as the env resolves it) lies
    /// nearest to the pursued path (FOLLOW_LANE on near ties). During a detour around a standing
    /// obstacle a path beyond the pursued one on the passing side (a whole lane over where the
    /// expert would shift less) counts a quarter of its distance: it passes as well.
    pub fn meta_in_world(&mut self, world: &World, route: &Polyline) -> MetaAction {
        self.sync_steer(world);
        let a = self.act_in_world(world, route);
        let ego = world.ego();
        let v = ego.speed_mps.max(0.0);
        let speed = if a.target_speed_mps <= META_STOP_MPS {
            SpeedAction::Stop
        } else if a.target_speed_mps > v + META_KEEP_BAND_MPS || (v < 1.0 && a.target_speed_mps > v) {
            SpeedAction::Accelerate
        } else if a.target_speed_mps < v - META_KEEP_BAND_MPS {
            SpeedAction::Decelerate
        } else {
            SpeedAction::Keep
        };
        // The path is compared over the next few seconds (where the next decisions can still
        // change it), nearest first.
        let step = (0.8 * v).max(META_SAMPLE_MIN_M);
        let reach = META_SAMPLES as f64 * step;
        let mut path = PathAction::FollowLane;
        let mut speed = speed;
        if self.s_hint.is_some() && ego.pose.pos.is_finite() {
            let own = self.pursued_path(route, reach);
            let samples: Vec<Vec2> = (1..=META_SAMPLES).map(|i| own.point_at(step * i as f64)).collect();
            // > 0: the detour passes on the left.
            let side = self.detour.map_or(0.0, |d| d.offset.signum());
            let meta = &mut self.meta;
            // Mean distance of a path action's path from the pursued one (weighted as above).
            let mut cost = |p: PathAction| {
                let Some(line) = meta.resolve_path(world.map(), route, &ego.pose, v, p, reach + 10.0) else {
                    return f64::INFINITY;
                };
                samples
                    .iter()
                    .map(|&q| {
                        line.project(q).map_or(f64::INFINITY, |pr| {
                            // `q` right of the line (lateral < 0): the line lies left of it.
                            let beyond = -pr.lateral * side > 0.0;
                            if beyond {
                                META_BEYOND_WEIGHT * pr.distance
                            } else {
                                pr.distance
                            }
                        })
                    })
                    .sum::<f64>()
                    / samples.len() as f64
            };
            let follow = cost(PathAction::FollowLane);
            let mut best = (follow, PathAction::FollowLane);
            for p in PathAction::ALL.into_iter().skip(1) {
                let c = cost(p);
                if c + META_PATH_TIE_M < best.0 {
                    best = (c, p);
                }
            }
            path = best.1;
            let mean = best.0;
            // During a detour no path action passes where the expert would (the pass uses space
            // beside the lane that the lane graph has no lane for): it stands rather than drive
            // into the obstacle. Elsewhere the nearest path is driven (a route's lane change or a
            // ramp merge only shifts over sooner or later than the expert would; a stand would
            // wait for a path the lane graph will not offer).
            if side != 0.0 && mean.is_finite() && mean > META_PATH_MISMATCH_M {
                speed = SpeedAction::Stop;
            }
        }
        MetaAction { path, speed }
    }
}

/// Targets at or below this are STOP; within this band of the ego speed, KEEP, m/s.
const META_STOP_MPS: f64 = 0.2;
/// Path samples compared (every `max(0.8 s · v, META_SAMPLE_MIN_M)` metres ahead).
const META_SAMPLES: usize = 5;
const META_SAMPLE_MIN_M: f64 = 5.0;
const META_KEEP_BAND_MPS: f64 = 0.5;
/// Another path action replaces FOLLOW_LANE only when its path is nearer by this, m.
const META_PATH_TIE_M: f64 = 0.3;
/// A path action whose path strays from the expert's by more than this (mean, m) is no match.
const META_PATH_MISMATCH_M: f64 = 1.0;
/// Weight of a path's distance beyond the expert's on a detour's passing side.
const META_BEYOND_WEIGHT: f64 = 0.25;
