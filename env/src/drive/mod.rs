//! The agent-facing side of the R4 protocol (PROTOCOL.md §2.2–2.3): route tracking, the
//! navigation command, the exact prompt text and the actuation bridge. Pure functions of the
//! tick state; no world access.

pub mod bridge;
pub mod command;
pub mod prompt;
pub mod route;

pub use bridge::{ActuationBridge, Control, Decision};
pub use command::{navigation_command, Command};
pub use prompt::{condition_prefix, decision_prompt, format_1f, ACTION_QUESTION};
pub use route::{RouteTracker, RouteView, LOOKAHEAD_M, SAMPLE_DISTANCES_M};
