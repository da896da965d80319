//! Seeded variation of a scenario (`[variation]`, see `docs/scenario-format.md`): each episode
//! seed other than 0 jitters the ego's start and speed, the scripted actors' start places,
//! speeds, trigger and brake thresholds, the obstacles' places and the background traffic's
//! departures and speed factors, within the bounds the scenario declares (defaults per kind so
//! that every file varies). Seed 0 is the scenario exactly as written.
//!
//! All randomness of an episode comes from [`seeded_rng`]: portable splitmix64 streams, one per
//! element (the ego, actor i, obstacle i, traffic), so adding an actor does not change how the
//! others vary.

use super::resolve::{ActorMotion, BrakeEvent, BrakeWhen, PaceMode, ResolvedScenario, ScriptedPath, Trigger};
use super::traffic::{SplitMix, TrafficDemand};
use crate::geom::{Polyline, Pose, Vec2};
use crate::view::ActorKind;
use crate::{Error, Result};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The seeded generator of stream `stream` of episode seed `seed` (the one place RNGs are
/// built: random trips use stream 0, the native traffic model `0x1D_0000`).
pub fn seeded_rng(seed: u64, stream: u64) -> SplitMix {
    SplitMix::new(seed ^ stream)
}

const STREAM_EGO: u64 = 0xE90_0000_0000;
const STREAM_ACTOR: u64 = 0xAC7_0000_0000;
const STREAM_OBSTACLE: u64 = 0x0B5_0000_0000;
const STREAM_TRAFFIC: u64 = 0x7AF_0000_0000;

/// `[variation]` as written: bounds of the per-seed jitter (absent keys take the defaults).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct VariationSpec {
    /// The ego starts up to this far further along its route, m (default 2).
    #[serde(default)]
    pub ego_start_m: Option<f64>,
    /// Relative jitter of the ego's initial speed, ± (default 0.1).
    #[serde(default)]
    pub ego_speed: Option<f64>,
    /// Scripted actors' start moved along their path by up to ± this, m (default by kind:
    /// pedestrian 0.3, cyclist 1, others 2).
    #[serde(default)]
    pub actor_start_m: Option<f64>,
    /// Relative jitter of scripted actors' speeds, ± (default 0.08).
    #[serde(default)]
    pub actor_speed: Option<f64>,
    /// Relative jitter of trigger and brake thresholds (times, radii, ETAs, gaps, delays,
    /// decelerations, holds), ± (default 0.1).
    #[serde(default)]
    pub trigger: Option<f64>,
    /// Obstacles moved along their heading by up to ± this, m (default 0.5).
    #[serde(default)]
    pub obstacle_m: Option<f64>,
    /// Background traffic: departure times (vehicles, flow begins) moved by up to ± this, s
    /// (default 1.5; never before the warm-up starts).
    #[serde(default)]
    pub traffic_depart_s: Option<f64>,
    /// Background traffic: relative jitter of the speed factors given per vehicle / flow, ±
    /// (default 0.05; SUMO draws the others from `speedDev` with its `--seed`).
    #[serde(default)]
    pub traffic_speed: Option<f64>,
}

/// The resolved bounds of the per-seed jitter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Variation {
    pub ego_start_m: f64,
    pub ego_speed: f64,
    /// None: by kind ([`default_actor_start_m`]).
    pub actor_start_m: Option<f64>,
    pub actor_speed: f64,
    pub trigger: f64,
    pub obstacle_m: f64,
}

impl Default for Variation {
    fn default() -> Self {
        Variation {
            ego_start_m: 2.0,
            ego_speed: 0.1,
            actor_start_m: None,
            actor_speed: 0.08,
            trigger: 0.1,
            obstacle_m: 0.5,
        }
    }
}

/// Jitter of the background traffic (kept with the demand, which both traffic modes read).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrafficJitter {
    pub depart_s: f64,
    pub speed: f64,
}

impl Default for TrafficJitter {
    fn default() -> Self {
        TrafficJitter { depart_s: 1.5, speed: 0.05 }
    }
}

/// Default bound of an actor's start shift, m.
pub fn default_actor_start_m(kind: ActorKind) -> f64 {
    match kind {
        ActorKind::Pedestrian => 0.3,
        ActorKind::Cyclist => 1.0,
        _ => 2.0,
    }
}

/// Relative jitters must stay well below 1 (a speed or threshold never flips sign).
const MAX_RELATIVE: f64 = 0.5;

/// `[variation]` → the bounds (errors name `variation.<key>`).
pub fn resolve_variation(file: &Path, spec: Option<&VariationSpec>) -> Result<(Variation, TrafficJitter)> {
    let (mut v, mut t) = (Variation::default(), TrafficJitter::default());
    let Some(s) = spec else { return Ok((v, t)) };
    let abs = |key: &str, x: Option<f64>, d: f64| -> Result<f64> {
        match x {
            None => Ok(d),
            Some(x) if x.is_finite() && x >= 0.0 => Ok(x),
            Some(x) => {
                Err(Error::scenario(file, format!("variation.{key}"), x, "must be a finite number ≥ 0"))
            }
        }
    };
    let rel = |key: &str, x: Option<f64>, d: f64| -> Result<f64> {
        match x {
            None => Ok(d),
            Some(x) if x.is_finite() && (0.0..=MAX_RELATIVE).contains(&x) => Ok(x),
            Some(x) => Err(Error::scenario(
                file,
                format!("variation.{key}"),
                x,
                format!("a relative jitter must lie in [0, {MAX_RELATIVE}]"),
            )),
        }
    };
    v.ego_start_m = abs("ego_start_m", s.ego_start_m, v.ego_start_m)?;
    v.ego_speed = rel("ego_speed", s.ego_speed, v.ego_speed)?;
    v.actor_start_m = match s.actor_start_m {
        Some(x) => Some(abs("actor_start_m", Some(x), 0.0)?),
        None => None,
    };
    v.actor_speed = rel("actor_speed", s.actor_speed, v.actor_speed)?;
    v.trigger = rel("trigger", s.trigger, v.trigger)?;
    v.obstacle_m = abs("obstacle_m", s.obstacle_m, v.obstacle_m)?;
    t.depart_s = abs("traffic_depart_s", s.traffic_depart_s, t.depart_s)?;
    t.speed = rel("traffic_speed", s.traffic_speed, t.speed)?;
    Ok((v, t))
}

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
