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

impl EdgeFunction {
    /// Parses SUMO's `function` attribute value (absent = `normal`).
    pub fn from_sumo(s: &str) -> Option<EdgeFunction> {
        Some(match s {
            "" | "normal" => EdgeFunction::Normal,
            "internal" => EdgeFunction::Internal,
            "crossing" => EdgeFunction::Crossing,
            "walkingarea" => EdgeFunction::WalkingArea,
            "connector" => EdgeFunction::Connector,
            _ => return None,
        })
    }
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
    /// SUMO edge `type` (empty when absent).
    pub type_id: String,
    /// Junction an internal / crossing / walking-area edge belongs to (`None` for normal edges).
    pub junction: Option<JunctionIdx>,
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

/// SUMO's default lane width, used when a lane has no `width` attribute.
pub const DEFAULT_LANE_WIDTH_M: f64 = 3.2;

#[derive(Debug, Clone)]
pub struct Junction {
    pub id: String,
    /// SUMO `type`: priority, traffic_light, right_before_left, dead_end, internal, ...
    pub kind: String,
    pub pos: Vec2,
    /// Outline polygon (may be empty for dead ends).
    pub shape: Vec<Vec2>,
    /// Lanes entering the junction (`incLanes`).
    pub inc_lanes: Vec<LaneIdx>,
    /// Internal lanes crossing the junction (`intLanes`).
    pub int_lanes: Vec<LaneIdx>,
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

impl TurnDir {
    /// Parses SUMO's `dir` letters (`s`, `l`, `r`, `L`, `R`, `t`, `invalid`).
    pub fn from_sumo(s: &str) -> Option<TurnDir> {
        Some(match s {
            "s" => TurnDir::Straight,
            "l" => TurnDir::Left,
            "r" => TurnDir::Right,
            "L" => TurnDir::PartLeft,
            "R" => TurnDir::PartRight,
            "t" | "T" => TurnDir::Turnaround,
            "invalid" => TurnDir::Invalid,
            _ => return None,
        })
    }
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

/// One signal-controlled link of a traffic light: index into the phase state string.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TlLink {
    pub link_index: usize,
    pub from_lane: LaneIdx,
    pub to_lane: LaneIdx,
    pub via: Option<LaneIdx>,
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
    /// SUMO `type`: static, actuated, delay_based, ...
    pub kind: String,
    pub program_id: String,
    pub offset_s: f64,
    pub phases: Vec<TlPhase>,
}

impl TlLogic {
    /// Length of one signal cycle, seconds.
    pub fn cycle_s(&self) -> f64 {
        self.phases.iter().map(|p| p.duration_s).sum()
    }
}

/// `<roundabout>`: its nodes and the edges forming the ring.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Roundabout {
    pub nodes: Vec<JunctionIdx>,
    pub edges: Vec<EdgeIdx>,
}

/// `<location>`: how network coordinates relate to the original projection.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Location {
    pub net_offset: Vec2,
    pub conv_boundary: [f64; 4],
    pub orig_boundary: [f64; 4],
    pub proj_parameter: String,
}

/// SUMO vehicle classes (every name SUMO 1.x accepts in `allow` / `disallow`).
///
/// `Other` stands for SUMO's `ignoring` class.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
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
    Private,
    Authority,
    Army,
    Vip,
    Hov,
    Taxi,
    Coach,
    Delivery,
    Trailer,
    Tram,
    RailUrban,
    RailElectric,
    RailFast,
    Moped,
    Evehicle,
    Ship,
    Container,
    CableCar,
    Subway,
    Aircraft,
    Wheelchair,
    Scooter,
    Drone,
    Custom1,
    Custom2,
}

/// (SUMO name, class); deprecated aliases of older SUMO versions come after the current names.
const VCLASS_NAMES: &[(&str, VClass)] = &[
    ("passenger", VClass::Passenger),
    ("bus", VClass::Bus),
    ("truck", VClass::Truck),
    ("bicycle", VClass::Bicycle),
    ("pedestrian", VClass::Pedestrian),
    ("motorcycle", VClass::Motorcycle),
    ("emergency", VClass::Emergency),
    ("rail", VClass::Rail),
    ("ignoring", VClass::Other),
    ("private", VClass::Private),
    ("authority", VClass::Authority),
    ("army", VClass::Army),
    ("vip", VClass::Vip),
    ("hov", VClass::Hov),
    ("taxi", VClass::Taxi),
    ("coach", VClass::Coach),
    ("delivery", VClass::Delivery),
    ("trailer", VClass::Trailer),
    ("tram", VClass::Tram),
    ("rail_urban", VClass::RailUrban),
    ("rail_electric", VClass::RailElectric),
    ("rail_fast", VClass::RailFast),
    ("moped", VClass::Moped),
    ("evehicle", VClass::Evehicle),
    ("ship", VClass::Ship),
    ("container", VClass::Container),
    ("cable_car", VClass::CableCar),
    ("subway", VClass::Subway),
    ("aircraft", VClass::Aircraft),
    ("wheelchair", VClass::Wheelchair),
    ("scooter", VClass::Scooter),
    ("drone", VClass::Drone),
    ("custom1", VClass::Custom1),
    ("custom2", VClass::Custom2),
    // Deprecated names still found in older networks.
    ("public_transport", VClass::Bus),
    ("public_emergency", VClass::Emergency),
    ("public_authority", VClass::Authority),
    ("public_army", VClass::Army),
    ("lightrail", VClass::Tram),
    ("cityrail", VClass::RailUrban),
    ("rail_slow", VClass::Rail),
    ("e_vehicle", VClass::Evehicle),
];

impl VClass {
    /// The class for a SUMO class name (`passenger`, `bus`, ...), or `None` if unknown.
    pub fn from_sumo(name: &str) -> Option<VClass> {
        VCLASS_NAMES.iter().find(|(n, _)| *n == name).map(|(_, c)| *c)
    }
    /// SUMO's current name of the class.
    pub fn sumo_name(self) -> &'static str {
        VCLASS_NAMES.iter().find(|(_, c)| *c == self).map(|(n, _)| *n).unwrap_or("ignoring")
    }
}

/// Bit set of [`VClass`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct VClassSet(pub u64);

impl VClassSet {
    pub const ALL: VClassSet = VClassSet(u64::MAX);
    pub const NONE: VClassSet = VClassSet(0);
    /// SUMO's current names of the classes in the set, in SUMO's order.
    pub fn sumo_names(self) -> Vec<&'static str> {
        let mut seen = VClassSet(0);
        let mut out = Vec::new();
        for &(name, class) in VCLASS_NAMES {
            if self.contains(class) && !seen.contains(class) {
                seen = seen.with(class);
                out.push(name);
            }
        }
        out
    }
    pub fn contains(self, c: VClass) -> bool {
        self.0 & (1 << c as u8) != 0
    }
    pub fn with(self, c: VClass) -> VClassSet {
        VClassSet(self.0 | (1 << c as u8))
    }
    pub fn without(self, c: VClass) -> VClassSet {
        VClassSet(self.0 & !(1 << c as u8))
    }
    pub fn intersect(self, o: VClassSet) -> VClassSet {
        VClassSet(self.0 & o.0)
    }
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }
    /// Parses a space-separated SUMO class list (`all` = every class). Returns the first
    /// unknown name on failure.
    pub fn parse_sumo(list: &str) -> Result<VClassSet, String> {
        let mut set = VClassSet::NONE;
        for name in list.split_ascii_whitespace() {
            if name == "all" {
                set = VClassSet::ALL;
            } else {
                set = set.with(VClass::from_sumo(name).ok_or_else(|| name.to_string())?);
            }
        }
        Ok(set)
    }
    /// SUMO lane semantics: `allow` wins when present, else everything but `disallow`.
    pub fn from_allow_disallow(allow: Option<&str>, disallow: Option<&str>) -> Result<VClassSet, String> {
        match (allow, disallow) {
            (Some(a), _) => VClassSet::parse_sumo(a),
            (None, Some(d)) => Ok(VClassSet(!VClassSet::parse_sumo(d)?.0)),
            (None, None) => Ok(VClassSet::ALL),
        }
    }
}
