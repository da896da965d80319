//! What the world exposes each tick to the drive, score, render and agent code: plain values,
//! no references into the world.

use crate::geom::{Obb, Pose};
use serde::{Deserialize, Serialize};

/// Kind of an actor; decides its collider class, its look and how scoring classes a contact.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ActorKind {
    Car,
    Bus,
    Truck,
    Motorcycle,
    Cyclist,
    Pedestrian,
    Cone,
    Barrier,
    /// Any other static object (a parked box, debris).
    StaticObject,
}

/// How a contact with the ego is classed by the protocol (docs/protocol.md#r4-termination).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ContactClass {
    Pedestrian,
    Vehicle,
    Static,
}

impl ActorKind {
    pub fn contact_class(self) -> ContactClass {
        match self {
            ActorKind::Pedestrian => ContactClass::Pedestrian,
            ActorKind::Car
            | ActorKind::Bus
            | ActorKind::Truck
            | ActorKind::Motorcycle
            | ActorKind::Cyclist => ContactClass::Vehicle,
            ActorKind::Cone | ActorKind::Barrier | ActorKind::StaticObject => ContactClass::Static,
        }
    }
    pub fn is_static(self) -> bool {
        self.contact_class() == ContactClass::Static
    }
}

/// One actor as seen at the end of a tick (the ego included, with id 0).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ActorView {
    pub id: u32,
    pub kind: ActorKind,
    pub pose: Pose,
    pub speed_mps: f64,
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    /// sRGB body colour.
    pub color: [u8; 3],
    pub braking: bool,
    /// Turn indicators lit: [`BLINKER_RIGHT`] | [`BLINKER_LEFT`] (both = hazard lights).
    #[serde(default)]
    pub blinkers: u8,
    /// Emergency beacons flashing (the scenario's `emergency = true`, or a SUMO `emergency`
    /// vClass). Drawn only; no dynamics read it.
    #[serde(default)]
    pub beacon: bool,
}

/// [`ActorView::blinkers`] bits.
pub const BLINKER_RIGHT: u8 = 1;
pub const BLINKER_LEFT: u8 = 2;

impl ActorView {
    /// An actor at rest with its kind's default size (zero sizes), no lamps lit and no beacon.
    pub fn at_rest(id: u32, kind: ActorKind, pose: Pose, color: [u8; 3]) -> ActorView {
        ActorView {
            id,
            kind,
            pose,
            speed_mps: 0.0,
            length_m: 0.0,
            width_m: 0.0,
            height_m: 0.0,
            color,
            braking: false,
            blinkers: 0,
            beacon: false,
        }
    }

    pub fn footprint(&self) -> Obb {
        Obb { pose: self.pose, half_length: self.length_m * 0.5, half_width: self.width_m * 0.5 }
    }
}

/// Signal shown to one controlled link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightColor {
    Red,
    Yellow,
    Green,
    Off,
}

impl LightColor {
    /// SUMO state letter → colour (`G`/`g` green, `y`/`Y` yellow, `r`/`R`/`s`/`u` red, `o`/`O` off).
    pub fn from_sumo(c: char) -> LightColor {
        match c {
            'G' | 'g' => LightColor::Green,
            'y' | 'Y' => LightColor::Yellow,
            'r' | 'R' | 's' | 'u' => LightColor::Red,
            _ => LightColor::Off,
        }
    }
}

/// A signal head at the stop line of one incoming lane.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrafficLightView {
    pub tl_id: String,
    /// Lane (SUMO lane id) whose stop line the head controls.
    pub lane_id: String,
    /// Centre of the stop line and the lane direction there.
    pub stop_line: Pose,
    pub lane_width_m: f64,
    pub color: LightColor,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SignKind {
    Stop,
    Yield,
    SpeedLimit,
}

/// A road sign placed by a scenario.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SignView {
    pub kind: SignKind,
    /// Where the post stands; yaw is the direction the sign face looks at.
    pub pose: Pose,
}
