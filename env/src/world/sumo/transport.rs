//! The narrow seam between the SUMO orchestration ([`super::SumoCoSim`]) and a SUMO client:
//! what to start, add, move, step and read. Three transports implement it: libsumo in this
//! process and TraCI to a `sumo` subprocess (both through the C++ shim, [`super::shim`]), and the
//! `libsumo` Python module (in the binding crate, the fallback when the shim was not built).
//!
//! A transport does no co-simulation logic: no command line, warm-up, light sync, mirrors,
//! departure keys or type cache. Those live once, in the orchestration, so every transport gives
//! the same traffic for the same calls.

use crate::Result;

/// One tracked vehicle present now: SUMO's front-bumper position, SUMO angle (degrees,
/// clockwise from north), speed and signal bits (`VAR_SIGNALS`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[repr(C)]
pub struct VehicleState {
    pub key: u64,
    pub x: f64,
    pub y: f64,
    pub angle: f64,
    pub speed: f64,
    pub signals: i32,
    pub _pad: i32,
}

/// A vehicle type's attributes (read once per type).
#[derive(Debug, Clone, PartialEq)]
pub struct TypeInfo {
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    pub vclass: String,
    /// RGBA.
    pub color: [i64; 4],
}

/// Whether `move_to_xy` placed the vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placed {
    Yes,
    /// SUMO cannot map it there (a TraCIException: off its network, too far from a lane its
    /// class may use, not known).
    Unmappable,
}

/// The SUMO client one co-simulation runs on. Errors carry SUMO's own message.
pub trait SumoTransport: Send + Sync + std::fmt::Debug {
    /// "libsumo", "libsumo-python" or "traci".
    fn kind(&self) -> &'static str;
    /// Whether this transport holds the process's one in-process SUMO (libsumo's global state).
    fn in_process(&self) -> bool;
    /// Starts SUMO with this command line (`cmd[0]` is the `sumo` binary).
    fn start(&mut self, cmd: &[String]) -> std::result::Result<(), String>;
    /// Stops SUMO (idempotent; also after a failed start).
    fn close(&mut self);
    fn time_s(&mut self) -> Result<f64>;
    /// The net's traffic lights, in SUMO's order.
    fn light_ids(&mut self) -> Result<Vec<String>>;
    /// Installs a replacement program (`[(state, duration s)]`) and switches the light to it.
    fn set_program(&mut self, tl: &str, phases: &[(String, f64)]) -> Result<()>;
    fn set_phase(&mut self, tl: &str, phase: usize, remaining_s: f64) -> Result<()>;
    /// Adds a vehicle departing now.
    fn add(&mut self, vid: &str, route: &str, vtype: &str) -> Result<()>;
    fn remove(&mut self, vid: &str) -> Result<()>;
    fn move_to_xy(&mut self, vid: &str, x: f64, y: f64, angle: f64, keep_route: u8) -> Result<Placed>;
    /// One simulation step; `departed` gets the ids of the vehicles that departed in it.
    fn step(&mut self, departed: &mut Vec<String>) -> Result<()>;
    fn vehicle_type(&mut self, vid: &str) -> Result<String>;
    fn type_info(&mut self, vtype: &str) -> Result<TypeInfo>;
    /// From now on [`SumoTransport::read`] reports `vid` under `key` until it leaves SUMO.
    fn track(&mut self, vid: &str, key: u64) -> Result<()>;
    /// The tracked vehicles present now, in id order (byte order of the ids).
    fn read(&mut self, out: &mut Vec<VehicleState>) -> Result<()>;
    /// Every light's state string, in [`SumoTransport::light_ids`] order.
    fn light_states(&mut self, out: &mut Vec<String>) -> Result<()>;
}
