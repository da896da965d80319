//! Waypoint tracker (docs/r4.md#action-levels): the controller behind the `waypoints` and `meta`
//! action levels, this project's extension of the protocol. A plan is K ego-frame points
//! (x forward, y left, metres) at fixed time steps; the tracker turns it into a control at every
//! 0.05 s tick until the next plan: pure pursuit with a speed-dependent lookahead for the wheel,
//! and a speed PID (with the plan's acceleration as feed-forward) for the pedals, both inverted
//! through the ego's own vehicle model. Deterministic: a function of the plan, the ego state and
//! the ticks since the plan arrived.

use super::bridge::Control;
use crate::geom::{wrap_angle, Polyline, Pose, Vec2};
use crate::vehicle_params::VehicleParams;
use crate::DT_S;
use serde::{Deserialize, Serialize};

/// Default number of plan points (the 8 points at 0.5 s: a 4 s horizon).
pub const DEFAULT_WAYPOINTS: usize = 8;
/// Default time between plan points, s.
pub const DEFAULT_WAYPOINT_DT_S: f64 = 0.5;
/// Plan points farther than this from the ego (either axis) are clipped to it, m.
pub const MAX_WAYPOINT_M: f64 = 200.0;
/// Straight extension of a plan's path beyond its last point (pursuit needs a lookahead target), m.
const PATH_EXTENSION_M: f64 = 50.0;
/// Plan points closer than this to the previous path point do not shape the path, m.
const MIN_PATH_STEP_M: f64 = 0.5;
/// A plan whose path ends nearer than this to the ego is extended along the ego heading, m.
const MIN_DIRECTION_M: f64 = 2.0;

/// The tracker's gains. `Ld = clamp(lookahead_base_m + lookahead_gain_s · v, min, max)`;
/// desired acceleration `a = a_plan + kp·e + ki·∫e + kd·ė` with `e` the plan speed
/// `speed_preview_s` ahead minus the ego speed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrackerGains {
    pub lookahead_base_m: f64,
    pub lookahead_gain_s: f64,
    pub lookahead_min_m: f64,
    pub lookahead_max_m: f64,
    /// 1/s.
    pub speed_kp: f64,
    /// 1/s².
    pub speed_ki: f64,
    /// Dimensionless.
    pub speed_kd: f64,
    /// |∫e| is kept below this, m.
    pub integral_limit_m: f64,
    /// The speed target is read this far ahead on the plan (pedal-to-speed lag), s.
    pub speed_preview_s: f64,
    /// Gain on the progress error (planned minus actual distance along the path) added to the
    /// speed target, 1/s: the ego ends where the plan puts it, not only at its speeds.
    pub progress_gain: f64,
    /// The progress error's contribution is kept within ± this, m/s.
    pub progress_limit_mps: f64,
    /// A plan speed at or below this is a stop: the brake holds the ego at rest.
    pub stop_speed_mps: f64,
    /// Brake pedal held at rest under a stop plan.
    pub hold_brake: f64,
}

impl Default for TrackerGains {
    fn default() -> Self {
        Self {
            lookahead_base_m: 3.0,
            lookahead_gain_s: 0.55,
            lookahead_min_m: 3.5,
            lookahead_max_m: 15.0,
            speed_kp: 3.0,
            speed_ki: 0.3,
            speed_kd: 0.0,
            integral_limit_m: 2.0,
            speed_preview_s: 0.25,
            progress_gain: 1.0,
            progress_limit_mps: 3.0,
            stop_speed_mps: 0.2,
            hold_brake: 0.6,
        }
    }
}

/// How well one decision's plan was tracked over the ticks it was held (logged per decision).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct TrackingError {
    /// Mean and largest distance of the ego centre from the plan's path, m.
    pub lateral_mean_m: f64,
    pub lateral_max_m: f64,
    /// Mean |plan speed − ego speed|, m/s.
    pub speed_mean_mps: f64,
    /// Ticks measured.
    pub ticks: u32,
}

/// A plan in the world frame: the path from where the ego was when it arrived, and the speed
/// profile implied by the points' spacing.
#[derive(Debug, Clone, PartialEq)]
struct WorldPlan {
    path: Polyline,
    /// (time since the plan arrived, speed) knots at the origin and at every point, from the
    /// points' spacing by finite differences (see [`speed_knots`]).
    speeds: Vec<(f64, f64)>,
    /// (time, planned distance from the origin) at the origin and at every point.
    progress: Vec<(f64, f64)>,
}

impl WorldPlan {
    fn new(origin: Pose, points: &[(f64, f64)], dt: f64) -> WorldPlan {
        let mut pts = Vec::with_capacity(points.len() + 2);
        pts.push(origin.pos);
        let mut progress = vec![(0.0, 0.0)];
        let mut prev = origin.pos;
        for (k, &(x, y)) in points.iter().enumerate() {
            let (x, y) = (clip_coord(x), clip_coord(y));
            let w = origin.local_to_world(x, y);
            let s_prev = progress[progress.len() - 1].1;
            progress.push(((k as f64 + 1.0) * dt, s_prev + w.dist(prev)));
            // Creeping or standing points say nothing about direction: the path keeps only
            // points at least MIN_PATH_STEP_M from the last one kept.
            if pts.last().is_some_and(|q: &Vec2| w.dist(*q) >= MIN_PATH_STEP_M) {
                pts.push(w);
            }
            prev = w;
        }
        // Extend straight on past the last point; along the ego heading for a plan that ends
        // within MIN_DIRECTION_M (a stop: its few centimetres of sideways scatter are no
        // direction to steer for).
        let n = pts.len();
        let dir = if n >= 2 && pts[n - 1].dist(origin.pos) >= MIN_DIRECTION_M {
            (pts[n - 1] - pts[n - 2]).normalized()
        } else {
            origin.forward()
        };
        pts.push(pts[n - 1] + dir * PATH_EXTENSION_M);
        let dists: Vec<f64> = progress.iter().map(|q| q.1).collect();
        WorldPlan { path: Polyline::new(pts), speeds: speed_knots(&dists, dt), progress }
    }

    /// Planned distance from the origin at `t` (linear between points, held after the last).
    fn progress_at(&self, t: f64) -> f64 {
        let p = &self.progress;
        for w in p.windows(2) {
            if t <= w[1].0 {
                let f = ((t - w[0].0) / (w[1].0 - w[0].0).max(1e-9)).clamp(0.0, 1.0);
                return w[0].1 + f * (w[1].1 - w[0].1);
            }
        }
        p.last().map_or(0.0, |q| q.1)
    }

    /// Plan speed at `t` s after the plan arrived (piecewise linear through the knots, held flat
    /// outside them) and its slope.
    fn speed_at(&self, t: f64) -> (f64, f64) {
        let k = &self.speeds;
        let Some(&first) = k.first() else { return (0.0, 0.0) };
        if t <= first.0 {
            return (first.1, 0.0);
        }
        for w in k.windows(2) {
            let (a, b) = (w[0], w[1]);
            if t <= b.0 {
                let slope = (b.1 - a.1) / (b.0 - a.0).max(1e-9);
                return (a.1 + slope * (t - a.0), slope);
            }
        }
        (k[k.len() - 1].1, 0.0)
    }
}

/// Speed knots `(k·dt, v_k)` from the planned distances `s_0 = 0, s_1, …` at `k·dt`: central
/// differences at the inner points, a second-order one-sided difference at the origin and a
/// backward one at the last point, all at least 0. Instantaneous speeds (not the segments' means
/// at their mid-times) keep a braking plan's front-loaded deceleration: segment means lag a
/// convex speed curve, and the ego would end past where the plan stops.
fn speed_knots(s: &[f64], dt: f64) -> Vec<(f64, f64)> {
    let n = s.len() - 1;
    if n == 1 {
        return vec![(0.5 * dt, (s[1] - s[0]) / dt)];
    }
    (0..=n)
        .map(|k| {
            let v = if k == 0 {
                // Bounded by twice the first segment's mean speed: a plan's first point says
                // where the ego is in dt, not how fast it goes at the very start.
                ((4.0 * s[1] - s[2] - 3.0 * s[0]) / (2.0 * dt)).min(2.0 * (s[1] - s[0]) / dt)
            } else if k == n {
                (s[n] - s[n - 1]) / dt
            } else {
                (s[k + 1] - s[k - 1]) / (2.0 * dt)
            };
            (k as f64 * dt, v.max(0.0))
        })
        .collect()
}

fn clip_coord(v: f64) -> f64 {
    if v.is_nan() {
        0.0
    } else {
        v.clamp(-MAX_WAYPOINT_M, MAX_WAYPOINT_M)
    }
}

/// The tracker's state: the plan being tracked, ticks since it arrived and the PID memory.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WaypointTracker {
    gains: TrackerGains,
    plan: Option<WorldPlan>,
    ticks: u64,
    integral: f64,
    last_error: Option<f64>,
    /// The last steer; held while the ego stands under a stop (the wheel stays where it was, as
    /// a driver's does, instead of following a path that has no direction at rest).
    last_steer: f64,
    acc: TrackingError,
}

impl WaypointTracker {
    pub fn new(gains: TrackerGains) -> Self {
        Self { gains, ..Self::default() }
    }

    pub fn gains(&self) -> &TrackerGains {
        &self.gains
    }

    /// Back to the start-of-episode state (no plan: zero control).
    pub fn reset(&mut self) {
        *self = Self::new(self.gains);
    }

    /// A new plan from the ego at `origin`: `points` are (x forward, y left) metres, `dt` s apart.
    /// Non-finite coordinates are treated as 0 and huge ones clipped to ±[`MAX_WAYPOINT_M`];
    /// an empty list is a plan to stand still where the ego is.
    pub fn set_plan(&mut self, origin: Pose, points: &[(f64, f64)], dt: f64) {
        let dt = if dt.is_finite() && dt > 0.0 { dt } else { DEFAULT_WAYPOINT_DT_S };
        let points: Vec<(f64, f64)> = if points.is_empty() { vec![(0.0, 0.0)] } else { points.to_vec() };
        self.plan = Some(WorldPlan::new(origin, &points, dt));
        self.ticks = 0;
        self.integral = 0.0;
        self.last_error = None;
    }

    /// Whether a plan is being tracked (none before the first valid one).
    pub fn has_plan(&self) -> bool {
        self.plan.is_some()
    }

    /// The control for the next tick from the ego's centre pose and speed; advances the plan
    /// clock by one tick and accumulates the tracking error.
    pub fn control(&mut self, ego: &Pose, speed_mps: f64, vehicle: &VehicleParams) -> Control {
        let Some(plan) = &self.plan else { return Control::default() };
        let g = self.gains;
        let v = if speed_mps.is_finite() { speed_mps.max(0.0) } else { 0.0 };
        let t = self.ticks as f64 * DT_S;
        // Error bookkeeping at the state the control is computed from.
        let (lateral, s_ego) = plan.path.project(ego.pos).map_or((0.0, 0.0), |p| (p.distance, p.s));
        let (v_now, _) = plan.speed_at(t);
        self.acc.lateral_max_m = self.acc.lateral_max_m.max(lateral);
        self.acc.lateral_mean_m += lateral;
        self.acc.speed_mean_mps += (v_now - v).abs();
        self.acc.ticks += 1;

        // Lateral: pure pursuit from the rear axle on the lookahead point of the path.
        let rear = ego.pos - ego.forward() * vehicle.rear_axle_to_center_m;
        let ld = (g.lookahead_base_m + g.lookahead_gain_s * v).clamp(g.lookahead_min_m, g.lookahead_max_m);
        let s_rear = plan.path.project(rear).map_or(0.0, |p| p.s);
        let target = plan.path.point_at((s_rear + ld).min(plan.path.length()));
        let d: Vec2 = target - rear;
        let chord = d.norm().max(1e-3);
        let alpha = wrap_angle(d.angle() - ego.yaw);
        let kappa = 2.0 * alpha.sin() / chord;
        let delta = (vehicle.wheelbase_m * kappa).atan();
        let max_wheel = vehicle.max_steer_deg.to_radians().max(1e-6);
        let steer = (-delta / max_wheel).clamp(-1.0, 1.0);

        // Longitudinal: PID on the previewed plan speed corrected by the progress error,
        // feed-forward of the plan's slope.
        let (v_plan, slope) = plan.speed_at(t + g.speed_preview_s);
        let lag = (plan.progress_at(t) - s_ego).min(plan.progress_at(f64::INFINITY) - s_ego);
        let v_ref =
            (v_plan + (g.progress_gain * lag).clamp(-g.progress_limit_mps, g.progress_limit_mps)).max(0.0);
        self.ticks += 1;
        if v_plan <= g.stop_speed_mps && v_ref <= g.stop_speed_mps && v < 0.5 {
            self.integral = 0.0;
            self.last_error = None;
            return Control { throttle: 0.0, brake: g.hold_brake, steer: self.last_steer };
        }
        self.last_steer = steer;
        let e = v_ref - v;
        self.integral = (self.integral + e * DT_S).clamp(-g.integral_limit_m, g.integral_limit_m);
        let de = self.last_error.map_or(0.0, |le| (e - le) / DT_S);
        self.last_error = Some(e);
        let a = slope + g.speed_kp * e + g.speed_ki * self.integral + g.speed_kd * de;
        let (throttle, brake) = pedals_for_accel(a, v, vehicle);
        Control { throttle, brake, steer }
    }

    /// The tracking error since the last call (mean over its ticks), and a fresh start.
    pub fn take_error(&mut self) -> TrackingError {
        let mut e = std::mem::take(&mut self.acc);
        if e.ticks > 0 {
            let n = f64::from(e.ticks);
            e.lateral_mean_m /= n;
            e.speed_mean_mps /= n;
        }
        e
    }
}

/// Pedals giving acceleration `a` at speed `v` under the world's longitudinal model
/// (`drive·throttle·(1 − v/v_max) − brake·max_brake − rolling − drag·v²`), clipped to [0, 1].
pub fn pedals_for_accel(a: f64, v: f64, p: &VehicleParams) -> (f64, f64) {
    let resist = if v > 0.0 { p.rolling_decel_mps2 } else { 0.0 } + p.drag_per_m * v * v;
    let need = a + resist;
    if need >= 0.0 {
        let authority = p.max_accel_mps2 * (1.0 - v / p.max_speed_mps).max(0.0);
        let t = if authority > 1e-9 { need / authority } else { 0.0 };
        (t.clamp(0.0, 1.0), 0.0)
    } else {
        let b = if p.max_brake_mps2 > 1e-9 { -need / p.max_brake_mps2 } else { 0.0 };
        (0.0, b.clamp(0.0, 1.0))
    }
}

/// Ego-frame waypoints (x forward, y left) along `path` from the ego's projection, at the
/// distances a speed profile reaches at `dt`, `2dt`, … (`distances[k]` = metres after `(k+1)·dt`).
pub fn waypoints_along(path: &Polyline, ego: &Pose, distances: &[f64]) -> Vec<(f64, f64)> {
    let s0 = path.project(ego.pos).map_or(0.0, |p| p.s);
    distances
        .iter()
        .map(|&d| {
            let w = path.pose_extended(s0 + d.max(0.0)).pos;
            let (f, r) = ego.to_forward_right(w);
            (f, -r)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The world's model would make `drive` depend on `world` (a module cycle): a rear-axle
    /// kinematic bicycle with the same longitudinal law stands in for it.
    #[derive(Debug, Clone, Copy)]
    struct EgoState {
        pose: Pose,
        speed_mps: f64,
    }
    impl EgoState {
        fn new(pose: Pose, speed_mps: f64) -> Self {
            Self { pose, speed_mps }
        }
    }
    fn accel(p: &VehicleParams, c: &Control, v: f64) -> f64 {
        let drive = p.max_accel_mps2 * c.throttle * (1.0 - v / p.max_speed_mps).max(0.0);
        let rolling = if v > 0.0 { p.rolling_decel_mps2 } else { 0.0 };
        drive - p.max_brake_mps2 * c.brake - rolling - p.drag_per_m * v * v
    }
    fn step(p: &VehicleParams, s: &EgoState, c: &Control) -> EgoState {
        let delta = -c.steer * p.max_steer_deg.to_radians();
        let beta = (p.rear_axle_to_center_m / p.wheelbase_m * delta.tan()).atan();
        let yaw_rate = s.speed_mps / p.rear_axle_to_center_m * beta.sin();
        let pos = s.pose.pos + Vec2::from_angle(s.pose.yaw + beta) * (s.speed_mps * DT_S);
        let speed = (s.speed_mps + accel(p, c, s.speed_mps) * DT_S).clamp(0.0, p.max_speed_mps);
        EgoState { pose: Pose::new(pos, s.pose.yaw + yaw_rate * DT_S), speed_mps: speed }
    }

    fn drive(tracker: &mut WaypointTracker, mut s: EgoState, ticks: usize) -> EgoState {
        let p = VehicleParams::default();
        for _ in 0..ticks {
            let c = tracker.control(&s.pose, s.speed_mps, &p);
            s = step(&p, &s, &c);
        }
        s
    }

    #[test]
    fn tracks_a_straight_constant_speed_plan() {
        let mut tr = WaypointTracker::new(TrackerGains::default());
        let mut s = EgoState::new(Pose::new(Vec2::new(0.0, 0.0), 0.0), 8.0);
        let mut last = TrackingError::default();
        for _ in 0..40 {
            // Replan at 4 Hz: 8 m/s along y = 1 (1 m to the ego's left at the start).
            let pts: Vec<(f64, f64)> = (1..=8)
                .map(|k| {
                    let (f, r) = s.pose.to_forward_right(Vec2::new(s.pose.pos.x + 4.0 * k as f64, 1.0));
                    (f, -r)
                })
                .collect();
            tr.set_plan(s.pose, &pts, 0.5);
            s = drive(&mut tr, s, 5);
            last = tr.take_error();
        }
        assert!((s.pose.pos.y - 1.0).abs() < 0.1, "{:?}", s.pose);
        assert!((s.speed_mps - 8.0).abs() < 0.3, "{}", s.speed_mps);
        let e = last;
        assert!(e.ticks == 5 && e.lateral_mean_m < 0.1 && e.speed_mean_mps < 0.3, "{e:?}");
    }

    #[test]
    fn stop_plan_brings_the_ego_to_rest_and_holds_it() {
        let mut tr = WaypointTracker::new(TrackerGains::default());
        let s = EgoState::new(Pose::new(Vec2::new(0.0, 0.0), 0.3), 6.0);
        tr.set_plan(s.pose, &[], 0.5);
        let s = drive(&mut tr, s, 80);
        assert!(s.speed_mps < 0.05, "{}", s.speed_mps);
    }

    #[test]
    fn a_braking_plan_stops_where_it_ends() {
        // 10 m/s braking at 4 m/s² from the start: at rest after 2.5 s, 12.5 m on. Replanned
        // at 4 Hz from where the plan says the ego should be, as a planner would.
        let mut tr = WaypointTracker::new(TrackerGains::default());
        let mut s = EgoState::new(Pose::new(Vec2::new(0.0, 0.0), 0.0), 10.0);
        for d in 0..24 {
            let t0 = d as f64 * 0.25;
            let pos = |t: f64| {
                let t = t.min(2.5);
                10.0 * t - 2.0 * t * t
            };
            let pts: Vec<(f64, f64)> =
                (1..=8).map(|k| (pos(t0 + 0.5 * k as f64) - s.pose.pos.x, 0.0)).collect();
            tr.set_plan(s.pose, &pts, 0.5);
            s = drive(&mut tr, s, 5);
        }
        assert!(s.speed_mps < 0.2, "{}", s.speed_mps);
        assert!((s.pose.pos.x - 12.5).abs() < 0.4, "{:?}", s.pose);
    }

    #[test]
    fn no_plan_is_zero_control_and_garbage_is_finite() {
        let p = VehicleParams::default();
        let mut tr = WaypointTracker::new(TrackerGains::default());
        let pose = Pose::new(Vec2::new(1.0, 2.0), 0.1);
        assert_eq!(tr.control(&pose, 3.0, &p), Control::default());
        for pts in [vec![(f64::NAN, f64::INFINITY), (1e300, -1e300)], vec![(0.0, 0.0); 50], vec![(-5.0, 3.0)]]
        {
            tr.set_plan(pose, &pts, f64::NAN);
            for v in [0.0, 5.0, 30.0, f64::NAN] {
                let c = tr.control(&pose, v, &p);
                assert!((0.0..=1.0).contains(&c.throttle) && (0.0..=1.0).contains(&c.brake), "{c:?}");
                assert!((-1.0..=1.0).contains(&c.steer), "{c:?}");
            }
        }
    }

    #[test]
    fn pedal_inversion_round_trips() {
        let p = VehicleParams::default();
        for (a, v) in [(1.0, 5.0), (-2.0, 10.0), (0.0, 12.0)] {
            let (t, b) = pedals_for_accel(a, v, &p);
            let got = accel(&p, &Control { throttle: t, brake: b, steer: 0.0 }, v);
            assert!((got - a).abs() < 1e-9, "{a} {v} {got}");
        }
    }

    #[test]
    fn waypoints_along_a_path_are_ego_frame_left_positive() {
        let path = Polyline::new(vec![Vec2::new(0.0, 5.0), Vec2::new(100.0, 5.0)]);
        let ego = Pose::new(Vec2::new(10.0, 5.0), std::f64::consts::FRAC_PI_2);
        // Ego heads north, the path runs east: the path's points are to the ego's right (y < 0).
        let w = waypoints_along(&path, &ego, &[5.0]);
        assert!((w[0].0 - 0.0).abs() < 1e-9 && (w[0].1 + 5.0).abs() < 1e-9, "{w:?}");
    }
}
