//! The agent-facing side of the R4 protocol (docs/protocol.md#r4-prompt, #r4-actuation): route tracking, the
//! navigation command, the exact prompt text and the actuation bridge. Pure functions of the
//! tick state; no world access.

pub mod bridge;
pub mod command;
pub mod meta;
pub mod prompt;
pub mod prompt_levels;
pub mod route;
pub mod tracker;

pub use bridge::{ActuationBridge, Control, Decision, DecisionFailure};
pub use command::{navigation_command, Command};
pub use meta::{MetaAction, PathAction, SpeedAction};
pub use prompt::{condition_prefix, decision_prompt, format_1f, ACTION_QUESTION};
pub use route::{RouteTracker, RouteView, LOOKAHEAD_M, SAMPLE_DISTANCES_M};
pub use tracker::{TrackerGains, TrackingError, WaypointTracker};

/// A plan of the `waypoints` or `meta` action level (docs/r4.md#action-levels): what a
/// decision of those levels carries, as logged.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Plan {
    /// Ego-frame (x forward, y left) points, metres, one per plan time step.
    Waypoints(Vec<(f64, f64)>),
    Meta(MetaAction),
}

use crate::geom::Pose;

/// Everything the protocol derives from the ego state at one decision.
#[derive(Debug, Clone, PartialEq)]
pub struct DecisionContext {
    pub route: RouteView,
    pub command: Command,
    /// Condition prefix + action question, exactly as sent to the VLM.
    pub prompt: String,
}

/// Route view → navigation command → prompt text, for the ego at `ego` moving at `speed_mps`.
pub fn decision_context(tracker: &RouteTracker, ego: &Pose, speed_mps: f64) -> DecisionContext {
    let route = tracker.future_points(ego);
    let command = navigation_command(&route.points);
    let prompt = decision_prompt(speed_mps, command, route.distance_to_go_m, &route.points);
    DecisionContext { route, command, prompt }
}
