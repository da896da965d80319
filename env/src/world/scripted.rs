//! Scripted scenario actors at run time: the phases of an actor on its path (waiting for its
//! trigger, moving, braking, holding, done), one tick of its motion ([`step_scripted`]) and the
//! constants of its ego-relative control. The resolved description they run is
//! [`crate::scenario::ScriptedPath`]; the inputs that need the whole world (the ego, other
//! actors' events) are computed by [`super::World`] and passed in as [`EgoRelative`].

use crate::geom::Pose;
use crate::scenario::{AtEnd, BrakeEvent, BrakeWhen, ScriptedPath};
use crate::view::ActorView;
use crate::DT_S;

/// Floor of the ego speed in the time-to-conflict estimate, m/s (a standing ego is expected to
/// move off at walking pace rather than never).
pub const ETA_MIN_SPEED_MPS: f64 = 0.5;
/// Gain of the gap controller: speed = ego speed − gain × (gap − target gap), 1/s.
pub const PACE_GAIN_PER_S: f64 = 0.5;
/// A pace gap counts as settled within max(this, 15 % of the target) of its target, m.
pub const PACE_SETTLED_M: f64 = 1.0;

/// Where a scripted actor is on its path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Phase {
    Waiting,
    Moving,
    Braking,
    Holding { until_s: f64 },
    Done,
}

/// Smooth heading along a path: direction of the chord over ±`h` around `s`.
pub(super) fn path_pose(path: &crate::geom::Polyline, s: f64, h: f64) -> Pose {
    let p = path.point_at(s);
    let len = path.length();
    let a = path.point_at((s - h).max(0.0));
    let b = path.point_at((s + h).min(len));
    let d = b - a;
    let yaw = if d.norm_sq() > 1e-12 { d.angle() } else { path.heading_at(s) };
    Pose::new(p, yaw)
}

/// Chord half-length of [`path_pose`] for a body of `length_m`.
pub(super) fn smoothing_m(length_m: f64) -> f64 {
    (0.25 * length_m).clamp(0.25, 2.0)
}

/// The ego-relative inputs of one scripted-actor step.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct EgoRelative {
    /// Speed its `pace` asks for now (None: not pacing, the leg speed applies).
    pub(super) pace_mps: Option<f64>,
    /// An ego-relative or chained brake condition holds now.
    pub(super) brake_due: bool,
    /// Gap pacing: whether the gap is within tolerance of its target (None: not measured).
    pub(super) gap_settled: Option<bool>,
}

/// One scripted-actor step (`fire`: its start trigger holds now); returns true when the actor
/// leaves the world.
#[allow(clippy::too_many_arguments)]
pub(super) fn step_scripted(
    id: u32,
    view: &mut ActorView,
    s: &mut f64,
    phase: &mut Phase,
    triggered_at_s: &mut f64,
    brake_pending: &mut bool,
    p: &ScriptedPath,
    t: f64,
    fire: bool,
    rel: EgoRelative,
    triggered: &mut Vec<u32>,
) -> bool {
    let prev_speed = view.speed_mps;
    if *phase == Phase::Waiting {
        if !fire {
            return false;
        }
        triggered.push(id);
        *phase = Phase::Moving;
        *triggered_at_s = t;
        view.speed_mps = p.initial_speed_mps;
    }
    // Brake event.
    if *brake_pending && *phase == Phase::Moving {
        if let Some(BrakeEvent { when, .. }) = p.brake {
            let due = match when {
                BrakeWhen::AtS(at) => *s >= at,
                BrakeWhen::AfterS(dt) => t - *triggered_at_s >= dt - 1e-9,
                _ => rel.brake_due,
            };
            if due {
                *brake_pending = false;
                *phase = Phase::Braking;
            }
        }
    }
    let mut v = view.speed_mps;
    match *phase {
        Phase::Braking => {
            let b = p.brake.unwrap_or(BrakeEvent {
                when: BrakeWhen::AtS(0.0),
                decel_mps2: 1.0,
                to_speed_mps: 0.0,
                hold_s: None,
            });
            v = (v - b.decel_mps2 * DT_S).max(b.to_speed_mps);
            if v <= b.to_speed_mps {
                *phase = match b.hold_s {
                    Some(h) => Phase::Holding { until_s: t + h },
                    None => Phase::Holding { until_s: f64::INFINITY },
                };
            }
        }
        Phase::Holding { until_s } => {
            if t >= until_s {
                *phase = Phase::Moving;
            }
        }
        Phase::Moving => {
            let target = rel.pace_mps.unwrap_or_else(|| p.leg_speed(*s));
            let dv = p.accel_mps2 * DT_S;
            v = if v < target { (v + dv).min(target) } else { (v - dv).max(target) };
        }
        Phase::Waiting | Phase::Done => {}
    }
    if *phase == Phase::Done {
        v = 0.0;
    }
    let len = p.path.length();
    *s += v * DT_S;
    if *s >= len {
        *s = len;
        if *phase != Phase::Done {
            *phase = Phase::Done;
            if p.at_end == AtEnd::Remove {
                return true;
            }
        }
        v = 0.0;
    }
    view.speed_mps = v;
    // Brake lamps: lit while slowing down, and while standing after that until it drives off.
    view.braking = v < prev_speed - 1e-9 || (v <= 1e-9 && view.braking);
    view.pose = path_pose(&p.path, *s, smoothing_m(view.length_m));
    false
}
