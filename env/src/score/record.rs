//! The per-scenario score record: the original `scene_score.json` fields plus ours.

use super::event::{Event, TerminationReason};
use serde::{Deserialize, Serialize};

/// Version of the scoring protocol implemented here; written into every record and run log.
/// 2: the original's record keys and rounding, the off-road timeout on the 31st tick, the
/// scenario timeout from the scenario duration.
pub const PROTOCOL_VERSION: &str = "drivehierarchy-r4/2";

/// Outcome class of a run, decided as the original's scorer decides it: `Perfect` when the
/// (rounded) route score is 100, the run did not end in a failure and the rounded safety and
/// efficiency terms are ≥ 0.999999; `Completed` when only the first two hold; else `Failed`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Status {
    Perfect,
    Completed,
    Failed,
}

/// `last_location` of the original: the ego centre at the last tick, metres, 3 decimals. Our
/// world is 2-D, so `z` is 0; x/y are in the scenario's network (SUMO) frame — the original
/// wrote CARLA's frame (x − offset, offset − y).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Location {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `meta{}` of the record: the original's keys, rounded as the original rounds them (3
/// decimals for lengths and times, 6 for ratios), then ours.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneMeta {
    /// What the route polyline was built from (`route_edges`: lane shapes along the ego's
    /// route edges, the original's first choice).
    pub route_source: String,
    pub route_length_m: f64,
    /// Best progress along the route (= route length once the destination was reached).
    pub completed_distance_m: f64,
    pub travel_distance_m: f64,
    pub offroad_time_s: f64,
    /// clip(offroad_time / duration, 0, 1) (0 for an empty run).
    pub offroad_ratio: f64,
    /// 1 − offroad_ratio.
    pub lane_keep_penalty: f64,
    /// Sim duration, seconds.
    pub duration_game: f64,
    /// Wall-clock duration, seconds.
    pub duration_system: f64,
    /// T_ref actually used (the scenario's, else route length / 5.56).
    pub reference_duration_s: f64,
    pub distance_efficiency: f64,
    pub time_efficiency: f64,
    pub destination_radius: f64,
    /// Distance from the route at the last on-road tick (`null` if never on the road).
    pub last_route_distance_m: Option<f64>,
    pub last_location: Location,
    // Ours, unrounded.
    /// "scenario" or "fallback" (T_ref = L / 5.56 m/s).
    pub reference_duration_source: String,
    /// The scenario duration (longest estimated duration over all actors).
    pub scenario_duration_s: f64,
    /// Scenario timeout: factor × scenario duration.
    pub max_sim_time_s: f64,
    /// Π penalty multipliers of the events.
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

/// The scene score record (`scene_score.json`): the original's keys, each `score_*` rounded to
/// 6 decimals as the original rounds them, then ours.
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
    /// round(score_safety × score_efficiency, 6) of the rounded terms.
    pub score_penalty: f64,
    /// S_R4 = round(score_route × score_penalty, 6) of the rounded terms, 0–100.
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

/// Python's `round(x, digits)`: the decimal nearest to the exact binary value, ties to even
/// (Rust's fixed-precision formatting is exact and ties to even too), read back as f64.
pub fn round_to(x: f64, digits: usize) -> f64 {
    if !x.is_finite() {
        return x;
    }
    let r: f64 = format!("{x:.digits$}").parse().unwrap_or(x);
    // Python keeps the sign of zero: round(-0.0001, 3) == -0.0.
    if r == 0.0 {
        0.0f64.copysign(x)
    } else {
        r
    }
}

#[cfg(test)]
mod tests {
    use super::round_to;

    #[test]
    fn rounding_matches_python() {
        // Values checked against CPython's round().
        assert_eq!(round_to(0.0078125, 6), 0.007812); // exact tie → even
        assert_eq!(round_to(0.0234375, 6), 0.023438); // exact tie → even
        assert_eq!(round_to(2.675, 2), 2.67); // binary value below the tie
        assert_eq!(round_to(1.0000005, 6), 1.000001);
        assert_eq!(round_to(0.15000000000000002, 3), 0.15);
        assert_eq!(round_to(99.99999949999999, 6), 99.999999);
        assert_eq!(round_to(99.9999995, 6), 100.0);
        assert_eq!(round_to(-0.0001, 3).to_bits(), (-0.0f64).to_bits());
        assert_eq!(round_to(123456.78949999999, 3), 123456.789);
    }
}
