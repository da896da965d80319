//! The `[traffic]` table: background-traffic demand (see `docs/traffic.md`).
//!
//! Demand is resolved here once (vehicle types, routes over the map) and realised per episode
//! seed into explicit vehicles: SUMO gets them as a route file ([`TrafficDemand::sumo_routes_xml`]),
//! the `idm` model ([`crate::world::idm`]) spawns them itself. Random trips are drawn here with
//! a seeded generator, so both modes see the same vehicles, routes and departure places.

/// Re-exported at its old path (moved to [`super::sumo_routes`], which sits above `resolve`).
pub use super::sumo_routes::mirror_specs;
use super::tables::{default_size, vclass_of, LANE_NAMES, SPEED_NAMES};
use crate::geom::Polyline;
use crate::map::{EdgeFunction, EdgeIdx, Network, VClass};
use crate::view::ActorKind;
use crate::{Error, Result};
use quick_xml::events::Event;
use quick_xml::Reader;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The shipped vehicle-type file (`scenarios/traffic/vtypes.add.xml`), used when a scenario
/// names none.
pub const BUILTIN_VTYPES: &str =
    include_str!("../../../python/drivehierarchy/_data/scenarios/traffic/vtypes.add.xml");
/// The vehicle type of a traffic vehicle or flow that names none.
pub const DEFAULT_VTYPE: &str = "car";
/// How the default vehicle-type file is named in messages and summaries.
pub const BUILTIN_VTYPES_NAME: &str = "<builtin>/traffic/vtypes.add.xml";
/// SUMO ids of the vehicles that mirror the ego and the scenario's own actors.
pub const SUMO_EGO_ID: &str = "dh_ego";
pub const SUMO_EGO_ROUTE: &str = "dh_ego_route";

/// Who moves the background traffic.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum TrafficMode {
    /// SUMO through libsumo, in lockstep with the world (the Python env drives it).
    Sumo,
    /// The pure-Rust reactive model (IDM car-following on the lane graph); `native` is its old
    /// name, accepted until the next release.
    #[serde(alias = "native")]
    Idm,
    /// No background traffic (the scenario's scripted actors only).
    #[default]
    None,
}

impl TrafficMode {
    /// Old names still accepted (with a deprecation warning from the Python side) and the mode
    /// each now means. Keep in step with the `serde(alias)` attributes above (tested).
    pub const DEPRECATED_NAMES: [(&'static str, TrafficMode); 1] = [("native", TrafficMode::Idm)];

    pub fn as_str(self) -> &'static str {
        match self {
            TrafficMode::Sumo => "sumo",
            TrafficMode::Idm => "idm",
            TrafficMode::None => "none",
        }
    }
    /// The mode of a current name or of a deprecated one.
    pub fn parse(s: &str) -> Option<TrafficMode> {
        Some(match s {
            "sumo" => TrafficMode::Sumo,
            "idm" => TrafficMode::Idm,
            "none" => TrafficMode::None,
            _ => return Self::DEPRECATED_NAMES.iter().find(|(n, _)| *n == s).map(|(_, m)| *m),
        })
    }
}

/// `depart_lane`: a lane index or one of SUMO's names.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
#[schemars(transform = crate::scenario::schema_rules::lane_names)]
pub enum LaneChoice {
    Index(u32),
    Named(String),
}

/// `depart_speed`: m/s or one of SUMO's names.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
#[schemars(transform = crate::scenario::schema_rules::speed_names)]
pub enum SpeedChoice {
    Value(#[schemars(range(min = 0))] f64),
    Named(String),
}

/// The `[traffic]` table as written.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TrafficSpec {
    /// Default `sumo` when the table is present.
    #[serde(default)]
    pub mode: Option<TrafficMode>,
    /// Vehicle-type file (SUMO `<vType>` elements), relative to the scenario file.
    #[serde(default)]
    pub vtypes: Option<String>,
    /// Seconds the traffic runs before t = 0 (the ego standing at its start), so the episode
    /// starts in flowing traffic.
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub warmup_s: Option<f64>,
    #[serde(default)]
    pub vehicles: Vec<TrafficVehicleSpec>,
    #[serde(default)]
    pub flows: Vec<TrafficFlowSpec>,
    #[serde(default)]
    pub random: Option<RandomTripsSpec>,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TrafficVehicleSpec {
    #[serde(default)]
    pub id: Option<String>,
    #[serde(default)]
    pub vtype: Option<String>,
    /// Edges in order; gaps are filled by shortest-path routing for the type's class.
    pub route: Vec<String>,
    #[serde(default)]
    pub depart_s: Option<f64>,
    #[serde(default)]
    pub depart_lane: Option<LaneChoice>,
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub depart_pos_m: Option<f64>,
    #[serde(default)]
    pub depart_speed: Option<SpeedChoice>,
    /// This vehicle's maximum speed, m/s (a derived vType; idm: caps the desired speed).
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub max_speed_mps: Option<f64>,
    /// This vehicle's speed factor on the lane speed limit (SUMO `speedFactor`).
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    #[schemars(range(max = 5))]
    pub speed_factor: Option<f64>,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = crate::scenario::schema_rules::flow_alternatives)]
pub struct TrafficFlowSpec {
    #[serde(default)]
    pub id: Option<String>,
    #[serde(default)]
    pub vtype: Option<String>,
    pub from: String,
    pub to: String,
    #[serde(default)]
    pub via: Vec<String>,
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub vehs_per_hour: Option<f64>,
    /// Chance of a departure each second.
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    #[schemars(range(max = 1))]
    pub probability: Option<f64>,
    #[serde(default)]
    pub begin_s: Option<f64>,
    #[serde(default)]
    pub end_s: Option<f64>,
    #[serde(default)]
    pub number: Option<u32>,
    #[serde(default)]
    pub depart_lane: Option<LaneChoice>,
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub depart_pos_m: Option<f64>,
    #[serde(default)]
    pub depart_speed: Option<SpeedChoice>,
    /// Maximum speed of the flow's vehicles, m/s.
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub max_speed_mps: Option<f64>,
    /// Speed factor of the flow's vehicles (each gets exactly this factor).
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    #[schemars(range(max = 5))]
    pub speed_factor: Option<f64>,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RandomTripsSpec {
    /// Vehicles per km of lane (lanes open to each type's class) at SUMO time 0.
    #[schemars(range(min = 0))]
    pub density_per_km: f64,
    /// Vehicle types and their weights (default `{ car = 1.0 }`).
    #[serde(default)]
    pub mix: Option<BTreeMap<String, f64>>,
    /// Only departure edges within this distance of the ego route (default: the whole map).
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub within_m: Option<f64>,
    /// Routes are random walks over the lane graph of at least this length (default 1000 m).
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub min_route_m: Option<f64>,
}

/// One `<vType>` of the type file.
#[derive(Debug, Clone, PartialEq)]
pub struct VType {
    pub id: String,
    pub vclass: VClass,
    pub kind: ActorKind,
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    pub accel_mps2: f64,
    pub decel_mps2: f64,
    pub tau_s: f64,
    pub min_gap_m: f64,
    pub max_speed_mps: f64,
    pub speed_factor: f64,
    pub color: Option<[u8; 3]>,
    /// Attributes as written, handed to SUMO verbatim.
    pub attrs: Vec<(String, String)>,
}

/// Actor kind drawn for a SUMO vehicle class.
pub fn kind_of_vclass(c: VClass) -> ActorKind {
    match c {
        VClass::Bus | VClass::Coach => ActorKind::Bus,
        VClass::Truck | VClass::Trailer => ActorKind::Truck,
        VClass::Motorcycle | VClass::Moped => ActorKind::Motorcycle,
        VClass::Bicycle => ActorKind::Cyclist,
        VClass::Pedestrian => ActorKind::Pedestrian,
        _ => ActorKind::Car,
    }
}

/// Where and how one vehicle departs (episode time; negative = during the warm-up).
#[derive(Debug, Clone, PartialEq)]
pub struct DemandVehicle {
    pub id: String,
    pub vtype: usize,
    pub edges: Vec<EdgeIdx>,
    pub depart_s: f64,
    pub depart_lane: LaneChoice,
    pub depart_pos_m: Option<f64>,
    pub depart_speed: SpeedChoice,
    /// Exact speed factor of this vehicle (SUMO's vehicle attribute; also in its vType).
    pub speed_factor: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FlowRate {
    PerHour(f64),
    Probability(f64),
}

#[derive(Debug, Clone, PartialEq)]
pub struct DemandFlow {
    pub id: String,
    pub vtype: usize,
    pub edges: Vec<EdgeIdx>,
    pub rate: FlowRate,
    pub begin_s: f64,
    pub end_s: f64,
    pub number: Option<u32>,
    pub depart_lane: LaneChoice,
    pub depart_pos_m: Option<f64>,
    pub depart_speed: SpeedChoice,
    pub speed_factor: Option<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct DemandRandom {
    pub density_per_km: f64,
    /// (vehicle type, weight), weights summing to 1.
    pub mix: Vec<(usize, f64)>,
    /// Candidate departure edges (normal edges, sorted).
    pub edges: Vec<EdgeIdx>,
    pub min_route_m: f64,
}

/// The resolved `[traffic]` table (mode `none` and empty when the scenario has none).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TrafficDemand {
    pub mode: TrafficMode,
    pub vtypes_file: String,
    pub vtypes: Vec<VType>,
    pub warmup_s: f64,
    pub vehicles: Vec<DemandVehicle>,
    pub flows: Vec<DemandFlow>,
    pub random: Option<DemandRandom>,
    /// Per-seed jitter of departures and speed factors (`[variation]`).
    pub jitter: crate::scenario::variation_spec::TrafficJitter,
}

/// A scenario actor that SUMO sees as a vehicle placed every tick (`dh_actor_<id>`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MirrorSpec {
    pub id: u32,
    pub kind: ActorKind,
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
}

/// The seeded generator of stream `stream` of episode seed `seed` (the one place RNGs are
/// built: random trips use stream 0, the `idm` traffic model `0x1D_0000`).
pub fn seeded_rng(seed: u64, stream: u64) -> SplitMix {
    SplitMix::new(seed ^ stream)
}

/// splitmix64: the demand's seeded generator (tiny, portable, identical on every platform).
#[derive(Debug, Clone)]
pub struct SplitMix(u64);

impl SplitMix {
    pub fn new(seed: u64) -> Self {
        SplitMix(seed ^ 0x5EED_7AFF_1C00_0000)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn below(&mut self, n: usize) -> usize {
        ((self.unit() * n as f64) as usize).min(n.saturating_sub(1))
    }
}

// ---------------------------------------------------------------------------------------------
// Vehicle-type file

fn sumo_color(s: &str) -> Option<[u8; 3]> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() < 3 {
        return None;
    }
    let mut out = [0u8; 3];
    let floats = parts.iter().take(3).all(|p| p.contains('.'));
    for (o, p) in out.iter_mut().zip(&parts) {
        let v: f64 = p.parse().ok()?;
        *o = if floats { (v * 255.0).round().clamp(0.0, 255.0) as u8 } else { v.clamp(0.0, 255.0) as u8 };
    }
    Some(out)
}

/// Reads the `<vType>` elements of a SUMO additional / route file (`origin` names it in errors).
pub fn parse_vtypes(origin: &str, text: &str) -> Result<Vec<VType>> {
    let err = |msg: String| Error::Map { file: origin.to_string(), message: msg };
    let mut reader = Reader::from_str(text);
    let mut out: Vec<VType> = Vec::new();
    loop {
        let ev = reader.read_event().map_err(|e| err(format!("malformed XML: {e}")))?;
        let e = match &ev {
            Event::Start(e) | Event::Empty(e) => e,
            Event::Eof => break,
            _ => continue,
        };
        if e.local_name().as_ref() != "vType" {
            continue;
        }
        let mut attrs = Vec::new();
        for a in e.attributes().with_checks(false) {
            let a = a.map_err(|x| err(format!("vType: malformed attribute: {x}")))?;
            let key: &str = a.key.into_inner();
            attrs.push((key.to_string(), a.value.to_string()));
        }
        let get = |k: &str| attrs.iter().find(|(a, _)| a == k).map(|(_, v)| v.as_str());
        let id = get("id").ok_or_else(|| err("<vType> without id".into()))?.to_string();
        let num = |k: &str, default: f64| -> Result<f64> {
            match get(k) {
                None => Ok(default),
                Some(v) => {
                    v.trim().parse::<f64>().ok().filter(|x| x.is_finite() && *x >= 0.0).ok_or_else(|| {
                        err(format!("vType \"{id}\": attribute {k} = \"{v}\": not a number ≥ 0"))
                    })
                }
            }
        };
        let vclass = match get("vClass") {
            None => VClass::Passenger,
            Some(v) => VClass::from_sumo(v)
                .ok_or_else(|| err(format!("vType \"{id}\": attribute vClass = \"{v}\": unknown class")))?,
        };
        let kind = kind_of_vclass(vclass);
        let (dl, dw, dh) = default_size(kind);
        if out.iter().any(|t| t.id == id) {
            return Err(err(format!("vType \"{id}\" defined twice")));
        }
        let vt = VType {
            vclass,
            kind,
            length_m: num("length", dl)?,
            width_m: num("width", dw)?,
            height_m: num("height", dh)?,
            accel_mps2: num("accel", 2.6)?,
            decel_mps2: num("decel", 4.5)?,
            tau_s: num("tau", 1.0)?,
            min_gap_m: num("minGap", 2.5)?,
            max_speed_mps: num("maxSpeed", 55.55)?,
            speed_factor: num("speedFactor", 1.0)?,
            color: get("color").and_then(sumo_color),
            id,
            attrs,
        };
        if vt.length_m <= 0.0 || vt.width_m <= 0.0 || vt.accel_mps2 <= 0.0 || vt.decel_mps2 <= 0.0 {
            return Err(err(format!("vType \"{}\": length, width, accel and decel must be > 0", vt.id)));
        }
        out.push(vt);
    }
    Ok(out)
}

// ---------------------------------------------------------------------------------------------
// Resolution

struct Rx<'a> {
    file: &'a Path,
    map: &'a Network,
}

impl Rx<'_> {
    fn err(&self, field: impl Into<String>, value: impl std::fmt::Display, msg: impl Into<String>) -> Error {
        Error::scenario(self.file, field, value, msg)
    }
    fn edge(&self, field: &str, id: &str) -> Result<EdgeIdx> {
        let e = self
            .map
            .edge_by_id(id)
            .ok_or_else(|| self.err(field, format!("\"{id}\""), "no such edge in the map"))?;
        if self.map.edges[e].function != EdgeFunction::Normal {
            return Err(self.err(field, format!("\"{id}\""), "not a normal edge (internal / crossing)"));
        }
        Ok(e)
    }
    /// Edges in order with gaps routed for `vclass`.
    fn route(&self, field: &str, ids: &[String], vclass: VClass) -> Result<Vec<EdgeIdx>> {
        if ids.is_empty() {
            return Err(self.err(field, "[]", "needs at least one edge"));
        }
        self.route_fields(&|i| format!("{field}[{i}]"), ids, vclass)
    }
    /// [`Rx::route`] with the field of the `i`-th id given by `field_of` (errors point at the
    /// key that names the edge, e.g. a flow's `to`).
    fn route_fields(
        &self,
        field_of: &dyn Fn(usize) -> String,
        ids: &[String],
        vclass: VClass,
    ) -> Result<Vec<EdgeIdx>> {
        let mut out: Vec<EdgeIdx> = Vec::new();
        for (i, id) in ids.iter().enumerate() {
            let e = self.edge(&field_of(i), id)?;
            if !edge_allows(self.map, e, vclass) {
                return Err(self.err(
                    field_of(i),
                    format!("\"{id}\""),
                    format!("no lane allows vehicle class {}", vclass.sumo_name()),
                ));
            }
            match out.last() {
                None => out.push(e),
                Some(&prev) => {
                    let leg = self.map.edge_route(prev, e, vclass).ok_or_else(|| {
                        self.err(
                            field_of(i),
                            format!("\"{id}\""),
                            format!(
                                "not reachable from \"{}\" for class {}",
                                self.map.edges[prev].id,
                                vclass.sumo_name()
                            ),
                        )
                    })?;
                    out.extend_from_slice(&leg[1..]);
                }
            }
        }
        Ok(out)
    }
    fn vtype(&self, field: &str, name: Option<&str>, types: &[VType]) -> Result<usize> {
        let name = name.unwrap_or(DEFAULT_VTYPE);
        types.iter().position(|t| t.id == name).ok_or_else(|| {
            let known: Vec<&str> = types.iter().map(|t| t.id.as_str()).collect();
            self.err(
                field,
                format!("\"{name}\""),
                format!("unknown vehicle type (known: {})", known.join(", ")),
            )
        })
    }
    /// Per-vehicle `max_speed_mps` / `speed_factor`: a vType derived from `base` (id
    /// `<base>@<vehicle or flow id>`, every attribute copied, `maxSpeed` / `speedFactor`
    /// replaced) so that SUMO and the `idm` model read the same values. Returns the type to
    /// use and the exact speed factor for SUMO's vehicle attribute.
    fn speed_vtype(
        &self,
        field: &str,
        vtypes: &mut Vec<VType>,
        base: usize,
        id: &str,
        max_speed: Option<f64>,
        factor: Option<f64>,
    ) -> Result<(usize, Option<f64>)> {
        if max_speed.is_none() && factor.is_none() {
            return Ok((base, None));
        }
        let mut t = vtypes[base].clone();
        let mut set = |key: &str, v: f64| match t.attrs.iter_mut().find(|(k, _)| k == key) {
            Some(a) => a.1 = format!("{v}"),
            None => t.attrs.push((key.to_string(), format!("{v}"))),
        };
        if let Some(m) = max_speed {
            if !(m.is_finite() && m > 0.0) {
                return Err(self.err(format!("{field}.max_speed_mps"), m, "must be a finite number > 0"));
            }
            set("maxSpeed", m);
        }
        if let Some(f) = factor {
            if !(f.is_finite() && f > 0.0 && f <= 5.0) {
                return Err(self.err(format!("{field}.speed_factor"), f, "must lie in (0, 5]"));
            }
            set("speedFactor", f);
        }
        t.max_speed_mps = max_speed.unwrap_or(t.max_speed_mps);
        t.speed_factor = factor.unwrap_or(t.speed_factor);
        t.id = format!("{}@{id}", t.id);
        let new_id = t.id.clone();
        if vtypes.iter().any(|v| v.id == new_id) {
            return Err(self.err(
                format!("{field}.id"),
                format!("\"{id}\""),
                format!("vehicle type id `{new_id}` exists already"),
            ));
        }
        match t.attrs.iter_mut().find(|(k, _)| k == "id") {
            Some(a) => a.1 = new_id,
            None => t.attrs.insert(0, ("id".into(), new_id)),
        }
        vtypes.push(t);
        Ok((vtypes.len() - 1, factor))
    }
    /// `depart_lane`: a SUMO name, or the index of a lane of the first edge that is open to
    /// `vclass` and from which the route can be driven (SUMO refuses the whole route file
    /// otherwise; the `idm` model would drive on it regardless).
    fn lane(
        &self,
        field: &str,
        l: &Option<LaneChoice>,
        edges: &[EdgeIdx],
        vclass: VClass,
    ) -> Result<LaneChoice> {
        match l {
            None => Ok(LaneChoice::Named("best".into())),
            Some(LaneChoice::Named(n)) if !LANE_NAMES.contains(&n.as_str()) => Err(self.err(
                field,
                format!("\"{n}\""),
                format!("expected a lane index or one of {}", LANE_NAMES.join(", ")),
            )),
            Some(LaneChoice::Index(i)) => {
                let edge = &self.map.edges[edges[0]];
                let open: Vec<String> = edge
                    .lanes
                    .iter()
                    .filter(|&&l| self.map.lanes[l].allow.contains(vclass))
                    .map(|&l| self.map.lanes[l].index.to_string())
                    .collect();
                let Some(&lane) = edge.lanes.iter().find(|&&l| self.map.lanes[l].index == *i as usize) else {
                    return Err(self.err(
                        field,
                        i,
                        format!(
                            "edge \"{}\" has no lane {i} (lanes 0 … {}; open to class {}: {})",
                            edge.id,
                            edge.lanes.len().saturating_sub(1),
                            vclass.sumo_name(),
                            open.join(", ")
                        ),
                    ));
                };
                if !self.map.lanes[lane].allow.contains(vclass) {
                    return Err(self.err(
                        field,
                        i,
                        format!(
                            "lane \"{}\" is closed to vehicle class {} (lanes of \"{}\" open to it: {})",
                            self.map.lanes[lane].id,
                            vclass.sumo_name(),
                            edge.id,
                            open.join(", ")
                        ),
                    ));
                }
                if let Err(e) = self.map.route_lanes_for(edges, Some(lane), vclass) {
                    let msg = match e {
                        Error::Map { message, .. } => message,
                        other => other.to_string(),
                    };
                    return Err(self.err(
                        field,
                        i,
                        format!(
                            "the route cannot be driven from lane \"{}\": {msg}",
                            self.map.lanes[lane].id
                        ),
                    ));
                }
                Ok(LaneChoice::Index(*i))
            }
            Some(c) => Ok(c.clone()),
        }
    }
    fn speed(&self, field: &str, s: &Option<SpeedChoice>) -> Result<SpeedChoice> {
        match s {
            None => Ok(SpeedChoice::Named("max".into())),
            Some(SpeedChoice::Named(n)) if !SPEED_NAMES.contains(&n.as_str()) => Err(self.err(
                field,
                format!("\"{n}\""),
                format!("expected m/s or one of {}", SPEED_NAMES.join(", ")),
            )),
            Some(SpeedChoice::Value(v)) if !(v.is_finite() && *v >= 0.0) => {
                Err(self.err(field, v, "must be a finite number ≥ 0"))
            }
            Some(c) => Ok(c.clone()),
        }
    }
    fn nonneg(&self, field: &str, v: Option<f64>, default: f64) -> Result<f64> {
        let v = v.unwrap_or(default);
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(self.err(field, v, "must be a finite number ≥ 0"))
        }
    }
    fn depart_pos(&self, field: &str, v: Option<f64>, edges: &[EdgeIdx]) -> Result<Option<f64>> {
        let Some(p) = v else { return Ok(None) };
        let len = edge_length(self.map, edges[0]);
        if !(p.is_finite() && p >= 0.0 && p <= len) {
            return Err(self.err(field, p, format!("must lie on the first edge (0 … {len:.1} m)")));
        }
        Ok(Some(p))
    }
}

pub(crate) fn edge_allows(map: &Network, e: EdgeIdx, c: VClass) -> bool {
    map.edges[e].lanes.iter().any(|&l| map.lanes[l].allow.contains(c))
}

pub(crate) fn edge_length(map: &Network, e: EdgeIdx) -> f64 {
    map.edges[e].lanes.first().map_or(0.0, |&l| map.lanes[l].length_m)
}

/// Resolves the `[traffic]` table (`None` = no table: mode `none`, no demand).
pub fn resolve_traffic(
    file: &Path,
    map: &Network,
    spec: Option<&TrafficSpec>,
    ego_route: &Polyline,
) -> Result<TrafficDemand> {
    let Some(spec) = spec else { return Ok(TrafficDemand::default()) };
    let rx = Rx { file, map };
    let (vtypes_file, text) = match &spec.vtypes {
        None => (BUILTIN_VTYPES_NAME.to_string(), BUILTIN_VTYPES.to_string()),
        Some(rel) => {
            let p: PathBuf = file.parent().unwrap_or(Path::new(".")).join(rel);
            let text = std::fs::read_to_string(&p).map_err(|e| {
                rx.err("traffic.vtypes", format!("\"{rel}\""), format!("cannot read {}: {e}", p.display()))
            })?;
            (p.display().to_string(), text)
        }
    };
    let mut vtypes = parse_vtypes(&vtypes_file, &text)
        .map_err(|e| rx.err("traffic.vtypes", format!("\"{vtypes_file}\""), e.to_string()))?;
    let warmup_s = rx.nonneg("traffic.warmup_s", spec.warmup_s, 0.0)?;
    let mut ids: Vec<String> = Vec::new();
    let mut unique = |field: String, id: String| -> Result<String> {
        if id.starts_with("dh_") || ids.contains(&id) {
            return Err(Error::scenario(
                file,
                field,
                format!("\"{id}\""),
                "ids must be unique and not start with dh_",
            ));
        }
        ids.push(id.clone());
        Ok(id)
    };
    let mut vehicles = Vec::with_capacity(spec.vehicles.len());
    for (i, v) in spec.vehicles.iter().enumerate() {
        let f = format!("traffic.vehicles[{i}]");
        let vtype = rx.vtype(&format!("{f}.vtype"), v.vtype.as_deref(), &vtypes)?;
        let vclass = vtypes[vtype].vclass;
        let edges = rx.route(&format!("{f}.route"), &v.route, vclass)?;
        let depart_lane = rx.lane(&format!("{f}.depart_lane"), &v.depart_lane, &edges, vclass)?;
        let id = v.id.clone().unwrap_or_else(|| format!("veh{i}"));
        let (vtype, speed_factor) =
            rx.speed_vtype(&f, &mut vtypes, vtype, &id, v.max_speed_mps, v.speed_factor)?;
        let depart_s = v.depart_s.unwrap_or(0.0);
        if !(depart_s.is_finite() && depart_s >= -warmup_s) {
            return Err(rx.err(format!("{f}.depart_s"), depart_s, "must be a finite number ≥ −warmup_s"));
        }
        vehicles.push(DemandVehicle {
            id: unique(format!("{f}.id"), id)?,
            vtype,
            speed_factor,
            depart_pos_m: rx.depart_pos(&format!("{f}.depart_pos_m"), v.depart_pos_m, &edges)?,
            edges,
            depart_s,
            depart_lane,
            depart_speed: rx.speed(&format!("{f}.depart_speed"), &v.depart_speed)?,
        });
    }
    let mut flows = Vec::with_capacity(spec.flows.len());
    for (i, fl) in spec.flows.iter().enumerate() {
        let f = format!("traffic.flows[{i}]");
        let vtype = rx.vtype(&format!("{f}.vtype"), fl.vtype.as_deref(), &vtypes)?;
        let mut names = vec![fl.from.clone()];
        names.extend(fl.via.iter().cloned());
        names.push(fl.to.clone());
        let vclass = vtypes[vtype].vclass;
        let n_via = fl.via.len();
        let field_of = |k: usize| match k {
            0 => format!("{f}.from"),
            k if k <= n_via => format!("{f}.via[{}]", k - 1),
            _ => format!("{f}.to"),
        };
        let edges = rx.route_fields(&field_of, &names, vclass)?;
        let depart_lane = rx.lane(&format!("{f}.depart_lane"), &fl.depart_lane, &edges, vclass)?;
        let id = fl.id.clone().unwrap_or_else(|| format!("flow{i}"));
        let (vtype, speed_factor) =
            rx.speed_vtype(&f, &mut vtypes, vtype, &id, fl.max_speed_mps, fl.speed_factor)?;
        let rate = match (fl.vehs_per_hour, fl.probability) {
            (Some(v), None) if v.is_finite() && v > 0.0 => FlowRate::PerHour(v),
            (None, Some(p)) if p.is_finite() && p > 0.0 && p <= 1.0 => FlowRate::Probability(p),
            (Some(v), None) => {
                return Err(rx.err(format!("{f}.vehs_per_hour"), v, "must be a finite number > 0"))
            }
            (None, Some(p)) => return Err(rx.err(format!("{f}.probability"), p, "must lie in (0, 1]")),
            _ => {
                return Err(rx.err(&f, "{…}", "give exactly one of vehs_per_hour and probability"));
            }
        };
        let begin_s = fl.begin_s.unwrap_or(-warmup_s);
        let end_s = fl.end_s.unwrap_or(3600.0);
        if !(begin_s.is_finite() && begin_s >= -warmup_s) {
            return Err(rx.err(format!("{f}.begin_s"), begin_s, "must be a finite number ≥ −warmup_s"));
        }
        if !(end_s.is_finite() && end_s > begin_s) {
            return Err(rx.err(format!("{f}.end_s"), end_s, "must be a finite number > begin_s"));
        }
        flows.push(DemandFlow {
            id: unique(format!("{f}.id"), id)?,
            vtype,
            speed_factor,
            depart_pos_m: rx.depart_pos(&format!("{f}.depart_pos_m"), fl.depart_pos_m, &edges)?,
            edges,
            rate,
            begin_s,
            end_s,
            number: match (fl.number, fl.probability) {
                (Some(n), Some(_)) => {
                    return Err(rx.err(
                        format!("{f}.number"),
                        n,
                        "`number` goes with `vehs_per_hour` (a probability flow ends at `end_s`)",
                    ))
                }
                (n, _) => n,
            },
            depart_lane,
            depart_speed: rx.speed(&format!("{f}.depart_speed"), &fl.depart_speed)?,
        });
    }
    let random = match &spec.random {
        None => None,
        Some(r) => {
            let f = "traffic.random";
            if !(r.density_per_km.is_finite() && r.density_per_km >= 0.0) {
                return Err(rx.err(
                    format!("{f}.density_per_km"),
                    r.density_per_km,
                    "must be a finite number ≥ 0",
                ));
            }
            let mix_spec = r.mix.clone().unwrap_or_else(|| BTreeMap::from([("car".to_string(), 1.0)]));
            let mut mix = Vec::new();
            let total: f64 = mix_spec.values().sum();
            for (name, w) in &mix_spec {
                let t = rx.vtype(&format!("{f}.mix.{name}"), Some(name), &vtypes)?;
                if !(w.is_finite() && *w >= 0.0 && total.is_finite() && total > 0.0) {
                    return Err(rx.err(
                        format!("{f}.mix.{name}"),
                        w,
                        "weights must be ≥ 0 with a positive sum",
                    ));
                }
                mix.push((t, w / total));
            }
            let within = match r.within_m {
                Some(w) if !(w.is_finite() && w > 0.0) => {
                    return Err(rx.err(format!("{f}.within_m"), w, "must be a finite number > 0"))
                }
                w => w,
            };
            let min_route_m = rx.nonneg(&format!("{f}.min_route_m"), r.min_route_m, 1000.0)?;
            let edges: Vec<EdgeIdx> = (0..map.edges.len())
                .filter(|&e| map.edges[e].function == EdgeFunction::Normal)
                .filter(|&e| mix.iter().any(|&(t, _)| edge_allows(map, e, vtypes[t].vclass)))
                .filter(|&e| match within {
                    None => true,
                    Some(w) => map.edges[e].lanes.iter().any(|&l| {
                        let shape = &map.lanes[l].shape;
                        (0..=8).any(|k| {
                            let p = shape.point_at(shape.length() * f64::from(k) / 8.0);
                            ego_route.project(p).is_some_and(|pr| pr.distance <= w)
                        })
                    }),
                })
                .collect();
            if edges.is_empty() && r.density_per_km > 0.0 {
                return Err(rx.err(
                    format!("{f}.within_m"),
                    within.unwrap_or(0.0),
                    "no edge to start random trips on",
                ));
            }
            Some(DemandRandom { density_per_km: r.density_per_km, mix, edges, min_route_m })
        }
    };
    Ok(TrafficDemand {
        mode: spec.mode.unwrap_or(TrafficMode::Sumo),
        vtypes_file,
        vtypes,
        warmup_s,
        vehicles,
        flows,
        random,
        jitter: Default::default(),
    })
}

// ---------------------------------------------------------------------------------------------
// Realisation

impl TrafficDemand {
    /// Whether there is anything to simulate.
    pub fn is_empty(&self) -> bool {
        self.vehicles.is_empty()
            && self.flows.is_empty()
            && self.random.as_ref().is_none_or(|r| r.density_per_km <= 0.0)
    }

    /// Lane length open to `vclass` over the random-trip edges, km.
    fn lane_km(&self, map: &Network, r: &DemandRandom) -> f64 {
        let mut m = 0.0;
        for &e in &r.edges {
            for &l in &map.edges[e].lanes {
                let lane = &map.lanes[l];
                if r.mix.iter().any(|&(t, _)| lane.allow.contains(self.vtypes[t].vclass)) {
                    m += lane.length_m;
                }
            }
        }
        m / 1000.0
    }

    /// The random trips of one episode: `density × lane km` vehicles departing at SUMO time 0
    /// (episode time −warmup_s) at seeded places, each on a seeded random walk of at least
    /// `min_route_m`. Places within `keep_clear_m` of `keep_clear` (the ego start) are skipped.
    pub fn random_trips(
        &self,
        map: &Network,
        seed: u64,
        keep_clear: crate::geom::Vec2,
        keep_clear_m: f64,
    ) -> Vec<DemandVehicle> {
        let Some(r) = &self.random else { return Vec::new() };
        let n = (r.density_per_km * self.lane_km(map, r)).round() as usize;
        let mut rng = seeded_rng(seed, 0);
        // Departure edges weighted by their length.
        let weights: Vec<f64> =
            r.edges.iter().map(|&e| edge_length(map, e) * map.edges[e].lanes.len() as f64).collect();
        let total: f64 = weights.iter().sum();
        let mut out = Vec::with_capacity(n);
        let mut attempts = 0;
        while out.len() < n && attempts < 20 * n + 100 {
            attempts += 1;
            let u = rng.unit();
            let mut t = u * r.mix.iter().map(|m| m.1).sum::<f64>();
            let vtype = r
                .mix
                .iter()
                .find(|&&(_, w)| {
                    t -= w;
                    t < 0.0
                })
                .map_or(r.mix[0].0, |m| m.0);
            let vc = self.vtypes[vtype].vclass;
            let mut x = rng.unit() * total;
            let mut ei = 0;
            while ei + 1 < weights.len() && x >= weights[ei] {
                x -= weights[ei];
                ei += 1;
            }
            let e = r.edges[ei];
            let lanes: Vec<usize> = map.edges[e]
                .lanes
                .iter()
                .enumerate()
                .filter(|(_, &l)| map.lanes[l].allow.contains(vc))
                .map(|(i, _)| i)
                .collect();
            if lanes.is_empty() {
                continue;
            }
            let lane_index = lanes[rng.below(lanes.len())];
            let len = edge_length(map, e);
            let vlen = self.vtypes[vtype].length_m;
            if len < vlen + 1.0 {
                continue;
            }
            let pos = vlen + rng.unit() * (len - vlen - 0.5);
            let lane = &map.lanes[map.edges[e].lanes[lane_index]];
            if lane.shape.point_at(pos.min(lane.shape.length())).dist(keep_clear) < keep_clear_m {
                continue;
            }
            // Random walk over successors (no immediate U-turn unless it is the only way on).
            let mut edges = vec![e];
            let mut length = len - pos;
            while length < r.min_route_m && edges.len() < 256 {
                let cur = *edges.last().unwrap_or(&e);
                let succ: Vec<EdgeIdx> =
                    map.succ[cur].iter().filter(|(_, set, _)| set.contains(vc)).map(|s| s.0).collect();
                let forward: Vec<EdgeIdx> = succ
                    .iter()
                    .copied()
                    .filter(|&s| map.edges[s].to != map.edges[cur].from || map.edges[s].to.is_none())
                    .collect();
                let pick = if forward.is_empty() { &succ } else { &forward };
                if pick.is_empty() {
                    break;
                }
                let next = pick[rng.below(pick.len())];
                edges.push(next);
                length += edge_length(map, next);
            }
            out.push(DemandVehicle {
                id: format!("rnd{}", out.len()),
                vtype,
                edges,
                depart_s: -self.warmup_s,
                depart_lane: LaneChoice::Index(lane_index as u32),
                depart_pos_m: Some(pos),
                depart_speed: SpeedChoice::Named("max".into()),
                speed_factor: None,
            });
        }
        out
    }
}

/// `vclass_of` re-exported for the traffic models (kind of a scenario actor → SUMO class).
pub fn actor_vclass(kind: ActorKind) -> VClass {
    vclass_of(kind)
}
