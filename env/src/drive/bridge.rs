//! Actuation bridge (docs/protocol.md#r4-actuation): a (steer, target speed) decision → pedal and steering
//! commands, with the original's clipping, steering rate limit and launch floor.

use serde::{Deserialize, Serialize};

/// Largest steering change per decision (from the last valid steer).
pub const STEER_RATE_LIMIT: f64 = 0.12;
/// Target speeds are clipped to [0, this] m/s.
pub const MAX_TARGET_SPEED_MPS: f64 = 30.0;
/// At or below this target the bridge brakes to a stop.
pub const STOP_TARGET_MPS: f64 = 0.2;
/// Stop branch: brake = min(0.85, 0.35 + 0.25·v).
pub const STOP_BRAKE_BASE: f64 = 0.35;
pub const STOP_BRAKE_PER_MPS: f64 = 0.25;
/// Accelerate branch: throttle = 0.25 + 0.22·e.
pub const THROTTLE_BASE: f64 = 0.25;
pub const THROTTLE_PER_MPS: f64 = 0.22;
/// Launch floor: throttle ≥ 0.45 when target ≥ 0.8 and v < 0.8.
pub const LAUNCH_TARGET_MPS: f64 = 0.8;
pub const LAUNCH_SPEED_MPS: f64 = 0.8;
pub const LAUNCH_THROTTLE: f64 = 0.45;
/// Slow-down branch: brake = clip(0.30·(v − target), 0, 0.85).
pub const BRAKE_PER_MPS: f64 = 0.30;
/// Cap on both pedals.
pub const MAX_PEDAL: f64 = 0.85;

/// What a policy asks for at one decision.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Decision {
    /// Negative = left, positive = right; clipped to [−1, 1] by the bridge.
    pub steer: f64,
    /// Clipped to [0, 30] m/s by the bridge.
    pub target_speed_mps: f64,
}

/// Why a decision step carried no usable decision. The first three are the reply parser's
/// (`dh_agents::vlm::ParseFailure`); `no_reply` is a transport error or timeout; the last four
/// are the `waypoints` and `meta` levels' parsers' (`dh_agents::plan_reply`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DecisionFailure {
    MissingSteer,
    MissingTargetSpeed,
    MissingBoth,
    NoReply,
    MissingWaypoints,
    MissingPathAction,
    MissingSpeedAction,
    MissingMetaAction,
}

/// The command applied to the ego until the next decision. Pedals in [0, 1], steer in [−1, 1].
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Control {
    pub throttle: f64,
    pub brake: f64,
    pub steer: f64,
}

/// Stateful bridge: remembers the last valid steer (for the rate limit) and the last control
/// (held when a reply cannot be parsed).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ActuationBridge {
    last_steer: f64,
    last_control: Control,
    decisions: u64,
    parse_failures: u64,
}

#[inline]
fn clip(x: f64, lo: f64, hi: f64) -> f64 {
    x.max(lo).min(hi)
}

impl ActuationBridge {
    pub fn new() -> Self {
        Self::default()
    }

    /// Back to the start-of-episode state: last steer 0, zero control, counters 0.
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Turns one decision into a control at the current ego speed (m/s, a magnitude ≥ 0).
    ///
    /// `None` (an unparseable reply), or a decision with a NaN field, is a failure: it is
    /// counted and the previous control is returned verbatim — the pedals and steer computed at
    /// the last valid decision, not that decision re-evaluated at today's speed ("the previous
    /// valid control is retained", paper App. "Model-to-Control Interface"). Before any valid
    /// decision the previous control is the zero control, which is what the original runner
    /// applies before its first query. The last steer is not touched by a failure.
    pub fn apply(&mut self, decision: Option<Decision>, ego_speed_mps: f64) -> Control {
        self.decisions += 1;
        let Some(d) = decision.filter(|d| !d.steer.is_nan() && !d.target_speed_mps.is_nan()) else {
            self.parse_failures += 1;
            return self.last_control;
        };
        let steer = clip(d.steer, -1.0, 1.0);
        let steer = clip(steer, self.last_steer - STEER_RATE_LIMIT, self.last_steer + STEER_RATE_LIMIT);
        self.last_steer = steer;
        let (throttle, brake) = pedals(d.target_speed_mps, ego_speed_mps);
        self.last_control = Control { throttle, brake, steer };
        self.last_control
    }

    /// Steer of the last valid decision (0 at the start).
    pub fn last_steer(&self) -> f64 {
        self.last_steer
    }
    /// The control currently held.
    pub fn last_control(&self) -> Control {
        self.last_control
    }
    /// Calls to [`apply`](Self::apply) since the last reset.
    pub fn decisions(&self) -> u64 {
        self.decisions
    }
    /// Calls whose decision was missing or NaN.
    pub fn parse_failures(&self) -> u64 {
        self.parse_failures
    }
}

/// (throttle, brake) for a target speed at ego speed `v`, per docs/protocol.md#r4-actuation.
pub fn pedals(target_speed_mps: f64, v: f64) -> (f64, f64) {
    let target = clip(target_speed_mps, 0.0, MAX_TARGET_SPEED_MPS);
    let e = target - v;
    if target <= STOP_TARGET_MPS {
        (0.0, MAX_PEDAL.min(STOP_BRAKE_BASE + STOP_BRAKE_PER_MPS * v))
    } else if e >= 0.0 {
        let mut throttle = THROTTLE_BASE + THROTTLE_PER_MPS * e;
        if target >= LAUNCH_TARGET_MPS && v < LAUNCH_SPEED_MPS {
            throttle = throttle.max(LAUNCH_THROTTLE);
        }
        (clip(throttle, 0.0, MAX_PEDAL), 0.0)
    } else {
        (0.0, clip(BRAKE_PER_MPS * (v - target), 0.0, MAX_PEDAL))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn d(steer: f64, target: f64) -> Option<Decision> {
        Some(Decision { steer, target_speed_mps: target })
    }
    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn constants_are_the_protocol() {
        assert_eq!(STEER_RATE_LIMIT, 0.12);
        assert_eq!(MAX_TARGET_SPEED_MPS, 30.0);
        assert_eq!(STOP_TARGET_MPS, 0.2);
        assert_eq!((STOP_BRAKE_BASE, STOP_BRAKE_PER_MPS), (0.35, 0.25));
        assert_eq!((THROTTLE_BASE, THROTTLE_PER_MPS), (0.25, 0.22));
        assert_eq!((LAUNCH_TARGET_MPS, LAUNCH_SPEED_MPS, LAUNCH_THROTTLE), (0.8, 0.8, 0.45));
        assert_eq!(BRAKE_PER_MPS, 0.30);
        assert_eq!(MAX_PEDAL, 0.85);
    }

    #[test]
    fn steer_clip_and_rate_limit() {
        let mut b = ActuationBridge::new();
        assert_eq!(b.apply(d(5.0, 10.0), 10.0).steer, 0.12);
        assert!(close(b.apply(d(1.0, 10.0), 10.0).steer, 0.24));
        assert!(close(b.apply(d(0.2, 10.0), 10.0).steer, 0.2));
        assert!(close(b.apply(d(-1.0, 10.0), 10.0).steer, 0.08));
        assert!(close(b.last_steer(), 0.08));
        // Infinite steer clips like any other.
        assert!(close(b.apply(d(f64::NEG_INFINITY, 10.0), 10.0).steer, -0.04));
        b.reset();
        assert_eq!(b.last_steer(), 0.0);
        assert_eq!(b.apply(d(-0.05, 10.0), 10.0).steer, -0.05);
    }

    #[test]
    fn pedal_branches() {
        // Stop branch: target ≤ 0.2 (incl. negative targets clipped to 0).
        let (t, br) = pedals(0.2, 2.0);
        assert_eq!(t, 0.0);
        assert!(close(br, 0.85)); // 0.35 + 0.5 = 0.85
        assert!(close(pedals(-3.0, 1.0).1, 0.60));
        assert_eq!(pedals(0.0, 0.0), (0.0, 0.35));
        assert_eq!(pedals(0.1, 10.0), (0.0, 0.85));
        // Accelerate: e ≥ 0.
        let (t, br) = pedals(5.0, 3.0);
        assert!(close(t, 0.25 + 0.44));
        assert_eq!(br, 0.0);
        assert_eq!(pedals(30.0, 0.0).0, 0.85); // capped
        assert_eq!(pedals(100.0, 29.0).0, 0.47); // target clipped to 30: 0.25 + 0.22
                                                 // Launch floor: target ≥ 0.8 and v < 0.8.
        assert_eq!(pedals(0.8, 0.0).0, 0.45); // 0.25 + 0.176 < 0.45
        assert!(close(pedals(0.79, 0.0).0, 0.25 + 0.22 * 0.79)); // below the launch target
        assert!(close(pedals(1.5, 0.8).0, 0.25 + 0.22 * 0.7)); // v not < 0.8
        assert_eq!(pedals(1.0, 1.0), (0.25, 0.0)); // e = 0 is the accelerate branch
                                                   // Slow down: e < 0.
        let (t, br) = pedals(5.0, 6.0);
        assert_eq!(t, 0.0);
        assert!(close(br, 0.30));
        assert_eq!(pedals(5.0, 25.0).1, 0.85);
    }

    #[test]
    fn failure_holds_previous_control_verbatim() {
        let mut b = ActuationBridge::new();
        // First reply unparseable: the zero control.
        assert_eq!(b.apply(None, 4.0), Control::default());
        let c = b.apply(d(0.5, 3.0), 2.0);
        assert!(close(c.throttle, 0.47));
        // Held verbatim although the speed changed; last steer unchanged.
        assert_eq!(b.apply(None, 9.5), c);
        let nan = Some(Decision { steer: f64::NAN, target_speed_mps: 3.0 });
        assert_eq!(b.apply(nan, 9.5), c);
        assert_eq!(b.last_steer(), 0.12);
        assert_eq!((b.decisions(), b.parse_failures()), (4, 3));
        // Next valid reply rate-limits from the last valid steer.
        assert!(close(b.apply(d(1.0, 10.0), 10.0).steer, 0.24));
        b.reset();
        assert_eq!((b.decisions(), b.parse_failures(), b.last_control()), (0, 0, Control::default()));
    }
}
