//! Scoring of R4 runs (docs/protocol.md#r4-termination, #r4-scene-score): events, termination
//! order and thresholds, the
//! route / safety / efficiency terms, the `scene_score.json` record, and re-scoring of a
//! recorded run without the simulator.

pub mod event;
pub mod params;
pub mod record;
pub mod replay;
pub mod tracker;

pub use event::{Contact, Event, EventKind, ExternalStop, Termination, TerminationReason, TickInput};
pub use params::{CarlaPenalties, Penalties, ScoreParams};
pub use record::{
    CarlaDialect, Dialects, Location, RunInfo, SceneMeta, SceneScore, Status, PROTOCOL_VERSION,
};
pub use replay::{rescore, LogLine, RunFooter, RunHeader, RunLog, TrajectorySample};
pub use tracker::ScoreTracker;
