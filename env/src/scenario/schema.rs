//! Scenario file v1: the serde schema exactly as written in TOML (see `docs/scenario-format.md`).
//!
//! Every table rejects unknown keys. Alternatives (a place given by lane or by coordinates, a
//! trigger by time or by distance) are flat optional fields checked by the resolver, so errors
//! can say precisely which field is wrong instead of "no variant matched".

pub use super::tables::{CATEGORIES, SCENARIO_VERSION};
use crate::vehicle_params::VehicleParams;
use crate::view::{ActorKind, SignKind};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = crate::scenario::schema_rules::file_constraints)]
pub struct ScenarioFile {
    pub version: u32,
    pub id: String,
    #[serde(default)]
    pub name: Option<String>,
    pub category: String,
    #[serde(default)]
    pub description: String,
    /// Path relative to the scenario file, `sumo:<path under SUMO_HOME>`, or `builtin:<name>`
    /// for a map shipped with the package (`builtin:town01`, `builtin:town02`, ...).
    pub map: String,
    /// T_ref: the ego's reference duration (efficiency term only).
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub reference_duration_s: Option<f64>,
    /// The scenario duration: the longest estimated duration over all actors, ego included.
    /// The scenario timeout is 2 × it. Default: see `ResolvedScenario::scenario_duration_s`.
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub duration_s: Option<f64>,
    #[serde(default)]
    pub seed: u64,
    pub ego: EgoSpec,
    #[serde(default)]
    pub obstacles: Vec<ObstacleSpec>,
    #[serde(default)]
    pub actors: Vec<ActorSpec>,
    #[serde(default)]
    pub signs: Vec<SignSpec>,
    /// Background traffic (`[traffic]`, see `docs/traffic.md`).
    #[serde(default)]
    pub traffic: Option<crate::scenario::traffic::TrafficSpec>,
    /// Traffic-light program overrides (`[[lights]]`), applied in every traffic mode.
    #[serde(default)]
    pub lights: Vec<LightOverrideSpec>,
    /// Bounds of the per-seed jitter (`[variation]`; defaults apply when absent).
    #[serde(default)]
    pub variation: Option<crate::scenario::variation_spec::VariationSpec>,
    /// Light and weather (`[conditions]`; noon and clear when absent). Pictures only: the world
    /// runs the same.
    #[serde(default)]
    pub conditions: Option<crate::conditions::ConditionsSpec>,
}

/// A point (and optionally a heading) either on a lane (`lane` + `s` + `offset_m`) or in
/// network coordinates (`x`, `y`). `offset_m` > 0 is left of the lane direction;
/// `yaw_deg` (counter-clockwise from east) overrides the lane heading.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = crate::scenario::schema_rules::place_alternatives)]
pub struct PlaceSpec {
    #[serde(default)]
    pub lane: Option<String>,
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub s: Option<f64>,
    #[serde(default)]
    pub offset_m: Option<f64>,
    #[serde(default)]
    pub x: Option<f64>,
    #[serde(default)]
    pub y: Option<f64>,
    #[serde(default)]
    pub yaw_deg: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = crate::scenario::schema_rules::ego_alternatives)]
pub struct EgoSpec {
    #[serde(default)]
    pub start: Option<PlaceSpec>,
    #[serde(default)]
    pub destination: Option<PlaceSpec>,
    /// Edges the route must pass, in order; gaps are filled by shortest-path routing.
    #[serde(default)]
    pub route_edges: Option<Vec<String>>,
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub speed_mps: f64,
    #[serde(default)]
    pub color: Option<[u8; 3]>,
    /// Overrides of the vehicle parameters (dimensions and dynamics).
    #[serde(default)]
    pub vehicle: Option<VehicleParams>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ObstacleSpec {
    #[serde(default)]
    pub name: Option<String>,
    pub kind: ActorKind,
    pub at: PlaceSpec,
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub length_m: Option<f64>,
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub width_m: Option<f64>,
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub height_m: Option<f64>,
    #[serde(default)]
    pub color: Option<[u8; 3]>,
    /// An emergency vehicle (car, bus or truck): a light bar on its roof flashes red and blue.
    /// It changes only the picture; the actor still moves as scripted.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub emergency: bool,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum BehaviorSpec {
    /// Follows its path at its speeds once triggered.
    #[default]
    Scripted,
    /// Pose set by the caller every tick (SUMO co-simulation).
    External,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum AtEndSpec {
    /// Stays at the end of its path.
    #[default]
    Stop,
    /// Leaves the world (no collider, not drawn).
    Remove,
}

/// One point of a waypoint path; `speed_mps` is the speed on the leg that arrives here.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = crate::scenario::schema_rules::place_alternatives)]
pub struct WaypointSpec {
    #[serde(default)]
    pub lane: Option<String>,
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub s: Option<f64>,
    #[serde(default)]
    pub offset_m: Option<f64>,
    #[serde(default)]
    pub x: Option<f64>,
    #[serde(default)]
    pub y: Option<f64>,
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub speed_mps: Option<f64>,
}

/// A path along lanes: `edges` (gaps routed) or an explicit `lanes` list (junction internal
/// lanes inserted automatically), cut to [`start_s`, `end_s`] along the route.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = crate::scenario::schema_rules::route_alternatives)]
pub struct RouteSpec {
    #[serde(default)]
    pub edges: Option<Vec<String>>,
    #[serde(default)]
    pub lanes: Option<Vec<String>>,
    /// Lane of the first edge to start on (edges form only; default: routing's choice).
    #[serde(default)]
    pub start_lane: Option<String>,
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub start_s: Option<f64>,
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub end_s: Option<f64>,
    /// Lateral shift of the whole path, > 0 = left.
    #[serde(default)]
    pub offset_m: Option<f64>,
}

/// What the `of` of a distance trigger refers to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
#[schemars(transform = crate::scenario::schema_rules::of_alternatives)]
pub enum OfSpec {
    Point([f64; 2]),
    /// Only `"actor_self"`: the actor's own start position.
    Name(String),
    Place(PlaceSpec),
}

/// Start trigger: exactly one of `time_s` or `ego_within_m` (+ `of`, default `"actor_self"`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = crate::scenario::schema_rules::trigger_alternatives)]
pub struct TriggerSpec {
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub time_s: Option<f64>,
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub ego_within_m: Option<f64>,
    #[serde(default)]
    pub of: Option<OfSpec>,
    /// Time-to-conflict trigger: fires when the ego is expected to reach the projection of `of`
    /// on its route within this many seconds (route distance ÷ max(ego speed, 0.5 m/s)).
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub ego_eta_s: Option<f64>,
    /// Chained trigger: name of the actor whose `event` this one follows.
    #[serde(default)]
    pub after: Option<String>,
    /// Chained trigger: seconds after the other actor's event (default 0).
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub delay_s: Option<f64>,
    /// Chained trigger: which event of the other actor (default `start`).
    #[serde(default)]
    pub event: Option<ChainEventSpec>,
}

/// What a chained trigger follows.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ChainEventSpec {
    /// The other actor's start trigger fired.
    #[default]
    Start,
    /// The other actor began its brake event.
    Brake,
    /// The other actor reached the end of its path.
    End,
}

/// A lane change of a `route` actor: from arc length `at_s` along its path it moves over
/// `length_m` into `to_lane`, a neighbour lane of the edge it is on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LaneChangeSpec {
    #[schemars(range(min = 0))]
    pub at_s: f64,
    pub to_lane: String,
    /// Length of the manoeuvre along the path (default 20 m).
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub length_m: Option<f64>,
}

/// One phase of a replacement light program.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LightPhaseSpec {
    /// SUMO state string, one character per link index.
    pub state: String,
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub duration_s: f64,
}

/// `[[lights]]`: override of one traffic light's program: `offset_s` shifts it, `start_phase`
/// (+ `phase_elapsed_s`) sets where it is at t = 0, `phases` replaces it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = crate::scenario::schema_rules::light_alternatives)]
pub struct LightOverrideSpec {
    pub tls: String,
    #[serde(default)]
    pub offset_s: Option<f64>,
    #[serde(default)]
    pub start_phase: Option<usize>,
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub phase_elapsed_s: Option<f64>,
    #[serde(default)]
    pub phases: Option<Vec<LightPhaseSpec>>,
}

/// A hard-braking event: decelerate at `decel_mps2` to `to_speed_mps`, resume after `hold_s` if
/// given. When, exactly one of: at arc length `at_s` of the path; `after_s` seconds after the
/// trigger; when the ego comes within `ego_within_m` of `of` (default: the actor itself); when
/// the ego's bumper gap behind the actor along the ego route falls to `ego_gap_m`, its time gap
/// to `ego_gap_s` or its time to collision to `ego_ttc_s`; when the ego is expected to reach
/// `of` within `ego_eta_s`; `gap_held_s` after the actor's `pace` gap has settled; or chained
/// (`after` + `event`, `delay_s`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = crate::scenario::schema_rules::brake_alternatives)]
pub struct BrakeSpec {
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub at_s: Option<f64>,
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub after_s: Option<f64>,
    /// Brake when the ego centre comes within this radius of `of` (default: the actor's centre).
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub ego_within_m: Option<f64>,
    /// Brake when the ego's bumper gap behind the actor (along the ego route) is at most this, m.
    #[serde(default)]
    pub ego_gap_m: Option<f64>,
    /// Brake when the ego's time gap (bumper gap ÷ ego speed) is at most this, s.
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub ego_gap_s: Option<f64>,
    /// Brake when the ego's time to collision (bumper gap ÷ closing speed) is at most this, s.
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub ego_ttc_s: Option<f64>,
    /// Brake when the ego is expected to reach `of` (required) within this many seconds.
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub ego_eta_s: Option<f64>,
    /// Point of `ego_within_m` / `ego_eta_s`: `[x, y]`, a place, or `"actor_self"` (the actor
    /// where it is at that moment; `ego_within_m` only).
    #[serde(default)]
    pub of: Option<OfSpec>,
    /// Brake once the actor's `pace` gap has stayed within tolerance of its target this long, s.
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub gap_held_s: Option<f64>,
    /// Chained: name of the actor whose `event` this brake follows.
    #[serde(default)]
    pub after: Option<String>,
    /// Chained: seconds after the other actor's event (default 0).
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub delay_s: Option<f64>,
    /// Chained: which event of the other actor (default `start`).
    #[serde(default)]
    pub event: Option<ChainEventSpec>,
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub decel_mps2: f64,
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub to_speed_mps: f64,
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub hold_s: Option<f64>,
}

/// Ego-relative pacing of a scripted actor while it moves: either it holds a gap ahead of the
/// ego (`gap_s` × ego speed + `gap_m`, bumper to bumper along the ego route; negative = beside
/// the ego), or it times its arrival at a conflict point `meet` to the ego's (`offset_s` later).
/// Its speed stays within [`min_speed_mps`, `max_speed_mps`]; pacing ends at arc length
/// `until_s` of its path, after the meet point, or when its brake event begins.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = crate::scenario::schema_rules::pace_alternatives)]
pub struct PaceSpec {
    /// Time part of the gap: seconds at the ego's speed.
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub gap_s: Option<f64>,
    /// Distance part of the gap, m (may be negative: the actor's rear behind the ego's front).
    #[serde(default)]
    pub gap_m: Option<f64>,
    /// Conflict point (`[x, y]` or a place): on the actor's path and beside the ego route.
    #[serde(default)]
    pub meet: Option<OfSpec>,
    /// Meet mode: the actor reaches `meet` this many seconds after the ego would (< 0: before).
    #[serde(default)]
    pub offset_s: Option<f64>,
    /// Lower speed bound (default 0: the actor may wait).
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub min_speed_mps: Option<f64>,
    /// Upper speed bound (default 1.5 × the actor's speed).
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub max_speed_mps: Option<f64>,
    /// Arc length along the path where pacing ends (default: never).
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub until_s: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = crate::scenario::schema_rules::actor_alternatives)]
pub struct ActorSpec {
    #[serde(default)]
    pub name: Option<String>,
    pub kind: ActorKind,
    #[serde(default)]
    pub behavior: BehaviorSpec,
    /// Cruise speed; per-waypoint speeds override it leg by leg. Default by kind
    /// (pedestrian 1.2, cyclist 4.0, others 8.0 m/s).
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub speed_mps: Option<f64>,
    /// Speed at the moment of triggering (default: the first leg's speed).
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub initial_speed_mps: Option<f64>,
    /// Limit on speed changes between legs (default: pedestrians instant, others 3.0 m/s²).
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub accel_mps2: Option<f64>,
    #[serde(default)]
    pub waypoints: Option<Vec<WaypointSpec>>,
    #[serde(default)]
    pub route: Option<RouteSpec>,
    /// Where an `external` actor first stands (scripted actors start at their path start).
    #[serde(default)]
    pub at: Option<PlaceSpec>,
    #[serde(default)]
    pub start: Option<TriggerSpec>,
    #[serde(default)]
    pub brake: Option<BrakeSpec>,
    /// Ego-relative speed: hold a gap to the ego or meet it at a conflict point.
    #[serde(default)]
    pub pace: Option<PaceSpec>,
    #[serde(default)]
    pub at_end: AtEndSpec,
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub length_m: Option<f64>,
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub width_m: Option<f64>,
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub height_m: Option<f64>,
    #[serde(default)]
    pub color: Option<[u8; 3]>,
    /// An emergency vehicle (car, bus or truck): a light bar on its roof flashes red and blue.
    /// It changes only the picture; the actor still moves as scripted.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub emergency: bool,
    /// Lane changes / cut-ins of a `route` actor, in path order.
    #[serde(default)]
    pub lane_changes: Vec<LaneChangeSpec>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SignSpec {
    pub kind: SignKind,
    /// On a lane: the post stands `offset_m` (default: right edge + 1 m) beside the lane at `s`
    /// and faces oncoming traffic; by coordinates `yaw_deg` is the direction the face looks.
    pub at: PlaceSpec,
}
