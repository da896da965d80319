//! `dh-env`: the DriveHierarchy R4 world in pure Rust (no Python).
//!
//! Data flows one way: scenario file → world → observation (images, prompt, state) → agent →
//! action → actuation bridge → world. Scoring reads the world's event stream.

pub mod batch;
pub mod conditions;
pub mod drive;
pub mod error;
pub mod geom;
pub mod map;
pub mod render;
pub mod scenario;
pub mod score;
pub mod sim;
pub mod sumo_home;
pub mod vehicle_params;
pub mod view;
pub mod world;

pub use error::{Error, Result};

/// Fixed simulation step of the protocol (20 Hz).
pub const DT_S: f64 = 0.05;
/// The policy decides every 5 ticks (4 Hz).
pub const DECISION_INTERVAL_TICKS: u32 = 5;
