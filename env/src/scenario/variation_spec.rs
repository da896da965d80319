//! `[variation]` as written and its resolved bounds (see [`super::variation`], which applies
//! them): kept apart from the application so that the schema and the resolver depend on the
//! bounds without depending on the resolved scenario they vary.

use crate::view::ActorKind;
use crate::{Error, Result};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// `[variation]` as written: bounds of the per-seed jitter (absent keys take the defaults).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct VariationSpec {
    /// The ego starts up to this far further along its route, m (default 2).
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub ego_start_m: Option<f64>,
    /// Relative jitter of the ego's initial speed, ± (default 0.1).
    #[serde(default)]
    #[schemars(range(min = 0, max = 0.5))]
    pub ego_speed: Option<f64>,
    /// Scripted actors' start moved along their path by up to ± this, m (default by kind:
    /// pedestrian 0.3, cyclist 1, others 2).
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub actor_start_m: Option<f64>,
    /// Relative jitter of scripted actors' speeds, ± (default 0.08).
    #[serde(default)]
    #[schemars(range(min = 0, max = 0.5))]
    pub actor_speed: Option<f64>,
    /// Relative jitter of trigger and brake thresholds (times, radii, ETAs, gaps, delays,
    /// decelerations, holds), ± (default 0.1).
    #[serde(default)]
    #[schemars(range(min = 0, max = 0.5))]
    pub trigger: Option<f64>,
    /// Obstacles moved along their heading by up to ± this, m (default 0.5).
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub obstacle_m: Option<f64>,
    /// Background traffic: departure times (vehicles, flow begins) moved by up to ± this, s
    /// (default 1.5; never before the warm-up starts).
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub traffic_depart_s: Option<f64>,
    /// Background traffic: relative jitter of the speed factors given per vehicle / flow, ±
    /// (default 0.05; SUMO draws the others from `speedDev` with its `--seed`).
    #[serde(default)]
    #[schemars(range(min = 0, max = 0.5))]
    pub traffic_speed: Option<f64>,
    /// Conditions a seed other than 0 draws from, uniformly and deterministically per seed:
    /// names as `r4 evaluate --conditions` takes them (`noon`, `dusk`, `night`, `overcast`,
    /// `rain`, `fog`, `night+rain`, ...). Absent: every seed keeps `[conditions]`.
    #[serde(default)]
    #[schemars(length(min = 1))]
    pub conditions: Option<Vec<String>>,
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

/// `[variation] conditions` → the conditions to draw from (errors name
/// `variation.conditions[i]`).
pub fn resolve_condition_choices(
    file: &Path,
    spec: Option<&VariationSpec>,
) -> Result<Vec<crate::conditions::Conditions>> {
    let Some(names) = spec.and_then(|s| s.conditions.as_ref()) else { return Ok(Vec::new()) };
    if names.is_empty() {
        return Err(Error::scenario(file, "variation.conditions", "[]", "list at least one condition"));
    }
    names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            crate::conditions::Conditions::parse(n)
                .map_err(|e| Error::scenario(file, format!("variation.conditions[{i}]"), n, e))
        })
        .collect()
}
