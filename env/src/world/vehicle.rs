//! Ego vehicle: a kinematic bicycle model referenced at the vehicle centre.
//!
//! Frame: SUMO network frame (x east, y north), yaw counter-clockwise. The control convention
//! of the protocol is steer < 0 = LEFT, so a negative steer turns the vehicle counter-clockwise.

use crate::geom::{wrap_angle, Pose, Vec2};
use crate::{Error, Result};
use serde::{Deserialize, Serialize};

pub use crate::drive::Control;
/// Moved below `world` and `scenario` (both use it); re-exported at its old path.
pub use crate::vehicle_params::VehicleParams;

/// Checks a control for NaN/∞ and clamps it to its ranges (throttle, brake ∈ [0,1], steer ∈ [−1,1]).
pub fn sanitize_control(c: &Control) -> Result<Control> {
    for (name, v) in [("throttle", c.throttle), ("brake", c.brake), ("steer", c.steer)] {
        if !v.is_finite() {
            return Err(Error::config(format!("control.{name}"), v, "must be a finite number"));
        }
    }
    Ok(Control {
        throttle: c.throttle.clamp(0.0, 1.0),
        brake: c.brake.clamp(0.0, 1.0),
        steer: c.steer.clamp(-1.0, 1.0),
    })
}

/// State of the ego after a tick.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EgoState {
    /// Vehicle centre and heading.
    pub pose: Pose,
    /// Speed along the velocity direction, m/s (≥ 0).
    pub speed_mps: f64,
    /// Longitudinal acceleration applied during the last tick, m/s².
    pub accel_mps2: f64,
    /// Road-wheel angle applied during the last tick, radians, counter-clockwise positive.
    pub steer_angle_rad: f64,
    /// Yaw rate during the last tick, rad/s.
    pub yaw_rate_rps: f64,
}

impl EgoState {
    pub fn new(pose: Pose, speed_mps: f64) -> Self {
        Self { pose, speed_mps, accel_mps2: 0.0, steer_angle_rad: 0.0, yaw_rate_rps: 0.0 }
    }
}

/// Longitudinal acceleration (m/s²) for a sanitised control at speed `v`.
#[inline]
pub fn longitudinal_accel(p: &VehicleParams, c: &Control, v: f64) -> f64 {
    let drive = p.max_accel_mps2 * c.throttle * (1.0 - v / p.max_speed_mps).max(0.0);
    let rolling = if v > 0.0 { p.rolling_decel_mps2 } else { 0.0 };
    drive - p.max_brake_mps2 * c.brake - rolling - p.drag_per_m * v * v
}

/// One explicit (forward) Euler step of the kinematic bicycle model at the vehicle centre:
/// the pose advances with the speed at the start of the step, then the speed is updated and
/// clamped to [0, max_speed]. `c` must be sanitised ([`sanitize_control`]).
#[inline]
pub fn step_bicycle(p: &VehicleParams, s: &EgoState, c: &Control, dt: f64) -> EgoState {
    let v = s.speed_mps;
    // steer < 0 is left = counter-clockwise = positive road-wheel angle.
    let delta = -c.steer * p.max_steer_deg.to_radians();
    let beta = (p.rear_axle_to_center_m / p.wheelbase_m * delta.tan()).atan();
    let yaw_rate = if p.rear_axle_to_center_m > 0.0 {
        v / p.rear_axle_to_center_m * beta.sin()
    } else {
        // Reference point on the rear axle: β = 0, classic ψ̇ = v·tan δ / L.
        v * delta.tan() / p.wheelbase_m
    };
    let heading = s.pose.yaw + beta;
    let pos = s.pose.pos + Vec2::from_angle(heading) * (v * dt);
    // Wrap only when needed so a standing vehicle keeps its yaw bit for bit.
    let yaw = s.pose.yaw + yaw_rate * dt;
    let yaw = if yaw > std::f64::consts::PI || yaw <= -std::f64::consts::PI { wrap_angle(yaw) } else { yaw };
    let a = longitudinal_accel(p, c, v);
    let speed = (v + a * dt).clamp(0.0, p.max_speed_mps);
    EgoState {
        pose: Pose::new(pos, yaw),
        speed_mps: speed,
        accel_mps2: a,
        steer_angle_rad: delta,
        yaw_rate_rps: yaw_rate,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DT_S;

    fn ctl(throttle: f64, brake: f64, steer: f64) -> Control {
        Control { throttle, brake, steer }
    }

    #[test]
    fn straight_acceleration_matches_formula() {
        let p = VehicleParams::default();
        let s = EgoState::new(Pose::default(), 10.0);
        let n = step_bicycle(&p, &s, &ctl(1.0, 0.0, 0.0), DT_S);
        let a = 4.0 * (1.0 - 10.0 / 40.0) - 0.15 - 0.0005 * 100.0;
        assert!((n.speed_mps - (10.0 + a * DT_S)).abs() < 1e-12);
        assert!((n.pose.pos.x - 0.5).abs() < 1e-12 && n.pose.pos.y == 0.0);
    }

    #[test]
    fn negative_steer_turns_left_counter_clockwise() {
        let p = VehicleParams::default();
        let mut s = EgoState::new(Pose::default(), 5.0);
        for _ in 0..10 {
            s = step_bicycle(&p, &s, &ctl(0.0, 0.0, -1.0), DT_S);
        }
        assert!(s.pose.yaw > 0.0 && s.pose.pos.y > 0.0);
        // Yaw rate = v/l_r · sin β with β = atan(0.5 tan 35°).
        let beta = (0.5 * 35f64.to_radians().tan()).atan();
        let s1 = step_bicycle(&p, &EgoState::new(Pose::default(), 5.0), &ctl(0.0, 0.0, -1.0), DT_S);
        assert!((s1.yaw_rate_rps - 5.0 / 1.45 * beta.sin()).abs() < 1e-12);
    }

    #[test]
    fn no_reverse_and_no_creep_at_rest() {
        let p = VehicleParams::default();
        let s = EgoState::new(Pose::default(), 0.1);
        let n = step_bicycle(&p, &s, &ctl(0.0, 1.0, 0.0), DT_S);
        assert_eq!(n.speed_mps, 0.0);
        let n2 = step_bicycle(&p, &n, &ctl(0.0, 0.0, 0.0), DT_S);
        assert_eq!(n2.speed_mps, 0.0);
        assert_eq!(n2.pose, n.pose);
    }

    #[test]
    fn control_is_checked_and_clamped() {
        assert!(sanitize_control(&ctl(f64::NAN, 0.0, 0.0)).is_err());
        assert!(sanitize_control(&ctl(0.0, 0.0, f64::INFINITY)).is_err());
        assert_eq!(sanitize_control(&ctl(2.0, -1.0, -3.0)).unwrap(), ctl(1.0, 0.0, -1.0));
    }

    #[test]
    fn top_speed_is_bounded() {
        let p = VehicleParams::default();
        let mut s = EgoState::new(Pose::default(), 0.0);
        for _ in 0..20_000 {
            s = step_bicycle(&p, &s, &ctl(1.0, 0.0, 0.0), DT_S);
        }
        assert!(s.speed_mps < 40.0 && s.speed_mps > 30.0);
    }
}
