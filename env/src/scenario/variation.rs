//! Seeded variation of a scenario (`[variation]`, see `docs/scenario-format.md`): each episode
//! seed other than 0 jitters the ego's start and speed, the scripted actors' start places,
//! speeds, trigger and brake thresholds, the obstacles' places and the background traffic's
//! departures and speed factors, within the bounds the scenario declares (defaults per kind so
//! that every file varies). Seed 0 is the scenario exactly as written.
//!
//! All randomness of an episode comes from [`seeded_rng`]: portable splitmix64 streams, one per
//! element (the ego, actor i, obstacle i, traffic), so adding an actor does not change how the
//! others vary.

use super::model::{ActorMotion, BrakeEvent, BrakeWhen, PaceMode, ResolvedScenario, ScriptedPath, Trigger};
use super::traffic::{seeded_rng, SplitMix, TrafficDemand};
use super::variation_spec::{default_actor_start_m, Variation};
use crate::geom::{Polyline, Pose, Vec2};

const STREAM_EGO: u64 = 0xE90_0000_0000;
const STREAM_ACTOR: u64 = 0xAC7_0000_0000;
const STREAM_OBSTACLE: u64 = 0x0B5_0000_0000;
const STREAM_TRAFFIC: u64 = 0x7AF_0000_0000;
const STREAM_CONDITIONS: u64 = 0xC0D_0000_0000;

/// Uniform in [−1, 1).
fn sym(rng: &mut SplitMix) -> f64 {
    2.0 * rng.unit() - 1.0
}

/// `x` × (1 ± `j`).
fn scale(rng: &mut SplitMix, x: f64, j: f64) -> f64 {
    x * (1.0 + j * sym(rng))
}

impl ResolvedScenario {
    /// The scenario as episode seed `seed` plays it: seed 0 exactly as written, other seeds
    /// jittered within [`ResolvedScenario::variation`].
    pub fn varied(&self, seed: u64) -> ResolvedScenario {
        let mut s = self.clone();
        if seed == 0 {
            return s;
        }
        let v = self.variation;
        if !self.condition_choices.is_empty() {
            let mut rng = seeded_rng(seed, STREAM_CONDITIONS);
            let k = ((rng.unit() * self.condition_choices.len() as f64) as usize)
                .min(self.condition_choices.len() - 1);
            s.conditions = self.condition_choices[k];
        }
        // Ego: further along its route (keeping its offset from the centreline), speed ±.
        let mut rng = seeded_rng(seed, STREAM_EGO);
        let route = &self.ego.route;
        let ds = (v.ego_start_m * rng.unit()).min(0.25 * route.length());
        let shift = route.point_at(ds) - route.point_at(0.0);
        let turn = route.heading_at(ds) - route.heading_at(0.0);
        s.ego.start =
            Pose::new(self.ego.start.pos + shift, crate::geom::wrap_angle(self.ego.start.yaw + turn));
        if self.ego.speed_mps > 0.0 {
            s.ego.speed_mps =
                scale(&mut rng, self.ego.speed_mps, v.ego_speed).min(self.ego.params.max_speed_mps);
        }
        for (i, a) in s.actors.iter_mut().enumerate() {
            match &mut a.motion {
                ActorMotion::Scripted(p) => {
                    let mut rng = seeded_rng(seed, STREAM_ACTOR + i as u64);
                    let d = v.actor_start_m.unwrap_or_else(|| default_actor_start_m(a.kind));
                    let delta = d * sym(&mut rng);
                    vary_scripted(p, &mut rng, delta, v);
                }
                ActorMotion::Static { pose } => {
                    let mut rng = seeded_rng(seed, STREAM_OBSTACLE + i as u64);
                    pose.pos += Vec2::from_angle(pose.yaw) * (v.obstacle_m * sym(&mut rng));
                }
                ActorMotion::External { .. } => {}
            }
        }
        s
    }
}

/// Moves a scripted actor's start by `delta` m along its path (> 0 forward; backward extends
/// the path straight), keeping its brake place, pace end and meet point where they are, and
/// scales its speeds and thresholds.
fn vary_scripted(p: &mut ScriptedPath, rng: &mut SplitMix, delta: f64, v: Variation) {
    let len = p.path.length();
    let delta = delta.min(0.5 * len);
    if delta > 0.0 {
        p.path = p.path.slice(delta, len);
    } else if delta < 0.0 {
        let p0 = p.path.point_at(0.0);
        let back = p0 + Vec2::from_angle(p.path.heading_at(0.0)) * delta;
        let mut pts = vec![back];
        pts.extend_from_slice(p.path.points());
        p.path = Polyline::new(pts);
    }
    let new_len = p.path.length();
    for leg in &mut p.legs {
        leg.0 = (leg.0 - delta).max(1e-3);
    }
    if let Some(last) = p.legs.last_mut() {
        last.0 = new_len;
    }
    let f = 1.0 + v.actor_speed * sym(rng);
    for leg in &mut p.legs {
        leg.1 *= f;
    }
    p.initial_speed_mps *= f;
    let tj = v.trigger;
    p.trigger = match p.trigger {
        Trigger::Time(t) => Trigger::Time(scale(rng, t, tj)),
        Trigger::EgoWithin { radius_m, point } => {
            Trigger::EgoWithin { radius_m: scale(rng, radius_m, tj), point }
        }
        Trigger::EgoEta { eta_s, point, route_s } => {
            Trigger::EgoEta { eta_s: scale(rng, eta_s, tj), point, route_s }
        }
        Trigger::After { actor, event, delay_s } => {
            Trigger::After { actor, event, delay_s: scale(rng, delay_s, tj) }
        }
    };
    if let Some(b) = &mut p.brake {
        let BrakeEvent { when, decel_mps2, hold_s, .. } = *b;
        b.when = match when {
            BrakeWhen::AtS(s) => BrakeWhen::AtS((s - delta).max(0.0) + tj * 10.0 * sym(rng)),
            BrakeWhen::AfterS(t) => BrakeWhen::AfterS(scale(rng, t, tj)),
            BrakeWhen::EgoWithin { radius_m, point } => {
                BrakeWhen::EgoWithin { radius_m: scale(rng, radius_m, tj), point }
            }
            BrakeWhen::EgoGap { gap_m } => BrakeWhen::EgoGap { gap_m: scale(rng, gap_m, tj) },
            BrakeWhen::EgoTimeGap { gap_s } => BrakeWhen::EgoTimeGap { gap_s: scale(rng, gap_s, tj) },
            BrakeWhen::EgoTtc { ttc_s } => BrakeWhen::EgoTtc { ttc_s: scale(rng, ttc_s, tj) },
            BrakeWhen::EgoEta { eta_s, point, route_s } => {
                BrakeWhen::EgoEta { eta_s: scale(rng, eta_s, tj), point, route_s }
            }
            BrakeWhen::GapHeld { held_s } => BrakeWhen::GapHeld { held_s: scale(rng, held_s, tj) },
            BrakeWhen::After { actor, event, delay_s } => {
                BrakeWhen::After { actor, event, delay_s: scale(rng, delay_s, tj) }
            }
        };
        if let BrakeWhen::AtS(s) = &mut b.when {
            *s = s.max(0.0);
        }
        b.decel_mps2 = scale(rng, decel_mps2, 0.5 * tj);
        b.hold_s = hold_s.map(|h| scale(rng, h, tj));
    }
    if let Some(q) = &mut p.pace {
        if q.until_s.is_finite() {
            q.until_s = (q.until_s - delta).max(0.0);
        }
        q.mode = match q.mode {
            PaceMode::Gap { gap_m, gap_s } => {
                let g = 1.0 + tj * sym(rng);
                PaceMode::Gap { gap_m: gap_m * g, gap_s: gap_s * g }
            }
            PaceMode::Meet { point, route_s, actor_s, offset_s } => PaceMode::Meet {
                point,
                route_s,
                actor_s: (actor_s - delta).max(0.0),
                offset_s: offset_s + 0.5 * tj * sym(rng),
            },
        };
    }
}

impl TrafficDemand {
    /// The demand as episode seed `seed` plays it: seed 0 as written; other seeds move each
    /// vehicle's departure and each flow's begin by up to ± `jitter.depart_s` (not before the
    /// warm-up starts) and scale the speed factors given per vehicle / flow.
    pub fn varied(&self, seed: u64) -> TrafficDemand {
        let mut d = self.clone();
        if seed == 0 {
            return d;
        }
        let j = self.jitter;
        let mut rng = seeded_rng(seed, STREAM_TRAFFIC);
        let floor = -self.warmup_s;
        // Departures at the warm-up start can only move later.
        let shift = |rng: &mut SplitMix, t: f64| {
            if t <= floor + 1e-9 {
                floor + j.depart_s * rng.unit()
            } else {
                (t + j.depart_s * sym(rng)).max(floor)
            }
        };
        for v in &mut d.vehicles {
            v.depart_s = shift(&mut rng, v.depart_s);
            v.speed_factor = v.speed_factor.map(|f| scale(&mut rng, f, j.speed));
        }
        for f in &mut d.flows {
            let begin = shift(&mut rng, f.begin_s);
            f.end_s = (f.end_s + begin - f.begin_s).max(begin + 1.0);
            f.begin_s = begin;
            f.speed_factor = f.speed_factor.map(|x| scale(&mut rng, x, j.speed));
        }
        d
    }
}
