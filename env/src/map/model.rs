//! The in-memory road network, close to SUMO's `.net.xml` elements.

use crate::geom::{Polyline, Vec2};

pub type EdgeIdx = usize;
pub type LaneIdx = usize;
pub type JunctionIdx = usize;

/// `function` attribute of an edge.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EdgeFunction {
    Normal,
    Internal,
    Crossing,
    WalkingArea,
    Connector,
}

#[derive(Debug, Clone)]
pub struct Edge {
    pub id: String,
    pub function: EdgeFunction,
    pub from: Option<JunctionIdx>,
    pub to: Option<JunctionIdx>,
    /// Lanes ordered by SUMO lane index (0 = rightmost).
    pub lanes: Vec<LaneIdx>,
    pub priority: i32,
    pub name: Option<String>,
}

#[derive(Debug, Clone)]
pub struct Lane {
    pub id: String,
    pub edge: EdgeIdx,
    pub index: usize,
    pub speed_mps: f64,
    pub length_m: f64,
    pub width_m: f64,
    pub shape: Polyline,
    /// Vehicle classes allowed on the lane (SUMO semantics of allow/disallow resolved).
    pub allow: VClassSet,
}

impl Lane {
    /// Passenger cars may drive here (what "drivable" means for the ego).
    pub fn is_drivable(&self) -> bool {
        self.allow.contains(VClass::Passenger)
    }
}

#[derive(Debug, Clone)]
pub struct Junction {
    pub id: String,
    /// SUMO `type`: priority, traffic_light, right_before_left, dead_end, internal, ...
    pub kind: String,
    pub pos: Vec2,
    /// Outline polygon (may be empty for dead ends).
    pub shape: Vec<Vec2>,
}

/// SUMO `dir` attribute of a connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TurnDir {
    Straight,
    Left,
    Right,
    PartLeft,
    PartRight,
    Turnaround,
    Invalid,
}

#[derive(Debug, Clone)]
pub struct Connection {
    pub from_lane: LaneIdx,
    pub to_lane: LaneIdx,
    /// First internal lane crossed (`via`), if any.
    pub via: Option<LaneIdx>,
    /// Traffic light controlling the link and its index in the light's state string.
    pub tl: Option<String>,
    pub link_index: Option<usize>,
    pub dir: TurnDir,
    /// SUMO `state` (M, m, =, s, w, ...).
    pub state: char,
}

#[derive(Debug, Clone, PartialEq)]
pub struct TlPhase {
    pub duration_s: f64,
    /// One char per link index: r, y, g, G, s, u, o, O.
    pub state: String,
}

#[derive(Debug, Clone, PartialEq)]
pub struct TlLogic {
    pub id: String,
    pub program_id: String,
    pub offset_s: f64,
    pub phases: Vec<TlPhase>,
}

/// `<location>`: how network coordinates relate to the original projection.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Location {
    pub net_offset: Vec2,
    pub conv_boundary: [f64; 4],
    pub orig_boundary: [f64; 4],
    pub proj_parameter: String,
}

/// SUMO vehicle classes the simulator distinguishes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum VClass {
    Passenger,
    Bus,
    Truck,
    Bicycle,
    Pedestrian,
    Motorcycle,
    Emergency,
    Rail,
    Other,
}

/// Bit set of [`VClass`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct VClassSet(pub u16);

impl VClassSet {
    pub const ALL: VClassSet = VClassSet(u16::MAX);
    pub fn contains(self, c: VClass) -> bool {
        self.0 & (1 << c as u8) != 0
    }
    pub fn with(self, c: VClass) -> VClassSet {
        VClassSet(self.0 | (1 << c as u8))
    }
    pub fn without(self, c: VClass) -> VClassSet {
        VClassSet(self.0 & !(1 << c as u8))
    }
}
