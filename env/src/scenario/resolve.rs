//! Scenario file → [`ResolvedScenario`]: every place, route and path turned into world-frame
//! geometry against the map, with errors naming file, TOML field and value.

use super::schema::*;
use crate::geom::{Polyline, Pose, Vec2};
use crate::map::{EdgeFunction, EdgeIdx, LaneIdx, Network, VClass};
use crate::view::{ActorKind, SignView};
use crate::world::VehicleParams;
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Protocol fallback speed for the reference duration when a scenario gives none (§2.5).
pub const DEFAULT_REFERENCE_SPEED_MPS: f64 = 5.56;
/// A start/destination given by coordinates must lie this close to a drivable lane centreline.
pub const SNAP_DISTANCE_M: f64 = 6.0;
/// Map-path prefix resolved against `SUMO_HOME`.
pub const SUMO_PREFIX: &str = "sumo:";

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

/// Default cruise speed of a scripted actor, m/s.
pub fn default_speed_mps(kind: ActorKind) -> f64 {
    match kind {
        ActorKind::Pedestrian => 1.2,
        ActorKind::Cyclist => 4.0,
        _ => 8.0,
    }
}

/// Fixed palette; actor `i` (file order, obstacles after actors) gets `PALETTE[i % 8]`.
pub const PALETTE: [[u8; 3]; 8] = [
    [200, 40, 40],
    [40, 90, 200],
    [230, 230, 230],
    [40, 40, 40],
    [220, 180, 30],
    [40, 150, 70],
    [140, 60, 160],
    [150, 150, 150],
];
/// Ego body colour unless the scenario sets one.
pub const EGO_COLOR: [u8; 3] = [30, 110, 230];

fn default_color(kind: ActorKind, i: usize) -> [u8; 3] {
    match kind {
        ActorKind::Cone => [255, 120, 0],
        ActorKind::Barrier => [230, 60, 40],
        _ => PALETTE[i % PALETTE.len()],
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

#[derive(Debug, Clone)]
pub struct ResolvedEgo {
    /// Vehicle centre and heading at t = 0.
    pub start: Pose,
    pub speed_mps: f64,
    pub params: VehicleParams,
    pub color: [u8; 3],
    pub start_lane: LaneIdx,
    /// Normal edges of the route, start edge first.
    pub route_edges: Vec<EdgeIdx>,
    /// Route centreline clipped between the projections of start and destination (§2.5 L).
    pub route: Polyline,
    pub destination: Vec2,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Trigger {
    /// Starts when sim time ≥ this.
    Time(f64),
    /// Starts when the ego centre is within `radius_m` of `point`.
    EgoWithin { radius_m: f64, point: Vec2 },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BrakeWhen {
    /// Arc length along the actor's path.
    AtS(f64),
    /// Seconds after the actor's trigger fired.
    AfterS(f64),
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BrakeEvent {
    pub when: BrakeWhen,
    pub decel_mps2: f64,
    pub to_speed_mps: f64,
    /// Resume the leg speed this long after reaching `to_speed_mps` (None = never).
    pub hold_s: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AtEnd {
    Stop,
    Remove,
}

#[derive(Debug, Clone)]
pub struct ScriptedPath {
    /// World-frame path; the actor's centre moves along it.
    pub path: Polyline,
    /// (arc length at which the leg ends, speed on the leg), increasing arc lengths; the last
    /// leg ends at the path length.
    pub legs: Vec<(f64, f64)>,
    pub initial_speed_mps: f64,
    /// Limit on speed changes between legs (∞ = instant).
    pub accel_mps2: f64,
    pub trigger: Trigger,
    pub brake: Option<BrakeEvent>,
    pub at_end: AtEnd,
}

impl ScriptedPath {
    /// Speed of the leg containing arc length `s`.
    pub fn leg_speed(&self, s: f64) -> f64 {
        let i = self.legs.partition_point(|&(end, _)| end <= s).min(self.legs.len().saturating_sub(1));
        self.legs.get(i).map_or(0.0, |l| l.1)
    }
}

#[derive(Debug, Clone)]
pub enum ActorMotion {
    /// Never moves (obstacles).
    Static {
        pose: Pose,
    },
    Scripted(ScriptedPath),
    /// Pose set by the caller each tick; `pose` is where it stands until then.
    External {
        pose: Pose,
    },
}

#[derive(Debug, Clone)]
pub struct ResolvedActor {
    /// From the file, or `actors[i]` / `obstacles[i]`.
    pub name: String,
    pub kind: ActorKind,
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    pub color: [u8; 3],
    pub motion: ActorMotion,
}

/// A scenario with everything in world coordinates; the world never re-reads the file.
#[derive(Debug, Clone)]
pub struct ResolvedScenario {
    pub file: PathBuf,
    pub id: String,
    pub name: String,
    pub category: String,
    pub description: String,
    /// The map file actually read (after `sumo:` resolution).
    pub map_path: PathBuf,
    /// The `map` value as written in the scenario file.
    pub map_spec: String,
    pub map: Arc<Network>,
    pub seed: u64,
    /// As written; see [`ResolvedScenario::reference_duration_s`] for the effective value.
    pub reference_duration_given_s: Option<f64>,
    /// As written; see [`ResolvedScenario::scenario_duration_s`] for the effective value.
    pub duration_given_s: Option<f64>,
    pub ego: ResolvedEgo,
    /// Scripted/external actors in file order, then obstacles in file order.
    pub actors: Vec<ResolvedActor>,
    pub signs: Vec<SignView>,
    /// Background-traffic demand (`[traffic]`; mode `none` when absent).
    pub traffic: crate::scenario::traffic::TrafficDemand,
}

impl ResolvedScenario {
    /// Route length L, metres.
    pub fn route_length_m(&self) -> f64 {
        self.ego.route.length()
    }
    /// T_ref of §2.5: the scenario's value, else L / 5.56 m/s.
    pub fn reference_duration_s(&self) -> f64 {
        self.reference_duration_given_s.unwrap_or(self.route_length_m() / DEFAULT_REFERENCE_SPEED_MPS)
    }

    /// The scenario duration of §2.4 (the scenario timeout is 2 × it): the file's `duration_s`,
    /// else — like the original's "longest estimated duration over all actors, ego included" —
    /// the largest of T_ref and every scripted actor's estimated finish time (start trigger +
    /// travel time of its legs + any brake hold). An ego-distance trigger is estimated to fire
    /// when the ego, progressing at L / T_ref, comes within the trigger radius of its point.
    pub fn scenario_duration_s(&self) -> f64 {
        if let Some(d) = self.duration_given_s {
            return d;
        }
        let t_ref = self.reference_duration_s();
        let ego_speed = self.route_length_m() / t_ref;
        self.actors
            .iter()
            .filter_map(|a| match &a.motion {
                ActorMotion::Scripted(p) => Some(scripted_finish_s(p, &self.ego.route, ego_speed)),
                _ => None,
            })
            .filter(|d| d.is_finite())
            .fold(t_ref, f64::max)
    }
}

/// Estimated time at which a scripted actor finishes its path.
fn scripted_finish_s(p: &ScriptedPath, ego_route: &Polyline, ego_speed_mps: f64) -> f64 {
    let start = match p.trigger {
        Trigger::Time(t) => t,
        Trigger::EgoWithin { radius_m, point } => match ego_route.project(point) {
            Some(proj) if ego_speed_mps > 0.0 => (proj.s - radius_m).max(0.0) / ego_speed_mps,
            _ => 0.0,
        },
    };
    let mut travel = 0.0;
    let mut from = 0.0;
    for &(end, speed) in &p.legs {
        if speed > 0.0 {
            travel += (end - from).max(0.0) / speed;
        }
        from = end;
    }
    let hold = p.brake.and_then(|b| b.hold_s).unwrap_or(0.0);
    start + travel + hold
}

/// Where `sumo:` maps live and an optional cache of loaded networks.
#[derive(Debug, Clone, Default)]
pub struct LoadOptions {
    /// `SUMO_HOME` for `sumo:` map paths; when `None` the `SUMO_HOME` environment variable is used
    /// (the Python layer sets it from `sumo.SUMO_HOME`).
    pub sumo_home: Option<PathBuf>,
    pub cache: Option<Arc<MapCache>>,
}

/// Loaded networks by canonical path, so episodes on one map parse it once.
#[derive(Debug, Default)]
pub struct MapCache {
    maps: Mutex<BTreeMap<PathBuf, Arc<Network>>>,
}

impl MapCache {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn get_or_load(&self, path: &Path) -> Result<Arc<Network>> {
        let key = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
        if let Some(n) = self.maps.lock().ok().and_then(|m| m.get(&key).cloned()) {
            return Ok(n);
        }
        let net = Arc::new(Network::from_file(path)?);
        if let Ok(mut m) = self.maps.lock() {
            m.insert(key, net.clone());
        }
        Ok(net)
    }
}

/// `SUMO_HOME` from the environment, else the one the installed `eclipse-sumo` Python package
/// reports (`python3 -c "import sumo; print(sumo.SUMO_HOME)"`); `None` when neither exists.
pub fn discover_sumo_home() -> Option<PathBuf> {
    if let Some(h) = std::env::var_os("SUMO_HOME") {
        return Some(PathBuf::from(h));
    }
    let out = std::process::Command::new("python3")
        .args(["-c", "import sumo; print(sumo.SUMO_HOME)"])
        .output()
        .ok()?;
    let s = String::from_utf8(out.stdout).ok()?;
    let p = PathBuf::from(s.trim());
    (out.status.success() && p.is_dir()).then_some(p)
}

/// Resolves the `map` value of a scenario file to a path.
pub fn resolve_map_path(file: &Path, map: &str, sumo_home: Option<&Path>) -> Result<PathBuf> {
    if let Some(rest) = map.strip_prefix(SUMO_PREFIX) {
        let home = match sumo_home {
            Some(h) => h.to_path_buf(),
            None => discover_sumo_home().ok_or_else(|| {
                Error::scenario(file, "map", map, "a `sumo:` map needs SUMO_HOME (set the SUMO_HOME environment variable, pass sumo_home, or `pip install eclipse-sumo`)")
            })?,
        };
        let p = home.join(rest.trim_start_matches('/'));
        if !p.is_file() {
            return Err(Error::scenario(
                file,
                "map",
                map,
                format!("map file not found under SUMO_HOME ({})", p.display()),
            ));
        }
        return Ok(p);
    }
    let base = file.parent().unwrap_or(Path::new("."));
    let p = base.join(map);
    if map.is_empty() || !p.is_file() {
        return Err(Error::scenario(
            file,
            "map",
            map,
            format!("map file not found (looked for {}, relative to the scenario file)", p.display()),
        ));
    }
    Ok(p)
}

/// Resolution context: the file for errors and the map.
struct Ctx<'a> {
    file: &'a Path,
    map: &'a Network,
}

impl Ctx<'_> {
    fn err(&self, field: impl Into<String>, value: impl std::fmt::Display, msg: impl Into<String>) -> Error {
        Error::scenario(self.file, field, value, msg)
    }
    fn finite(&self, field: &str, v: f64) -> Result<f64> {
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.err(field, v, "must be a finite number"))
        }
    }
    fn nonneg(&self, field: &str, v: f64) -> Result<f64> {
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(self.err(field, v, "must be a finite number ≥ 0"))
        }
    }
    fn positive(&self, field: &str, v: f64) -> Result<f64> {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(self.err(field, v, "must be a finite number > 0"))
        }
    }
    fn lane(&self, field: &str, id: &str) -> Result<LaneIdx> {
        self.map.lane_by_id(id).ok_or_else(|| self.err(field, id, "unknown lane id in the map"))
    }
    fn edge(&self, field: &str, id: &str) -> Result<EdgeIdx> {
        let e = self.map.edge_by_id(id).ok_or_else(|| self.err(field, id, "unknown edge id in the map"))?;
        if self.map.edges[e].function != EdgeFunction::Normal {
            return Err(self.err(field, id, "not a normal edge (internal/crossing edges cannot be routed)"));
        }
        Ok(e)
    }

    /// A place → (pose, lane if given by lane). Yaw: `yaw_deg`, else lane heading, else 0.
    fn place(&self, field: &str, p: &PlaceSpec) -> Result<(Pose, Option<LaneIdx>)> {
        let yaw = match p.yaw_deg {
            Some(d) => {
                Some(crate::geom::wrap_angle(self.finite(&format!("{field}.yaw_deg"), d)?.to_radians()))
            }
            None => None,
        };
        match (&p.lane, p.x, p.y) {
            (Some(lane_id), None, None) => {
                let lane = self.lane(&format!("{field}.lane"), lane_id)?;
                let len = self.map.lanes[lane].shape.length();
                let s = self.nonneg(&format!("{field}.s"), p.s.unwrap_or(0.0))?;
                if s > len + 1e-6 {
                    return Err(self.err(
                        format!("{field}.s"),
                        s,
                        format!("beyond the end of lane `{lane_id}` (length {len:.2} m)"),
                    ));
                }
                let off = self.finite(&format!("{field}.offset_m"), p.offset_m.unwrap_or(0.0))?;
                let base = self.map.lane_position(lane, s);
                let pos = base.pos + base.forward().perp() * off;
                Ok((Pose::new(pos, yaw.unwrap_or(base.yaw)), Some(lane)))
            }
            (None, Some(x), Some(y)) => {
                if let Some(s) = p.s {
                    return Err(self.err(format!("{field}.s"), s, "`s` needs `lane` (not `x`/`y`)"));
                }
                if let Some(o) = p.offset_m {
                    return Err(self.err(
                        format!("{field}.offset_m"),
                        o,
                        "`offset_m` needs `lane` (not `x`/`y`)",
                    ));
                }
                let x = self.finite(&format!("{field}.x"), x)?;
                let y = self.finite(&format!("{field}.y"), y)?;
                Ok((Pose::new(Vec2::new(x, y), yaw.unwrap_or(0.0)), None))
            }
            (Some(l), _, _) => {
                Err(self.err(field, l, "give either `lane` (+ `s`, `offset_m`) or `x` and `y`, not both"))
            }
            _ => Err(self.err(field, "<incomplete>", "give `lane` (+ `s`, `offset_m`) or both `x` and `y`")),
        }
    }

    /// Drivable normal lane under a place (given lane, else nearest within SNAP_DISTANCE_M).
    fn snap_lane(&self, field: &str, pose: Pose, lane: Option<LaneIdx>) -> Result<LaneIdx> {
        let lane = match lane {
            Some(l) => l,
            None => {
                self.map
                    .drivable()
                    .nearest_lane(pose.pos, SNAP_DISTANCE_M)
                    .ok_or_else(|| {
                        self.err(
                            field,
                            format!("({:.2}, {:.2})", pose.pos.x, pose.pos.y),
                            format!("no drivable lane within {SNAP_DISTANCE_M} m"),
                        )
                    })?
                    .0
            }
        };
        let l = &self.map.lanes[lane];
        if !l.is_drivable() {
            return Err(self.err(field, &l.id, "lane does not allow passenger cars"));
        }
        if self.map.edges[l.edge].function != EdgeFunction::Normal {
            return Err(self.err(field, &l.id, "must lie on a normal edge, not inside a junction"));
        }
        Ok(lane)
    }

    /// Edge ids → edges with gaps between consecutive entries filled by shortest paths.
    fn edge_chain(&self, field: &str, ids: &[String], vclass: VClass) -> Result<Vec<EdgeIdx>> {
        if ids.is_empty() {
            return Err(self.err(field, "[]", "needs at least one edge"));
        }
        let mut out: Vec<EdgeIdx> = Vec::new();
        for (i, id) in ids.iter().enumerate() {
            let e = self.edge(&format!("{field}[{i}]"), id)?;
            match out.last() {
                None => out.push(e),
                Some(&prev) => {
                    let seg = self.map.edge_route(prev, e, vclass).ok_or_else(|| {
                        self.err(
                            format!("{field}[{i}]"),
                            id,
                            format!("not reachable from `{}` for vClass {vclass:?}", self.map.edges[prev].id),
                        )
                    })?;
                    out.extend_from_slice(&seg[1..]);
                }
            }
        }
        Ok(out)
    }

    /// Rightmost lane of `edge` allowing `vclass`.
    fn first_lane(&self, field: &str, edge: EdgeIdx, vclass: VClass) -> Result<LaneIdx> {
        let e = &self.map.edges[edge];
        e.lanes
            .iter()
            .copied()
            .find(|&l| self.map.lanes[l].allow.contains(vclass))
            .ok_or_else(|| self.err(field, &e.id, format!("edge has no lane for vClass {vclass:?}")))
    }
}

fn map_err(ctx: &Ctx<'_>, field: &str, value: &str, e: Error) -> Error {
    let msg = match e {
        Error::Map { message, .. } => message,
        other => other.to_string(),
    };
    ctx.err(field, value, msg)
}

/// Shifts a polyline sideways by `d` (> 0 = left), using per-vertex averaged normals.
pub fn offset_polyline(pl: &Polyline, d: f64) -> Polyline {
    let pts = pl.points();
    if d == 0.0 || pts.len() < 2 {
        return pl.clone();
    }
    let n = pts.len();
    let out = (0..n)
        .map(|i| {
            let a = if i > 0 { (pts[i] - pts[i - 1]).normalized() } else { Vec2::ZERO };
            let b = if i + 1 < n { (pts[i + 1] - pts[i]).normalized() } else { Vec2::ZERO };
            let t = (a + b).normalized();
            let normal = t.perp();
            // Keep the offset distance at corners (limited to avoid spikes at sharp turns).
            let cos_half = normal.dot(if i > 0 { a.perp() } else { b.perp() }).max(0.5);
            pts[i] + normal * (d / cos_half)
        })
        .collect();
    Polyline::new(out)
}

fn route_label(map: &Network, edges: &[EdgeIdx]) -> String {
    edges.iter().map(|&e| map.edges[e].id.as_str()).collect::<Vec<_>>().join(" ")
}

fn resolve_ego(ctx: &Ctx<'_>, spec: &EgoSpec) -> Result<ResolvedEgo> {
    let map = ctx.map;
    let params = spec.vehicle.unwrap_or_default();
    params.validate().map_err(|e| match e {
        Error::Config { field, value, message } => ctx.err(format!("ego.{field}"), value, message),
        other => other,
    })?;
    let speed = ctx.nonneg("ego.speed_mps", spec.speed_mps)?;
    if speed > params.max_speed_mps {
        return Err(ctx.err(
            "ego.speed_mps",
            speed,
            format!("above the vehicle's max speed {} m/s", params.max_speed_mps),
        ));
    }
    let chain = match &spec.route_edges {
        Some(ids) => Some(ctx.edge_chain("ego.route_edges", ids, VClass::Passenger)?),
        None => None,
    };
    if spec.destination.is_none() && chain.is_none() {
        return Err(ctx.err("ego.destination", "<missing>", "give `destination` or `route_edges`"));
    }
    // Start.
    let (start, start_lane) = match (&spec.start, &chain) {
        (Some(p), _) => {
            let (mut pose, lane) = ctx.place("ego.start", p)?;
            let lane = ctx.snap_lane("ego.start", pose, lane)?;
            if p.lane.is_none() && p.yaw_deg.is_none() {
                let sh = &map.lanes[lane].shape;
                pose.yaw = sh.heading_at(sh.project(pose.pos).map_or(0.0, |q| q.s));
            }
            (pose, lane)
        }
        (None, Some(c)) => {
            let lane = ctx.first_lane("ego.route_edges[0]", c[0], VClass::Passenger)?;
            let len = map.lanes[lane].shape.length();
            (map.lane_position(lane, (0.25 * len).min(5.0)), lane)
        }
        (None, None) => {
            return Err(ctx.err(
                "ego.start",
                "<missing>",
                "give `start` (or `route_edges` to start on its first edge)",
            ))
        }
    };
    let start_edge = map.lanes[start_lane].edge;
    // Destination.
    let (destination, dest_edge) = match (&spec.destination, &chain) {
        (Some(p), _) => {
            let (pose, lane) = ctx.place("ego.destination", p)?;
            let lane = ctx.snap_lane("ego.destination", pose, lane)?;
            (pose.pos, map.lanes[lane].edge)
        }
        (None, Some(c)) => {
            let last = *c.last().unwrap_or(&start_edge);
            let lane = ctx.first_lane("ego.route_edges", last, VClass::Passenger)?;
            let len = map.lanes[lane].shape.length();
            (map.lane_position(lane, len - (0.25 * len).min(5.0)).pos, last)
        }
        (None, None) => {
            return Err(ctx.err("ego.destination", "<missing>", "give `destination` or `route_edges`"))
        }
    };
    // Route edges.
    let edges = match &chain {
        Some(c) => {
            let i0 = c.iter().position(|&e| e == start_edge).ok_or_else(|| {
                ctx.err(
                    "ego.start",
                    &map.edges[start_edge].id,
                    format!("start edge is not on route_edges ({})", route_label(map, c)),
                )
            })?;
            let i1 = c.iter().rposition(|&e| e == dest_edge).filter(|&i| i >= i0).ok_or_else(|| {
                ctx.err(
                    "ego.destination",
                    &map.edges[dest_edge].id,
                    format!(
                        "destination edge is not on route_edges after the start ({})",
                        route_label(map, c)
                    ),
                )
            })?;
            c[i0..=i1].to_vec()
        }
        None => map.edge_route(start_edge, dest_edge, VClass::Passenger).ok_or_else(|| {
            ctx.err(
                "ego.destination",
                &map.edges[dest_edge].id,
                format!("no drivable route from edge `{}`", map.edges[start_edge].id),
            )
        })?,
    };
    let label = route_label(map, &edges);
    let full = map
        .route_polyline(&edges, Some(start_lane))
        .map_err(|e| map_err(ctx, "ego.route_edges", &label, e))?;
    let p0 = full.project(start.pos).ok_or_else(|| ctx.err("ego.route_edges", &label, "empty route"))?;
    let p1 = full.project(destination).ok_or_else(|| ctx.err("ego.route_edges", &label, "empty route"))?;
    if p1.distance > SNAP_DISTANCE_M + 4.0 {
        return Err(ctx.err(
            "ego.destination",
            format!("({:.2}, {:.2})", destination.x, destination.y),
            format!("{:.1} m away from the route {label}", p1.distance),
        ));
    }
    if p1.s <= p0.s + 1.0 {
        return Err(ctx.err(
            "ego.destination",
            format!("({:.2}, {:.2})", destination.x, destination.y),
            format!("lies behind (or at) the start along the route {label} (start s = {:.1} m, destination s = {:.1} m)", p0.s, p1.s),
        ));
    }
    let color = spec.color.unwrap_or(EGO_COLOR);
    Ok(ResolvedEgo {
        start,
        speed_mps: speed,
        params,
        color,
        start_lane,
        route_edges: edges,
        route: full.slice(p0.s, p1.s),
        destination,
    })
}

fn size(
    ctx: &Ctx<'_>,
    field: &str,
    kind: ActorKind,
    l: Option<f64>,
    w: Option<f64>,
    h: Option<f64>,
) -> Result<(f64, f64, f64)> {
    let (dl, dw, dh) = default_size(kind);
    Ok((
        ctx.positive(&format!("{field}.length_m"), l.unwrap_or(dl))?,
        ctx.positive(&format!("{field}.width_m"), w.unwrap_or(dw))?,
        ctx.positive(&format!("{field}.height_m"), h.unwrap_or(dh))?,
    ))
}

/// Lanes of an explicit lane list with junction-internal lanes inserted.
fn lane_chain(ctx: &Ctx<'_>, field: &str, ids: &[String]) -> Result<Vec<LaneIdx>> {
    let map = ctx.map;
    if ids.is_empty() {
        return Err(ctx.err(field, "[]", "needs at least one lane"));
    }
    let mut out: Vec<LaneIdx> = Vec::new();
    for (i, id) in ids.iter().enumerate() {
        let f = format!("{field}[{i}]");
        let b = ctx.lane(&f, id)?;
        if let Some(&a) = out.last() {
            if map.lanes[a].edge == map.lanes[b].edge {
                out.push(b);
                continue;
            }
            let conns = map.connections_from_lane(a);
            if let Some(&ci) = conns.iter().find(|&&ci| map.connections[ci].to_lane == b) {
                if map.lane_function(b) != EdgeFunction::Internal {
                    out.extend(map.via_chain(ci));
                }
                out.push(b);
            } else if conns.iter().any(|&ci| map.connections[ci].via == Some(b)) {
                out.push(b);
            } else {
                return Err(ctx.err(
                    f,
                    id,
                    format!("not connected to the previous lane `{}`", map.lanes[a].id),
                ));
            }
        } else {
            out.push(b);
        }
    }
    Ok(out)
}

fn resolve_trigger(ctx: &Ctx<'_>, field: &str, t: Option<&TriggerSpec>, self_pos: Vec2) -> Result<Trigger> {
    let Some(t) = t else { return Ok(Trigger::Time(0.0)) };
    match (t.time_s, t.ego_within_m) {
        (Some(ts), None) => {
            if let Some(of) = &t.of {
                return Err(ctx.err(
                    format!("{field}.of"),
                    format!("{of:?}"),
                    "`of` goes with `ego_within_m`, not `time_s`",
                ));
            }
            Ok(Trigger::Time(ctx.nonneg(&format!("{field}.time_s"), ts)?))
        }
        (None, Some(r)) => {
            let radius_m = ctx.positive(&format!("{field}.ego_within_m"), r)?;
            let point = match &t.of {
                None => self_pos,
                Some(OfSpec::Name(n)) if n == "actor_self" => self_pos,
                Some(OfSpec::Name(n)) => {
                    return Err(ctx.err(format!("{field}.of"), n, "the only name allowed is \"actor_self\""))
                }
                Some(OfSpec::Point([x, y])) => Vec2::new(
                    ctx.finite(&format!("{field}.of[0]"), *x)?,
                    ctx.finite(&format!("{field}.of[1]"), *y)?,
                ),
                Some(OfSpec::Place(p)) => ctx.place(&format!("{field}.of"), p)?.0.pos,
            };
            Ok(Trigger::EgoWithin { radius_m, point })
        }
        (Some(ts), Some(_)) => Err(ctx.err(field, ts, "give exactly one of `time_s` or `ego_within_m`")),
        (None, None) => Err(ctx.err(field, "{}", "give `time_s` or `ego_within_m`")),
    }
}

fn resolve_actor(ctx: &Ctx<'_>, i: usize, a: &ActorSpec) -> Result<ResolvedActor> {
    let map = ctx.map;
    let field = format!("actors[{i}]");
    let (length_m, width_m, height_m) = size(ctx, &field, a.kind, a.length_m, a.width_m, a.height_m)?;
    let color = a.color.unwrap_or(default_color(a.kind, i));
    let name = a.name.clone().unwrap_or_else(|| field.clone());
    let base = |motion| ResolvedActor {
        name: name.clone(),
        kind: a.kind,
        length_m,
        width_m,
        height_m,
        color,
        motion,
    };
    if a.behavior == BehaviorSpec::External {
        if a.waypoints.is_some() || a.route.is_some() {
            return Err(ctx.err(
                format!("{field}.behavior"),
                "external",
                "an external actor takes `at`, not `waypoints`/`route`",
            ));
        }
        let at =
            a.at.as_ref()
                .ok_or_else(|| ctx.err(format!("{field}.at"), "<missing>", "an external actor needs `at`"))?;
        return Ok(base(ActorMotion::External { pose: ctx.place(&format!("{field}.at"), at)?.0 }));
    }
    if a.at.is_some() {
        return Err(ctx.err(
            format!("{field}.at"),
            "{..}",
            "scripted actors start at their path start; use [[obstacles]] for parked objects",
        ));
    }
    let speed =
        ctx.nonneg(&format!("{field}.speed_mps"), a.speed_mps.unwrap_or(default_speed_mps(a.kind)))?;
    let (path, legs) = match (&a.waypoints, &a.route) {
        (Some(wps), None) => {
            let f = format!("{field}.waypoints");
            if wps.is_empty() {
                return Err(ctx.err(&f, "[]", "empty waypoint list (needs at least 2 points)"));
            }
            if wps.len() < 2 {
                return Err(ctx.err(&f, wps.len(), "needs at least 2 waypoints"));
            }
            let mut pts = Vec::with_capacity(wps.len());
            let mut legs = Vec::with_capacity(wps.len() - 1);
            let mut acc = 0.0;
            for (k, w) in wps.iter().enumerate() {
                let wf = format!("{f}[{k}]");
                let place = PlaceSpec {
                    lane: w.lane.clone(),
                    s: w.s,
                    offset_m: w.offset_m,
                    x: w.x,
                    y: w.y,
                    yaw_deg: None,
                };
                let p = ctx.place(&wf, &place)?.0.pos;
                let v = match w.speed_mps {
                    Some(v) => ctx.nonneg(&format!("{wf}.speed_mps"), v)?,
                    None => speed,
                };
                if let Some(&prev) = pts.last() {
                    acc += p.dist(prev);
                    legs.push((acc, v));
                }
                pts.push(p);
            }
            if acc <= 1e-6 {
                return Err(ctx.err(&f, wps.len(), "waypoints do not span any distance"));
            }
            (Polyline::new(pts), legs)
        }
        (None, Some(r)) => {
            let f = format!("{field}.route");
            let vclass = vclass_of(a.kind);
            let full = match (&r.edges, &r.lanes) {
                (Some(ids), None) => {
                    let edges = ctx.edge_chain(&format!("{f}.edges"), ids, vclass)?;
                    let start_lane = match &r.start_lane {
                        Some(l) => {
                            let lane = ctx.lane(&format!("{f}.start_lane"), l)?;
                            if map.lanes[lane].edge != edges[0] {
                                return Err(ctx.err(
                                    format!("{f}.start_lane"),
                                    l,
                                    "not a lane of the first route edge",
                                ));
                            }
                            Some(lane)
                        }
                        None => None,
                    };
                    map.route_polyline_for(&edges, start_lane, vclass)
                        .map_err(|e| map_err(ctx, &format!("{f}.edges"), &route_label(map, &edges), e))?
                }
                (None, Some(ids)) => {
                    if let Some(l) = &r.start_lane {
                        return Err(ctx.err(
                            format!("{f}.start_lane"),
                            l,
                            "`start_lane` goes with `edges`; the lane list starts at its first lane",
                        ));
                    }
                    map.lanes_polyline(&lane_chain(ctx, &format!("{f}.lanes"), ids)?)
                }
                _ => return Err(ctx.err(&f, "{..}", "give exactly one of `edges` or `lanes`")),
            };
            let len = full.length();
            let s0 = ctx.nonneg(&format!("{f}.start_s"), r.start_s.unwrap_or(0.0))?;
            let s1 = ctx.nonneg(&format!("{f}.end_s"), r.end_s.unwrap_or(len))?.min(len);
            if s1 <= s0 + 1e-6 {
                return Err(ctx.err(
                    format!("{f}.start_s"),
                    s0,
                    format!("start_s must be below end_s ({s1:.2}) and the route length ({len:.2} m)"),
                ));
            }
            let off = ctx.finite(&format!("{f}.offset_m"), r.offset_m.unwrap_or(0.0))?;
            let path = offset_polyline(&full.slice(s0, s1), off);
            let l = path.length();
            (path, vec![(l, speed)])
        }
        (Some(_), Some(_)) => return Err(ctx.err(&field, "{..}", "give `waypoints` or `route`, not both")),
        (None, None) => {
            return Err(ctx.err(
                format!("{field}.waypoints"),
                "<missing>",
                "a scripted actor needs `waypoints` or `route` (use [[obstacles]] for parked objects)",
            ))
        }
    };
    let initial_speed_mps = match a.initial_speed_mps {
        Some(v) => ctx.nonneg(&format!("{field}.initial_speed_mps"), v)?,
        None => legs.first().map_or(0.0, |l| l.1),
    };
    let accel_mps2 = match a.accel_mps2 {
        Some(v) => ctx.positive(&format!("{field}.accel_mps2"), v)?,
        None if a.kind == ActorKind::Pedestrian => f64::INFINITY,
        None => 3.0,
    };
    let trigger = resolve_trigger(ctx, &format!("{field}.start"), a.start.as_ref(), path.point_at(0.0))?;
    let brake = match &a.brake {
        None => None,
        Some(b) => {
            let bf = format!("{field}.brake");
            let when = match (b.at_s, b.after_s) {
                (Some(s), None) => BrakeWhen::AtS(ctx.nonneg(&format!("{bf}.at_s"), s)?),
                (None, Some(t)) => BrakeWhen::AfterS(ctx.nonneg(&format!("{bf}.after_s"), t)?),
                _ => return Err(ctx.err(&bf, "{..}", "give exactly one of `at_s` or `after_s`")),
            };
            let hold_s = match b.hold_s {
                Some(h) => Some(ctx.nonneg(&format!("{bf}.hold_s"), h)?),
                None => None,
            };
            Some(BrakeEvent {
                when,
                decel_mps2: ctx.positive(&format!("{bf}.decel_mps2"), b.decel_mps2)?,
                to_speed_mps: ctx.nonneg(&format!("{bf}.to_speed_mps"), b.to_speed_mps)?,
                hold_s,
            })
        }
    };
    let at_end = match a.at_end {
        AtEndSpec::Stop => AtEnd::Stop,
        AtEndSpec::Remove => AtEnd::Remove,
    };
    Ok(base(ActorMotion::Scripted(ScriptedPath {
        path,
        legs,
        initial_speed_mps,
        accel_mps2,
        trigger,
        brake,
        at_end,
    })))
}

fn resolve_obstacle(
    ctx: &Ctx<'_>,
    i: usize,
    palette_index: usize,
    o: &ObstacleSpec,
) -> Result<ResolvedActor> {
    let field = format!("obstacles[{i}]");
    let (length_m, width_m, height_m) = size(ctx, &field, o.kind, o.length_m, o.width_m, o.height_m)?;
    let (pose, _) = ctx.place(&format!("{field}.at"), &o.at)?;
    Ok(ResolvedActor {
        name: o.name.clone().unwrap_or(field),
        kind: o.kind,
        length_m,
        width_m,
        height_m,
        color: o.color.unwrap_or(default_color(o.kind, palette_index)),
        motion: ActorMotion::Static { pose },
    })
}

fn resolve_sign(ctx: &Ctx<'_>, i: usize, s: &SignSpec) -> Result<SignView> {
    let field = format!("signs[{i}].at");
    let pose = match &s.at.lane {
        Some(lane_id) => {
            let lane = ctx.lane(&format!("{field}.lane"), lane_id)?;
            let default_off = -(0.5 * ctx.map.lanes[lane].width_m + 1.0);
            let spec = PlaceSpec { offset_m: Some(s.at.offset_m.unwrap_or(default_off)), ..s.at.clone() };
            let (pose, _) = ctx.place(&field, &spec)?;
            // Faces oncoming traffic unless a yaw is given.
            if s.at.yaw_deg.is_some() {
                pose
            } else {
                Pose::new(pose.pos, crate::geom::wrap_angle(pose.yaw + std::f64::consts::PI))
            }
        }
        None => ctx.place(&field, &s.at)?.0,
    };
    Ok(SignView { kind: s.kind, pose })
}

/// Resolves a parsed scenario file (`file` = its path) against its map.
pub fn resolve(file: &Path, spec: &ScenarioFile, opts: &LoadOptions) -> Result<ResolvedScenario> {
    if spec.version != SCENARIO_VERSION {
        return Err(Error::scenario(
            file,
            "version",
            spec.version,
            format!("this build reads scenario version {SCENARIO_VERSION}"),
        ));
    }
    if spec.id.trim().is_empty() {
        return Err(Error::scenario(file, "id", "\"\"", "must not be empty"));
    }
    if !CATEGORIES.contains(&spec.category.as_str()) {
        return Err(Error::scenario(
            file,
            "category",
            &spec.category,
            format!("must be one of {}", CATEGORIES.join(", ")),
        ));
    }
    for (field, value) in
        [("reference_duration_s", spec.reference_duration_s), ("duration_s", spec.duration_s)]
    {
        if let Some(r) = value {
            if !(r.is_finite() && r > 0.0) {
                return Err(Error::scenario(file, field, r, "must be a finite number > 0"));
            }
        }
    }
    let map_path = resolve_map_path(file, &spec.map, opts.sumo_home.as_deref())?;
    let map = match &opts.cache {
        Some(c) => c.get_or_load(&map_path),
        None => Network::from_file(&map_path).map(Arc::new),
    }
    .map_err(|e| Error::scenario(file, "map", &spec.map, format!("cannot load the map: {e}")))?;
    let ctx = Ctx { file, map: &map };
    let ego = resolve_ego(&ctx, &spec.ego)?;
    let mut actors = Vec::with_capacity(spec.actors.len() + spec.obstacles.len());
    for (i, a) in spec.actors.iter().enumerate() {
        actors.push(resolve_actor(&ctx, i, a)?);
    }
    for (i, o) in spec.obstacles.iter().enumerate() {
        actors.push(resolve_obstacle(&ctx, i, spec.actors.len() + i, o)?);
    }
    let signs =
        spec.signs.iter().enumerate().map(|(i, s)| resolve_sign(&ctx, i, s)).collect::<Result<Vec<_>>>()?;
    let traffic = crate::scenario::traffic::resolve_traffic(file, &map, spec.traffic.as_ref(), &ego.route)?;
    Ok(ResolvedScenario {
        file: file.to_path_buf(),
        id: spec.id.clone(),
        name: spec.name.clone().unwrap_or_else(|| spec.id.clone()),
        category: spec.category.clone(),
        description: spec.description.clone(),
        map_path,
        map_spec: spec.map.clone(),
        map: map.clone(),
        seed: spec.seed,
        reference_duration_given_s: spec.reference_duration_s,
        duration_given_s: spec.duration_s,
        ego,
        actors,
        signs,
        traffic,
    })
}
