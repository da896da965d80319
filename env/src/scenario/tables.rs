//! Constant tables of the scenario format that several scenario modules read: the schema
//! version and categories, SUMO's depart-lane/-speed names, and per-actor-kind sizes and vehicle
//! classes. They sit below `schema`, `schema_rules`, `traffic` and `resolve` so that none of
//! those needs another one for a constant (no cycle inside `scenario`).

use crate::map::VClass;
use crate::view::ActorKind;

/// Highest schema version this build reads.
pub const SCENARIO_VERSION: u32 = 1;

/// The ten R4 categories (docs/protocol.md#r4-categories), as written in `category` and used as
/// folder names.
pub const CATEGORIES: [&str; 10] = [
    "01_pedestrian",
    "02_obstacles",
    "03_turning",
    "04_intersection",
    "05_t_intersection",
    "06_traffic_flow",
    "07_sudden_brake",
    "08_merging",
    "09_yielding",
    "10_roundabout",
];

/// `depart_lane` names SUMO accepts (besides a lane index).
pub(crate) const LANE_NAMES: [&str; 4] = ["best", "random", "free", "first"];
/// `depart_speed` names SUMO accepts (besides m/s).
pub(crate) const SPEED_NAMES: [&str; 3] = ["max", "desired", "random"];

/// Default (length, width, height) in metres of each actor kind.
pub fn default_size(kind: ActorKind) -> (f64, f64, f64) {
    match kind {
        ActorKind::Car => (4.5, 1.9, 1.5),
        ActorKind::Bus => (12.0, 2.55, 3.2),
        ActorKind::Truck => (8.0, 2.5, 3.5),
        ActorKind::Motorcycle => (2.2, 0.8, 1.5),
        ActorKind::Cyclist => (1.8, 0.6, 1.7),
        ActorKind::Pedestrian => (0.5, 0.5, 1.75),
        ActorKind::Cone => (0.4, 0.4, 0.7),
        ActorKind::Barrier => (2.0, 0.5, 1.0),
        ActorKind::StaticObject => (1.0, 1.0, 1.0),
    }
}

/// SUMO vehicle class used to route an actor of this kind.
pub fn vclass_of(kind: ActorKind) -> VClass {
    match kind {
        ActorKind::Bus => VClass::Bus,
        ActorKind::Truck => VClass::Truck,
        ActorKind::Motorcycle => VClass::Motorcycle,
        ActorKind::Cyclist => VClass::Bicycle,
        ActorKind::Pedestrian => VClass::Pedestrian,
        _ => VClass::Passenger,
    }
}
