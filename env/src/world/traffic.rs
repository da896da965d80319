//! The background-traffic seam of the world.
//!
//! A [`TrafficModel`] moves vehicles the scenario does not script: SUMO (driven from the Python
//! env through libsumo) or the `idm` reactive model ([`super::idm`]). Once per tick, after the
//! ego and the scripted actors moved, the world hands the model one [`TrafficInput`] (time, ego,
//! scenario actors, light colours) and takes back one [`TrafficFrame`]: every traffic vehicle
//! present this tick and any changed light states. [`World::apply_traffic`](super::World) turns
//! that batch into actors (spawned when a key first appears, removed when it disappears), so
//! traffic vehicles collide with the ego through the same rapier2d path as every actor.
//!
//! The world knows nothing about SUMO: keys are opaque, poses are vehicle centres in the map
//! frame, light states are SUMO-style state strings (one character per link index), which is
//! also how the map stores its programs.

use crate::geom::Pose;
use crate::map::Network;
use crate::view::{ActorKind, ActorView};
use crate::Result;

/// SUMO's signal bits (`VAR_SIGNALS`) as carried in [`TrafficAgent::signals`].
pub const SIGNAL_BLINKER_RIGHT: u32 = 1;
pub const SIGNAL_BLINKER_LEFT: u32 = 2;
pub const SIGNAL_BLINKER_EMERGENCY: u32 = 4;
pub const SIGNAL_BRAKELIGHT: u32 = 8;

/// SUMO's blinker bits as [`crate::view::ActorView::blinkers`] (emergency = both sides).
pub fn blinkers(signals: u32) -> u8 {
    let mut b = 0;
    if signals & (SIGNAL_BLINKER_RIGHT | SIGNAL_BLINKER_EMERGENCY) != 0 {
        b |= crate::view::BLINKER_RIGHT;
    }
    if signals & (SIGNAL_BLINKER_LEFT | SIGNAL_BLINKER_EMERGENCY) != 0 {
        b |= crate::view::BLINKER_LEFT;
    }
    b
}

/// One traffic vehicle at the end of a tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrafficAgent {
    /// The model's stable handle of the vehicle (never reused within an episode).
    pub key: u64,
    pub kind: ActorKind,
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    pub color: [u8; 3],
    /// Emergency beacons flashing (SUMO vClass `emergency`); drawn only.
    pub emergency: bool,
    /// Centre and heading.
    pub pose: Pose,
    pub speed_mps: f64,
    /// Signal bits ([`SIGNAL_BRAKELIGHT`], blinkers).
    pub signals: u32,
}

/// What a model returns for one tick.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TrafficFrame {
    /// Every traffic vehicle present now, in the model's order (spawn order follows it).
    pub agents: Vec<TrafficAgent>,
    /// Light states that changed: (light id, state string).
    pub lights: Vec<(String, String)>,
}

impl TrafficFrame {
    pub fn clear(&mut self) {
        self.agents.clear();
        self.lights.clear();
    }
}

/// What a model sees of the world each tick.
#[derive(Debug, Clone, Copy)]
pub struct TrafficInput<'a> {
    /// Ticks done (0 at the start of the episode).
    pub tick: u64,
    pub time_s: f64,
    pub ego: &'a ActorView,
    /// The scenario's own active actors (scripted, static, external), sorted by id.
    pub actors: &'a [ActorView],
    pub map: &'a Network,
    /// The world's signal heads (their colours as of this tick when the model does not drive
    /// the lights).
    pub lights: &'a [crate::view::TrafficLightView],
    /// The episode's variation seed: the demand is played as `TrafficDemand::varied` of it
    /// (0 = as written).
    pub variation_seed: u64,
}

/// A background-traffic model plugged into the world (see the module docs).
pub trait TrafficModel: Send + Sync + std::fmt::Debug {
    /// Starts an episode (t = 0, before the first tick): fills the vehicles present at t = 0.
    fn start(&mut self, input: &TrafficInput<'_>, seed: u64, out: &mut TrafficFrame) -> Result<()>;
    /// Advances one tick; `out` arrives cleared.
    fn tick(&mut self, input: &TrafficInput<'_>, out: &mut TrafficFrame) -> Result<()>;
    /// Whether the model's light states replace the world's fixed-time programs.
    fn drives_lights(&self) -> bool {
        false
    }
    /// Short name for messages ("sumo", "idm").
    fn name(&self) -> &str;
}
