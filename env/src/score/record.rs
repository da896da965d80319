//! The per-scenario score record: the original `scene_score.json` fields plus ours.

use super::event::{Event, TerminationReason};
use serde::{Deserialize, Serialize};

/// Version of the scoring protocol implemented here; written into every record.
pub const PROTOCOL_VERSION: &str = "drivehierarchy-r4/1";

/// Outcome class of a run.
///
/// The paper names the three statuses without defining them; our reading: `Completed` = the
/// run ended with `destination_reached`; `Perfect` = completed with a composed score of 100
/// (no penalty event, no off-road time, both efficiencies 1); `Failed` = any other end.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Status {
    Perfect,
    Completed,
    Failed,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Location {
    pub x: f64,
    pub y: f64,
}

/// `meta{}` of the record. Distances in metres, times in seconds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneMeta {
    pub route_length: f64,
    /// Best progress along the route (= route_length once the destination was reached).
    pub completed_distance: f64,
    pub travel_distance: f64,
    pub offroad_time: f64,
    /// offroad_time / sim_duration (0 for an empty run).
    pub offroad_ratio: f64,
    pub sim_duration: f64,
    pub wall_duration: f64,
    /// T_ref actually used (the scenario's, else route_length / 5.56).
    pub reference_duration: f64,
    /// Ours: "scenario" or "fallback".
    pub reference_duration_source: String,
    pub distance_efficiency: f64,
    pub time_efficiency: f64,
    pub destination_radius: f64,
    /// Ego centre at the last tick, world (SUMO network) frame.
    pub last_location: Location,
    /// Ours: Π penalty multipliers of the events.
    pub penalty_product: f64,
}

/// Secondary CARLA-leaderboard-style reading of the same rollout (not the protocol score):
/// driving score = route completion × Π infraction multipliers × (1 − off-road distance share).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CarlaDialect {
    pub driving_score: f64,
    pub route_completion: f64,
    pub infraction_penalty: f64,
    /// Share of the travelled distance driven with the ego centre off-road.
    pub offroad_fraction: f64,
    pub collisions_pedestrian: u32,
    pub collisions_vehicle: u32,
    pub collisions_static: u32,
    pub red_light_infractions: u32,
    pub stop_sign_infractions: u32,
    pub scenario_timeouts: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Dialects {
    pub carla: CarlaDialect,
}

/// The scene score record (`scene_score.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneScore {
    pub scene_id: String,
    pub status: Status,
    pub termination_reason: TerminationReason,
    /// 0–100.
    pub score_route: f64,
    /// 0–1.
    pub score_safety: f64,
    /// 0–1.
    pub score_efficiency: f64,
    /// score_safety × score_efficiency.
    pub score_penalty: f64,
    /// S_R4 = score_route × score_safety × score_efficiency, 0–100.
    pub score_composed: f64,
    pub events: Vec<Event>,
    pub meta: SceneMeta,
    // Ours.
    pub protocol_version: String,
    pub ticks: u64,
    pub decisions: u64,
    pub parse_failures: u64,
    pub dialects: Dialects,
}

/// What the runner knows that the score tracker does not.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunInfo {
    pub scene_id: String,
    pub wall_duration_s: f64,
    pub decisions: u64,
    pub parse_failures: u64,
}
