//! Scenario files (TOML, schema v1 — see `docs/scenario-format.md`): parsing with precise
//! errors, and resolution against the map into world-frame geometry ([`ResolvedScenario`]).

pub mod json_schema;
pub mod map_paths;
pub mod model;
pub mod parse;
pub mod resolve;
pub mod schema;
pub mod schema_rules;
pub mod sumo_routes;
pub mod tables;
pub mod traffic;
pub mod variation;
pub mod variation_spec;

pub use json_schema::{scenario_json_schema, scenario_json_schema_string};
pub use map_paths::{
    resolve_map_path, set_builtin_maps_dir, LoadOptions, MapCache, BUILTIN_PREFIX, SUMO_PREFIX,
};
pub use model::{
    ActorMotion, AtEnd, BrakeEvent, BrakeWhen, ChainEvent, LightProgram, Pace, PaceMode, ResolvedActor,
    ResolvedEgo, ResolvedScenario, ScriptedPath, Trigger, DEFAULT_REFERENCE_SPEED_MPS, EGO_COLOR,
    ETA_MAX_OFFSET_M, PALETTE,
};
pub use parse::{parse_scenario_file, parse_scenario_str};
pub use resolve::{default_speed_mps, offset_polyline, OfRule, EGO_VCLASS, OF_RULES, SNAP_DISTANCE_M};
pub use schema::{ScenarioFile, CATEGORIES, SCENARIO_VERSION};
pub use tables::{default_size, vclass_of};
pub use traffic::seeded_rng;
pub use traffic::{TrafficDemand, TrafficMode};
pub use variation_spec::{Variation, VariationSpec};

use crate::Result;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Entry points for scenario files.
#[derive(Debug)]
pub struct Scenario;

impl Scenario {
    /// Reads, validates and resolves a scenario file (`sumo:` maps via the `SUMO_HOME`
    /// environment variable).
    pub fn load(path: impl AsRef<Path>) -> Result<ResolvedScenario> {
        Self::load_with(path, &LoadOptions::default())
    }

    pub fn load_with(path: impl AsRef<Path>, opts: &LoadOptions) -> Result<ResolvedScenario> {
        let path = path.as_ref();
        let text = parse::read_scenario_text(path)?;
        Self::load_str(path, &text, opts)
    }

    /// Parses and resolves scenario `text` standing for the file at `path` (an editor's unsaved
    /// buffer): relative map paths and error messages refer to `path`, which need not exist.
    pub fn load_str(path: impl AsRef<Path>, text: &str, opts: &LoadOptions) -> Result<ResolvedScenario> {
        let path = path.as_ref();
        let spec = parse_scenario_str(path, text)?;
        // Resolution errors name a TOML path; add where it is written in the file.
        resolve::resolve(path, &spec, opts).map_err(|e| parse::locate(e, path, text))
    }
}

/// What `drivehierarchy scenario validate FILE` prints.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    pub file: PathBuf,
    pub id: String,
    pub name: String,
    pub category: String,
    pub map: PathBuf,
    pub route_edges: Vec<String>,
    pub route_length_m: f64,
    /// Effective T_ref (the file's value, else L / 5.56 m/s).
    pub reference_duration_s: f64,
    pub actors: usize,
    pub obstacles: usize,
    pub signs: usize,
    /// Signal heads (controlled incoming lanes) in the map.
    pub traffic_lights: usize,
    /// Background traffic: mode and demand (`[traffic]`).
    pub traffic: String,
}

impl Summary {
    pub fn of(s: &ResolvedScenario) -> Summary {
        let obstacles = s.actors.iter().filter(|a| matches!(a.motion, ActorMotion::Static { .. })).count();
        Summary {
            file: s.file.clone(),
            id: s.id.clone(),
            name: s.name.clone(),
            category: s.category.clone(),
            map: s.map_path.clone(),
            route_edges: s.ego.route_edges.iter().map(|&e| s.map.edges[e].id.clone()).collect(),
            route_length_m: s.route_length_m(),
            reference_duration_s: s.reference_duration_s(),
            actors: s.actors.len() - obstacles,
            obstacles,
            signs: s.signs.len(),
            traffic_lights: crate::map::signal_heads(&s.map).len(),
            traffic: traffic_summary(&s.traffic),
        }
    }
}

fn traffic_summary(t: &TrafficDemand) -> String {
    if t.mode == TrafficMode::None && t.is_empty() {
        return "none".into();
    }
    let random =
        t.random.as_ref().map_or(String::new(), |r| format!(", random trips {}/lane-km", r.density_per_km));
    format!(
        "{}: {} vehicles, {} flows{random}, warm-up {} s",
        t.mode.as_str(),
        t.vehicles.len(),
        t.flows.len(),
        t.warmup_s
    )
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "{}: OK", self.file.display())?;
        writeln!(f, "  id        {} ({})", self.id, self.name)?;
        writeln!(f, "  category  {}", self.category)?;
        writeln!(f, "  map       {}", self.map.display())?;
        writeln!(
            f,
            "  route     {:.1} m over {} edges: {}",
            self.route_length_m,
            self.route_edges.len(),
            self.route_edges.join(" ")
        )?;
        writeln!(f, "  T_ref     {:.1} s", self.reference_duration_s)?;
        write!(
            f,
            "  actors    {} scripted/external, {} obstacles, {} signs, {} signal heads in the map\n  traffic   {}",
            self.actors, self.obstacles, self.signs, self.traffic_lights, self.traffic
        )
    }
}

/// Validates a scenario file completely (syntax, schema, map, routes, paths) and summarises it.
pub fn validate(path: impl AsRef<Path>) -> Result<Summary> {
    Ok(Summary::of(&Scenario::load(path)?))
}

/// [`validate`] with explicit load options (SUMO_HOME, map cache).
pub fn validate_with(path: impl AsRef<Path>, opts: &LoadOptions) -> Result<Summary> {
    Ok(Summary::of(&Scenario::load_with(path, opts)?))
}
