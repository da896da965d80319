//! Continuous lane changes for vehicles whose model moves them sideways in one step.
//!
//! SUMO (without its sublane model) and the native IDM's lane-pair paths put a vehicle on the
//! next lane within a tick or two: a 3 m sideways jump that a camera shows as a teleport. The
//! world keeps the model's pose for the model and shows (and collides) the vehicle at that pose
//! plus a lateral offset: a sideways step larger than [`JUMP_M`] in one tick is absorbed into the
//! offset, which then returns to zero at a lateral speed between [`MIN_LAT_MPS`] and
//! [`MAX_LAT_MPS`] (easing out over about [`EASE_S`]), with the heading turned into the
//! sideways motion. A lane change (≥ 2.5 m) then takes well over a second of continuous lateral
//! motion, and no vehicle moves sideways by more than `JUMP_M + MAX_LAT_MPS × DT_S` per tick.
//!
//! Deterministic: per-vehicle state in key order, no randomness.

use crate::geom::{wrap_angle, Pose};
use crate::DT_S;
use std::collections::BTreeMap;

/// A sideways step of the model's pose beyond this in one tick is a jump to smooth, m.
pub const JUMP_M: f64 = 0.15;
/// Fastest lateral speed while the offset returns to zero, m/s.
pub const MAX_LAT_MPS: f64 = 2.5;
/// Slowest lateral speed while it does (the offset's tail is not left to creep), m/s.
pub const MIN_LAT_MPS: f64 = 0.5;
/// Time scale of the ease-out (the lateral speed is offset / EASE_S, clamped), s.
pub const EASE_S: f64 = 1.0;
/// Largest heading turned into the sideways motion, rad.
const MAX_YAW_RAD: f64 = 0.3;

#[derive(Debug, Clone, Copy, Default)]
struct State {
    /// The model's pose last tick.
    raw: Pose,
    /// Offset to the left of the model's heading still to close, m.
    offset: f64,
}

/// Per-vehicle lateral smoothing of model poses (keyed by the model's vehicle key).
#[derive(Debug, Default)]
pub struct LaneChangeSmoother {
    states: BTreeMap<u64, State>,
}

impl LaneChangeSmoother {
    /// The pose to show for vehicle `key` whose model pose this tick is `raw`, moving at
    /// `speed_mps`. The first pose of a vehicle is shown as it is.
    pub fn smooth(&mut self, key: u64, raw: Pose, speed_mps: f64) -> Pose {
        let Some(st) = self.states.get_mut(&key) else {
            self.states.insert(key, State { raw, offset: 0.0 });
            return raw;
        };
        let left = raw.forward().perp();
        let step = (raw.pos - st.raw.pos).dot(left);
        let mut offset = st.offset;
        if step.abs() > JUMP_M {
            offset -= step;
        }
        st.raw = raw;
        if offset == 0.0 {
            st.offset = 0.0;
            return raw;
        }
        let lat = (offset.abs() / EASE_S).clamp(MIN_LAT_MPS, MAX_LAT_MPS);
        let close = (lat * DT_S).min(offset.abs());
        offset -= close * offset.signum();
        st.offset = offset;
        // Heading into the sideways motion (towards the model's lane: against the offset).
        let v_lat = -offset.signum() * close / DT_S;
        let yaw = (v_lat / speed_mps.max(1.0)).atan().clamp(-MAX_YAW_RAD, MAX_YAW_RAD);
        Pose::new(raw.pos + left * offset, wrap_angle(raw.yaw + if offset == 0.0 { 0.0 } else { yaw }))
    }

    /// Forgets vehicles that are gone (`keep(key)` false).
    pub fn retain(&mut self, mut keep: impl FnMut(u64) -> bool) {
        self.states.retain(|k, _| keep(*k));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Vec2;

    #[test]
    fn a_lane_jump_becomes_a_continuous_move_of_over_a_second() {
        let mut s = LaneChangeSmoother::default();
        let mut shown = Vec::new();
        for tick in 0..100 {
            let x = tick as f64 * 0.5; // 10 m/s east
            let y = if tick >= 10 { 3.2 } else { 0.0 }; // jumps one lane left at tick 10
            shown.push(s.smooth(7, Pose::new(Vec2::new(x, y), 0.0), 10.0));
        }
        let steps: Vec<f64> = shown.windows(2).map(|w| w[1].pos.y - w[0].pos.y).collect();
        assert!(steps.iter().all(|d| d.abs() <= 0.5), "{steps:?}");
        let moving = steps.iter().filter(|d| d.abs() > 1e-9).count();
        assert!(moving as f64 * DT_S >= 1.0, "lateral motion lasted {moving} ticks");
        assert!((shown.last().unwrap().pos.y - 3.2).abs() < 1e-9);
        assert!(shown.last().unwrap().yaw.abs() < 1e-12);
    }

    #[test]
    fn smooth_paths_are_left_alone() {
        let mut s = LaneChangeSmoother::default();
        for tick in 0..200 {
            let a = tick as f64 * 0.01;
            let raw = Pose::new(Vec2::new(30.0 * a.sin(), 30.0 * (1.0 - a.cos())), a);
            assert_eq!(s.smooth(1, raw, 15.0), raw);
        }
    }
}
