//! Scenario file → [`ResolvedScenario`]: every place, route and path turned into world-frame
//! geometry against the map, with errors naming file, TOML field and value.

use super::schema::*;
pub use super::tables::{default_size, vclass_of};
use crate::geom::{Polyline, Pose, Vec2};
use crate::map::{EdgeFunction, EdgeIdx, LaneIdx, Network, VClass};
use crate::sumo_home::SumoHome;
use crate::vehicle_params::VehicleParams;
use crate::view::{ActorKind, SignView};
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
/// `map = "builtin:town01"`: a map shipped with the package, from a scenario anywhere.
pub const BUILTIN_PREFIX: &str = "builtin:";

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
    /// Starts when the ego is expected to reach `point` within `eta_s`: its distance along its
    /// route to `route_s` (the point's projection) ÷ max(ego speed, [`crate::world::scripted::ETA_MIN_SPEED_MPS`]) ≤
    /// `eta_s`, while the point is still ahead.
    EgoEta { eta_s: f64, point: Vec2, route_s: f64 },
    /// Starts `delay_s` after `event` of the scenario actor with index `actor` (id = index + 1).
    After { actor: usize, event: ChainEvent, delay_s: f64 },
}

/// A time-to-conflict point must lie this close to the ego route, m.
pub const ETA_MAX_OFFSET_M: f64 = 30.0;

/// The event of another actor a chained trigger follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChainEvent {
    Start,
    Brake,
    End,
}

/// The program a traffic light runs in the episode (a `[[lights]]` override resolved against
/// the map): at episode time t it is at cycle position (t − `offset_s`) mod cycle, SUMO's
/// meaning of `offset`.
#[derive(Debug, Clone, PartialEq)]
pub struct LightProgram {
    pub tl_id: String,
    pub offset_s: f64,
    pub phases: Vec<crate::map::TlPhase>,
    /// Whether `phases` replace the map's program (SUMO must be given the new logic).
    pub replaced: bool,
}

impl LightProgram {
    /// (phase index, seconds left in it) at episode time `t`.
    pub fn phase_at(&self, t: f64) -> Option<(usize, f64)> {
        let cycle: f64 = self.phases.iter().map(|p| p.duration_s.max(0.0)).sum();
        if self.phases.is_empty() || !cycle.is_finite() || cycle <= 0.0 {
            return None;
        }
        let pos = (t - self.offset_s).rem_euclid(cycle);
        let mut end = 0.0;
        for (i, p) in self.phases.iter().enumerate() {
            end += p.duration_s.max(0.0);
            if pos < end {
                return Some((i, end - pos));
            }
        }
        Some((self.phases.len() - 1, 0.0))
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BrakeWhen {
    /// Arc length along the actor's path.
    AtS(f64),
    /// Seconds after the actor's trigger fired.
    AfterS(f64),
    /// The ego centre within `radius_m` of `point` (None: of the actor's centre, as it moves).
    EgoWithin { radius_m: f64, point: Option<Vec2> },
    /// The ego's bumper gap behind the actor along the ego route ≤ `gap_m`.
    EgoGap { gap_m: f64 },
    /// The ego's time gap (bumper gap ÷ ego speed) ≤ `gap_s`.
    EgoTimeGap { gap_s: f64 },
    /// The ego's time to collision (bumper gap ÷ closing speed, closing only) ≤ `ttc_s`.
    EgoTtc { ttc_s: f64 },
    /// The ego expected at `point` (route arc length `route_s`) within `eta_s`.
    EgoEta { eta_s: f64, point: Vec2, route_s: f64 },
    /// The actor's `pace` gap has stayed settled for `held_s`.
    GapHeld { held_s: f64 },
    /// `delay_s` after `event` of actor `actor` (index).
    After { actor: usize, event: ChainEvent, delay_s: f64 },
}

/// Ego-relative pacing (see [`crate::scenario::schema::PaceSpec`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pace {
    pub mode: PaceMode,
    pub min_speed_mps: f64,
    pub max_speed_mps: f64,
    /// Arc length along the path where pacing ends (∞ = never).
    pub until_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PaceMode {
    /// Hold a bumper gap of `gap_m` + `gap_s` × ego speed ahead of the ego along its route.
    Gap { gap_m: f64, gap_s: f64 },
    /// Reach arc length `actor_s` of the path (the point `point`, at `route_s` along the ego
    /// route) `offset_s` after the ego's expected arrival there.
    Meet { point: Vec2, route_s: f64, actor_s: f64, offset_s: f64 },
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
    /// Ego-relative speed control while moving (None: the leg speeds).
    pub pace: Option<Pace>,
    pub at_end: AtEnd,
}

impl ScriptedPath {
    /// Speed of the leg containing arc length `s`.
    pub fn leg_speed(&self, s: f64) -> f64 {
        let i = self.legs.partition_point(|&(end, _)| end <= s).min(self.legs.len().saturating_sub(1));
        self.legs.get(i).map_or(0.0, |l| l.1)
    }
}

// One per actor, resolved once per scenario: the size difference does not matter.
#[allow(clippy::large_enum_variant)]
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
    /// Traffic-light overrides (`[[lights]]`), one per overridden light, in file order.
    pub lights: Vec<LightProgram>,
    /// Bounds of the per-seed jitter ([`ResolvedScenario::varied`]).
    pub variation: crate::scenario::variation_spec::Variation,
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
        let starts = self.estimated_start_times_s();
        self.actors
            .iter()
            .zip(&starts)
            .filter_map(|(a, &start)| match &a.motion {
                ActorMotion::Scripted(p) => Some(start + travel_s(p, p.path.length()) + hold_s(p)),
                _ => None,
            })
            .filter(|d| d.is_finite())
            .fold(t_ref, f64::max)
    }

    /// Estimated trigger time of every actor (non-scripted: 0), the ego progressing along its
    /// route at L / T_ref: `time_s` as given; `ego_within_m` when the ego enters the radius;
    /// `ego_eta_s` when the ego is `eta_s` from the point at that pace (s_point / v − eta);
    /// chained triggers at the other actor's estimated event (start; start + time to its
    /// brake; start + travel + hold for the end) + `delay_s`.
    pub fn estimated_start_times_s(&self) -> Vec<f64> {
        let ego_speed = self.route_length_m() / self.reference_duration_s();
        let mut memo: Vec<Option<f64>> = vec![None; self.actors.len()];
        (0..self.actors.len()).map(|i| self.estimate_start(i, ego_speed, &mut memo, 0)).collect()
    }

    fn estimate_start(&self, i: usize, ego_speed: f64, memo: &mut Vec<Option<f64>>, depth: usize) -> f64 {
        if let Some(t) = memo[i] {
            return t;
        }
        let ActorMotion::Scripted(p) = &self.actors[i].motion else { return 0.0 };
        let t = match p.trigger {
            Trigger::Time(t) => t,
            Trigger::EgoWithin { radius_m, point } => match self.ego.route.project(point) {
                Some(proj) if ego_speed > 0.0 => (proj.s - radius_m).max(0.0) / ego_speed,
                _ => 0.0,
            },
            Trigger::EgoEta { eta_s, route_s, .. } => {
                if ego_speed > 0.0 {
                    (route_s / ego_speed - eta_s).max(0.0)
                } else {
                    0.0
                }
            }
            // Cycles are rejected at load; the depth guard keeps a hand-built one finite.
            Trigger::After { actor, event, delay_s } if depth < self.actors.len() => {
                let t0 = self.estimate_start(actor, ego_speed, memo, depth + 1);
                let ev = match (&self.actors[actor].motion, event) {
                    (ActorMotion::Scripted(q), ChainEvent::Brake) => match q.brake.map(|b| b.when) {
                        Some(BrakeWhen::AfterS(dt)) => dt,
                        Some(BrakeWhen::AtS(s)) => travel_s(q, s),
                        Some(BrakeWhen::GapHeld { held_s }) => held_s,
                        // Ego-relative and chained brakes: estimated at the trigger.
                        _ => 0.0,
                    },
                    (ActorMotion::Scripted(q), ChainEvent::End) => travel_s(q, q.path.length()) + hold_s(q),
                    _ => 0.0,
                };
                t0 + ev + delay_s
            }
            Trigger::After { .. } => 0.0,
        };
        memo[i] = Some(t);
        t
    }
}

/// Travel time of a scripted path from its start to arc length `upto` at the leg speeds.
fn travel_s(p: &ScriptedPath, upto: f64) -> f64 {
    let mut travel = 0.0;
    let mut from = 0.0;
    for &(end, speed) in &p.legs {
        let end = end.min(upto);
        if speed > 0.0 && end > from {
            travel += (end - from) / speed;
        }
        from = from.max(end);
    }
    travel
}

fn hold_s(p: &ScriptedPath) -> f64 {
    p.brake.and_then(|b| b.hold_s).unwrap_or(0.0)
}

/// Where `sumo:` maps live and an optional cache of loaded networks.
#[derive(Debug, Clone, Default)]
pub struct LoadOptions {
    /// `SUMO_HOME` for `sumo:` map paths; when `None`, [`SumoHome::locate`] finds it.
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

/// `builtin:NAME` maps: the folder holding the shipped maps (`NAME/NAME.net.xml`), registered
/// once per process (the Python package registers the maps it ships when imported).
static BUILTIN_MAPS: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();

/// Registers the folder of the shipped maps for `builtin:NAME`; a second call is ignored
/// (returns `false`) so every scenario of a process resolves against the same maps.
pub fn set_builtin_maps_dir(dir: PathBuf) -> bool {
    BUILTIN_MAPS.set(dir).is_ok()
}

fn resolve_builtin_map(file: &Path, map: &str, name: &str) -> Result<PathBuf> {
    let dir = BUILTIN_MAPS.get().ok_or_else(|| {
        Error::scenario(file, "map", map, "`builtin:` names the drivehierarchy package's shipped maps, and none are registered in this process (import drivehierarchy)")
    })?;
    let plain = !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    let path = dir.join(name).join(format!("{name}.net.xml"));
    if plain && path.is_file() {
        return Ok(path);
    }
    let mut shipped: Vec<String> = std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok()?.file_name().into_string().ok())
                .filter(|n| dir.join(n).join(format!("{n}.net.xml")).is_file())
                .collect()
        })
        .unwrap_or_default();
    shipped.sort();
    Err(Error::scenario(
        file,
        "map",
        map,
        format!("no shipped map of this name (shipped: {})", shipped.join(", ")),
    ))
}

/// Resolves the `map` value of a scenario file to a path.
pub fn resolve_map_path(file: &Path, map: &str, sumo_home: Option<&Path>) -> Result<PathBuf> {
    if let Some(name) = map.strip_prefix(BUILTIN_PREFIX) {
        return resolve_builtin_map(file, map, name);
    }
    if let Some(rest) = map.strip_prefix(SUMO_PREFIX) {
        let home = match sumo_home {
            Some(h) => h.to_path_buf(),
            None => SumoHome::locate().map(|h| h.0).ok_or_else(|| {
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
    /// Alternative keys of one table (`(key, given)`): exactly one must be given; the error
    /// shows the ones that were (`{}` for none) and names them all.
    fn exactly_one(&self, field: &str, keys: &[(&str, bool)]) -> Result<()> {
        let given: Vec<&str> = keys.iter().filter(|k| k.1).map(|k| k.0).collect();
        if given.len() == 1 {
            return Ok(());
        }
        let names: Vec<String> = keys.iter().map(|k| format!("`{}`", k.0)).collect();
        let (last, rest) = names.split_last().expect("alternatives are listed");
        Err(self.err(
            field,
            if given.is_empty() { "{}".to_string() } else { given.join(" + ") },
            format!("give exactly one of {} or {last}", rest.join(", ")),
        ))
    }
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

/// What a trigger needs besides its own table: the ego route (time-to-conflict points) and the
/// scenario actors' names (chained triggers).
struct TriggerCtx<'a> {
    ego_route: &'a Polyline,
    names: &'a [String],
}

fn resolve_of(ctx: &Ctx<'_>, field: &str, of: Option<&OfSpec>, self_pos: Vec2) -> Result<Vec2> {
    Ok(match of {
        None => self_pos,
        Some(OfSpec::Name(n)) if n == "actor_self" => self_pos,
        Some(OfSpec::Name(n)) => {
            return Err(ctx.err(format!("{field}.of"), n, "the only name allowed is \"actor_self\""))
        }
        Some(OfSpec::Point([x, y])) => {
            Vec2::new(ctx.finite(&format!("{field}.of[0]"), *x)?, ctx.finite(&format!("{field}.of[1]"), *y)?)
        }
        Some(OfSpec::Place(p)) => ctx.place(&format!("{field}.of"), p)?.0.pos,
    })
}

fn resolve_trigger(
    ctx: &Ctx<'_>,
    tc: &TriggerCtx<'_>,
    field: &str,
    t: Option<&TriggerSpec>,
    self_pos: Vec2,
) -> Result<Trigger> {
    let Some(t) = t else { return Ok(Trigger::Time(0.0)) };
    ctx.exactly_one(
        field,
        &[
            ("time_s", t.time_s.is_some()),
            ("ego_within_m", t.ego_within_m.is_some()),
            ("ego_eta_s", t.ego_eta_s.is_some()),
            ("after", t.after.is_some()),
        ],
    )?;
    let of_ok = t.ego_within_m.is_some() || t.ego_eta_s.is_some();
    if let (Some(of), false) = (&t.of, of_ok) {
        return Err(ctx.err(
            format!("{field}.of"),
            format!("{of:?}"),
            "`of` goes with `ego_within_m` or `ego_eta_s`",
        ));
    }
    if t.after.is_none() {
        if let Some(d) = t.delay_s {
            return Err(ctx.err(format!("{field}.delay_s"), d, "`delay_s` goes with `after`"));
        }
        if let Some(e) = t.event {
            return Err(ctx.err(format!("{field}.event"), format!("{e:?}"), "`event` goes with `after`"));
        }
    }
    if let Some(ts) = t.time_s {
        return Ok(Trigger::Time(ctx.nonneg(&format!("{field}.time_s"), ts)?));
    }
    if let Some(r) = t.ego_within_m {
        let radius_m = ctx.positive(&format!("{field}.ego_within_m"), r)?;
        let point = resolve_of(ctx, field, t.of.as_ref(), self_pos)?;
        return Ok(Trigger::EgoWithin { radius_m, point });
    }
    if let Some(eta) = t.ego_eta_s {
        let eta_s = ctx.positive(&format!("{field}.ego_eta_s"), eta)?;
        let point = resolve_of(ctx, field, t.of.as_ref(), self_pos)?;
        let route_s = ego_route_s_of(ctx, tc, &format!("{field}.of"), point)?;
        return Ok(Trigger::EgoEta { eta_s, point, route_s });
    }
    let actor = actor_by_name(ctx, tc, &format!("{field}.after"), t.after.as_deref().unwrap_or_default())?;
    let delay_s = ctx.nonneg(&format!("{field}.delay_s"), t.delay_s.unwrap_or(0.0))?;
    Ok(Trigger::After { actor, event: chain_event(t.event), delay_s })
}

fn chain_event(e: Option<ChainEventSpec>) -> ChainEvent {
    match e.unwrap_or_default() {
        ChainEventSpec::Start => ChainEvent::Start,
        ChainEventSpec::Brake => ChainEvent::Brake,
        ChainEventSpec::End => ChainEvent::End,
    }
}

/// The arc length along the ego route of a point's projection; the foot of the perpendicular
/// must fall strictly inside the route (not clamped to its start or destination) and near it.
fn ego_route_s_of(ctx: &Ctx<'_>, tc: &TriggerCtx<'_>, field: &str, point: Vec2) -> Result<f64> {
    let route = tc.ego_route;
    let proj = route.project(point).ok_or_else(|| ctx.err(field, "?", "empty ego route"))?;
    if proj.s <= 1e-6 || proj.s >= route.length() - 1e-6 || proj.distance > ETA_MAX_OFFSET_M {
        return Err(ctx.err(
            field,
            format!("({:.2}, {:.2})", point.x, point.y),
            format!(
                "does not project onto the ego route: nearest route point at s = {:.1} m of {:.1} m, {:.1} m away (the point must lie beside the route, within {ETA_MAX_OFFSET_M} m, between the ego start and destination)",
                proj.s,
                route.length(),
                proj.distance
            ),
        ));
    }
    Ok(proj.s)
}

/// Index of the scenario actor called `name` (its `name`, or `actors[i]`).
fn actor_by_name(ctx: &Ctx<'_>, tc: &TriggerCtx<'_>, field: &str, name: &str) -> Result<usize> {
    let hits: Vec<usize> = tc.names.iter().enumerate().filter(|(_, n)| *n == name).map(|(i, _)| i).collect();
    match hits.as_slice() {
        [i] => Ok(*i),
        [] => Err(ctx.err(
            field,
            format!("\"{name}\""),
            format!("no actor of that name (actors: {})", tc.names.join(", ")),
        )),
        _ => Err(ctx.err(
            field,
            format!("\"{name}\""),
            "several actors have that name; give them unique `name`s",
        )),
    }
}

/// `brake` → when and how the actor brakes.
fn resolve_brake(
    ctx: &Ctx<'_>,
    tc: &TriggerCtx<'_>,
    bf: &str,
    b: &BrakeSpec,
    has_pace: bool,
) -> Result<BrakeEvent> {
    ctx.exactly_one(
        bf,
        &[
            ("at_s", b.at_s.is_some()),
            ("after_s", b.after_s.is_some()),
            ("ego_within_m", b.ego_within_m.is_some()),
            ("ego_gap_m", b.ego_gap_m.is_some()),
            ("ego_gap_s", b.ego_gap_s.is_some()),
            ("ego_ttc_s", b.ego_ttc_s.is_some()),
            ("ego_eta_s", b.ego_eta_s.is_some()),
            ("gap_held_s", b.gap_held_s.is_some()),
            ("after", b.after.is_some()),
        ],
    )?;
    if let (Some(of), false) = (&b.of, b.ego_within_m.is_some() || b.ego_eta_s.is_some()) {
        return Err(ctx.err(
            format!("{bf}.of"),
            format!("{of:?}"),
            "`of` goes with `ego_within_m` or `ego_eta_s`",
        ));
    }
    if b.after.is_none() {
        if let Some(d) = b.delay_s {
            return Err(ctx.err(format!("{bf}.delay_s"), d, "`delay_s` goes with `after`"));
        }
        if let Some(e) = b.event {
            return Err(ctx.err(format!("{bf}.event"), format!("{e:?}"), "`event` goes with `after`"));
        }
    }
    let when = if let Some(v) = b.at_s {
        BrakeWhen::AtS(ctx.nonneg(&format!("{bf}.at_s"), v)?)
    } else if let Some(v) = b.after_s {
        BrakeWhen::AfterS(ctx.nonneg(&format!("{bf}.after_s"), v)?)
    } else if let Some(v) = b.ego_within_m {
        let radius_m = ctx.positive(&format!("{bf}.ego_within_m"), v)?;
        let point = match &b.of {
            None => None,
            Some(OfSpec::Name(n)) if n == "actor_self" => None,
            Some(of) => Some(resolve_of(ctx, bf, Some(of), Vec2::ZERO)?),
        };
        BrakeWhen::EgoWithin { radius_m, point }
    } else if let Some(v) = b.ego_gap_m {
        BrakeWhen::EgoGap { gap_m: ctx.finite(&format!("{bf}.ego_gap_m"), v)? }
    } else if let Some(v) = b.ego_gap_s {
        BrakeWhen::EgoTimeGap { gap_s: ctx.positive(&format!("{bf}.ego_gap_s"), v)? }
    } else if let Some(v) = b.ego_ttc_s {
        BrakeWhen::EgoTtc { ttc_s: ctx.positive(&format!("{bf}.ego_ttc_s"), v)? }
    } else if let Some(v) = b.ego_eta_s {
        let eta_s = ctx.positive(&format!("{bf}.ego_eta_s"), v)?;
        let point = match &b.of {
            None | Some(OfSpec::Name(_)) => {
                return Err(ctx.err(
                    format!("{bf}.of"),
                    b.of.as_ref().map_or("<missing>".to_string(), |o| format!("{o:?}")),
                    "`ego_eta_s` on a brake needs `of` = a point `[x, y]` or a place",
                ))
            }
            Some(of) => resolve_of(ctx, bf, Some(of), Vec2::ZERO)?,
        };
        let route_s = ego_route_s_of(ctx, tc, &format!("{bf}.of"), point)?;
        BrakeWhen::EgoEta { eta_s, point, route_s }
    } else if let Some(v) = b.gap_held_s {
        if !has_pace {
            return Err(ctx.err(format!("{bf}.gap_held_s"), v, "`gap_held_s` needs a `pace` with a gap"));
        }
        BrakeWhen::GapHeld { held_s: ctx.nonneg(&format!("{bf}.gap_held_s"), v)? }
    } else {
        let actor = actor_by_name(ctx, tc, &format!("{bf}.after"), b.after.as_deref().unwrap_or_default())?;
        let delay_s = ctx.nonneg(&format!("{bf}.delay_s"), b.delay_s.unwrap_or(0.0))?;
        BrakeWhen::After { actor, event: chain_event(b.event), delay_s }
    };
    let hold_s = match b.hold_s {
        Some(h) => Some(ctx.nonneg(&format!("{bf}.hold_s"), h)?),
        None => None,
    };
    Ok(BrakeEvent {
        when,
        decel_mps2: ctx.positive(&format!("{bf}.decel_mps2"), b.decel_mps2)?,
        to_speed_mps: ctx.nonneg(&format!("{bf}.to_speed_mps"), b.to_speed_mps)?,
        hold_s,
    })
}

/// `pace` → ego-relative speed control of a scripted actor on `path` cruising at `speed`.
fn resolve_pace(
    ctx: &Ctx<'_>,
    tc: &TriggerCtx<'_>,
    pf: &str,
    p: &PaceSpec,
    path: &Polyline,
    speed: f64,
) -> Result<Pace> {
    let gap = p.gap_s.is_some() || p.gap_m.is_some();
    let mode = match (gap, &p.meet) {
        (true, None) => {
            if let Some(o) = p.offset_s {
                return Err(ctx.err(format!("{pf}.offset_s"), o, "`offset_s` goes with `meet`"));
            }
            let gap_s = ctx.nonneg(&format!("{pf}.gap_s"), p.gap_s.unwrap_or(0.0))?;
            let gap_m = ctx.finite(&format!("{pf}.gap_m"), p.gap_m.unwrap_or(0.0))?;
            // The actor must start beside the ego route to measure a gap along it.
            let start = path.point_at(0.0);
            let d = tc.ego_route.project(start).map_or(f64::INFINITY, |q| q.distance);
            if d > ETA_MAX_OFFSET_M {
                return Err(ctx.err(
                    pf,
                    format!("gap_s = {gap_s}, gap_m = {gap_m}"),
                    format!("a gap is measured along the ego route, but the actor starts {d:.1} m from it (at most {ETA_MAX_OFFSET_M} m)"),
                ));
            }
            PaceMode::Gap { gap_m, gap_s }
        }
        (false, Some(of)) => {
            if let Some(OfSpec::Name(n)) = Some(of) {
                return Err(ctx.err(format!("{pf}.meet"), n, "give a point `[x, y]` or a place"));
            }
            let point = resolve_of(ctx, &format!("{pf}.meet"), Some(of), Vec2::ZERO)?;
            let route_s = ego_route_s_of(ctx, tc, &format!("{pf}.meet"), point)?;
            let q = path.project(point).ok_or_else(|| ctx.err(format!("{pf}.meet"), "?", "empty path"))?;
            if q.distance > 3.0 || q.s >= path.length() - 1e-6 {
                return Err(ctx.err(
                    format!("{pf}.meet"),
                    format!("({:.2}, {:.2})", point.x, point.y),
                    format!("not on the actor's path: nearest path point {:.1} m away at s = {:.1} m of {:.1} m (at most 3 m, before the path end)", q.distance, q.s, path.length()),
                ));
            }
            let offset_s = ctx.finite(&format!("{pf}.offset_s"), p.offset_s.unwrap_or(0.0))?;
            PaceMode::Meet { point, route_s, actor_s: q.s, offset_s }
        }
        (true, Some(_)) => {
            return Err(ctx.err(pf, "gap + meet", "give a gap (`gap_s`, `gap_m`) or `meet`, not both"))
        }
        (false, None) => {
            return Err(ctx.err(pf, "{}", "give a gap (`gap_s` and/or `gap_m`) or a conflict point `meet`"))
        }
    };
    let min_speed_mps = ctx.nonneg(&format!("{pf}.min_speed_mps"), p.min_speed_mps.unwrap_or(0.0))?;
    let max_speed_mps =
        ctx.positive(&format!("{pf}.max_speed_mps"), p.max_speed_mps.unwrap_or(1.5 * speed))?;
    if max_speed_mps < min_speed_mps {
        return Err(ctx.err(
            format!("{pf}.max_speed_mps"),
            max_speed_mps,
            format!("below min_speed_mps ({min_speed_mps})"),
        ));
    }
    let until_s = match p.until_s {
        Some(u) => ctx.nonneg(&format!("{pf}.until_s"), u)?,
        None => f64::INFINITY,
    };
    Ok(Pace { mode, min_speed_mps, max_speed_mps, until_s })
}

/// Chained triggers must point at scripted actors (brake: one with a brake event) and must
/// not form a cycle.
fn check_chains(file: &Path, actors: &[ResolvedActor]) -> Result<()> {
    let target = |i: usize| match &actors[i].motion {
        ActorMotion::Scripted(p) => match p.trigger {
            Trigger::After { actor, event, .. } => Some((actor, event)),
            _ => None,
        },
        _ => None,
    };
    for i in 0..actors.len() {
        let Some((j, event)) = target(i) else { continue };
        let field = format!("actors[{i}].start.after");
        let value = format!("\"{}\"", actors[j].name);
        match &actors[j].motion {
            ActorMotion::Scripted(q) => {
                if event == ChainEvent::Brake && q.brake.is_none() {
                    return Err(Error::scenario(
                        file,
                        field,
                        value,
                        "event = \"brake\" but that actor has no `brake`",
                    ));
                }
            }
            _ => {
                return Err(Error::scenario(
                    file,
                    field,
                    value,
                    "that actor is not scripted (it has no trigger or events)",
                ))
            }
        }
        let mut chain = vec![i];
        let mut k = j;
        for _ in 0..actors.len() {
            if k == i {
                let names: Vec<&str> = chain.iter().map(|&x| actors[x].name.as_str()).collect();
                return Err(Error::scenario(
                    file,
                    field,
                    value,
                    format!("chained triggers form a cycle: {} → {}", names.join(" → "), actors[i].name),
                ));
            }
            chain.push(k);
            match target(k) {
                Some((n, _)) => k = n,
                None => break,
            }
        }
    }
    Ok(())
}

fn resolve_actor(ctx: &Ctx<'_>, tc: &TriggerCtx<'_>, i: usize, a: &ActorSpec) -> Result<ResolvedActor> {
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
            if !a.lane_changes.is_empty() {
                return Err(ctx.err(
                    format!("{field}.lane_changes"),
                    a.lane_changes.len(),
                    "lane changes need a `route` actor (its path follows lanes)",
                ));
            }
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
            let lanes = match (&r.edges, &r.lanes) {
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
                    map.route_lanes_for(&edges, start_lane, vclass)
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
                    lane_chain(ctx, &format!("{f}.lanes"), ids)?
                }
                _ => return Err(ctx.err(&f, "{..}", "give exactly one of `edges` or `lanes`")),
            };
            let full = map.lanes_polyline(&lanes);
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
            let (full, s1) = apply_lane_changes(ctx, &field, full, &lanes, s0, s1, &a.lane_changes, vclass)?;
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
    let trigger = resolve_trigger(ctx, tc, &format!("{field}.start"), a.start.as_ref(), path.point_at(0.0))?;
    let pace = match &a.pace {
        Some(p) => Some(resolve_pace(ctx, tc, &format!("{field}.pace"), p, &path, speed)?),
        None => None,
    };
    let has_gap = matches!(pace, Some(Pace { mode: PaceMode::Gap { .. }, .. }));
    let brake = match &a.brake {
        None => None,
        Some(b) => Some(resolve_brake(ctx, tc, &format!("{field}.brake"), b, has_gap)?),
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
        pace,
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
    let names: Vec<String> = spec
        .actors
        .iter()
        .enumerate()
        .map(|(i, a)| a.name.clone().unwrap_or_else(|| format!("actors[{i}]")))
        .collect();
    let tc = TriggerCtx { ego_route: &ego.route, names: &names };
    for (i, a) in spec.actors.iter().enumerate() {
        actors.push(resolve_actor(&ctx, &tc, i, a)?);
    }
    check_chains(file, &actors)?;
    let lights = resolve_lights(&ctx, &spec.lights)?;
    for (i, o) in spec.obstacles.iter().enumerate() {
        actors.push(resolve_obstacle(&ctx, i, spec.actors.len() + i, o)?);
    }
    let signs =
        spec.signs.iter().enumerate().map(|(i, s)| resolve_sign(&ctx, i, s)).collect::<Result<Vec<_>>>()?;
    let mut traffic =
        crate::scenario::traffic::resolve_traffic(file, &map, spec.traffic.as_ref(), &ego.route)?;
    let (variation, jitter) =
        crate::scenario::variation_spec::resolve_variation(file, spec.variation.as_ref())?;
    traffic.jitter = jitter;
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
        lights,
        variation,
    })
}

/// `[[lights]]` → the programs the overridden lights run (see [`LightProgram`]).
fn resolve_lights(ctx: &Ctx<'_>, specs: &[LightOverrideSpec]) -> Result<Vec<LightProgram>> {
    let map = ctx.map;
    let mut out: Vec<LightProgram> = Vec::with_capacity(specs.len());
    for (i, l) in specs.iter().enumerate() {
        let f = format!("lights[{i}]");
        let tl_id = l.tls.as_str();
        let known = map.tl_ids();
        if !known.contains(&tl_id) {
            return Err(ctx.err(
                format!("{f}.tls"),
                format!("\"{tl_id}\""),
                format!("no traffic light of that id in the map (lights: {})", known.join(", ")),
            ));
        }
        if out.iter().any(|o| o.tl_id == tl_id) {
            return Err(ctx.err(format!("{f}.tls"), format!("\"{tl_id}\""), "overridden twice"));
        }
        let logic = map.tl_logic(tl_id);
        // Link count: the state length of the map's program, else the highest link index + 1.
        let links = logic
            .and_then(|lg| lg.phases.first())
            .map(|p| p.state.chars().count())
            .unwrap_or_else(|| map.tl_links(tl_id).iter().map(|k| k.link_index + 1).max().unwrap_or(0));
        let (phases, base_offset, replaced) = match &l.phases {
            Some(ps) => {
                if ps.is_empty() {
                    return Err(ctx.err(format!("{f}.phases"), "[]", "needs at least one phase"));
                }
                let mut phases = Vec::with_capacity(ps.len());
                for (k, p) in ps.iter().enumerate() {
                    let pf = format!("{f}.phases[{k}]");
                    let n = p.state.chars().count();
                    if n != links {
                        return Err(ctx.err(
                            format!("{pf}.state"),
                            format!("\"{}\"", p.state),
                            format!("has {n} characters; light `{tl_id}` controls {links} links (one character per link index)"),
                        ));
                    }
                    if let Some(c) = p.state.chars().find(|c| !"rygGsuoO".contains(*c)) {
                        return Err(ctx.err(
                            format!("{pf}.state"),
                            format!("\"{}\"", p.state),
                            format!("unknown signal character `{c}` (use SUMO's r y g G s u o O)"),
                        ));
                    }
                    let duration_s = ctx.positive(&format!("{pf}.duration_s"), p.duration_s)?;
                    phases.push(crate::map::TlPhase { duration_s, state: p.state.clone() });
                }
                (phases, 0.0, true)
            }
            None => match logic {
                Some(lg) if !lg.phases.is_empty() && lg.cycle_s() > 0.0 => {
                    (lg.phases.clone(), lg.offset_s, false)
                }
                _ => {
                    return Err(ctx.err(
                        format!("{f}.tls"),
                        format!("\"{tl_id}\""),
                        "the map has no timed program for this light; give `phases`",
                    ))
                }
            },
        };
        let offset_s = match (l.offset_s, l.start_phase, l.phase_elapsed_s) {
            (Some(_), Some(k), _) => {
                return Err(ctx.err(
                    &f,
                    format!("start_phase = {k}"),
                    "give `offset_s` or `start_phase`, not both",
                ))
            }
            (_, None, Some(e)) => {
                return Err(ctx.err(
                    format!("{f}.phase_elapsed_s"),
                    e,
                    "`phase_elapsed_s` goes with `start_phase`",
                ))
            }
            (Some(o), None, None) => base_offset + ctx.finite(&format!("{f}.offset_s"), o)?,
            (None, Some(k), e) => {
                if k >= phases.len() {
                    return Err(ctx.err(
                        format!("{f}.start_phase"),
                        k,
                        format!("light `{tl_id}` has {} phases (0-based index)", phases.len()),
                    ));
                }
                let e = ctx.nonneg(&format!("{f}.phase_elapsed_s"), e.unwrap_or(0.0))?;
                if e >= phases[k].duration_s {
                    return Err(ctx.err(
                        format!("{f}.phase_elapsed_s"),
                        e,
                        format!("must be below the phase's duration {} s", phases[k].duration_s),
                    ));
                }
                let before: f64 = phases[..k].iter().map(|p| p.duration_s).sum();
                -(before + e)
            }
            (None, None, None) if replaced => 0.0,
            (None, None, None) => {
                return Err(ctx.err(
                    &f,
                    format!("tls = \"{tl_id}\""),
                    "give one of `offset_s`, `start_phase` or `phases`",
                ))
            }
        };
        out.push(LightProgram { tl_id: tl_id.to_string(), offset_s, phases, replaced });
    }
    Ok(out)
}

/// Default length of a lane change along the path, m.
pub const LANE_CHANGE_LENGTH_M: f64 = 20.0;

/// Applies `lane_changes` to a route actor's path `full` (over `lanes`, cut later to
/// [`s0`, `s1`]): from `s0 + at_s` the actor blends over `length_m` (cosine lateral profile)
/// from its lane onto `to_lane`, a neighbour lane of the same edge, and then follows the route's
/// remaining edges from `to_lane` along the lane graph (its connections; where `to_lane` does
/// not lead on, the router's own lane change is kept). Returns the new path and its end.
#[allow(clippy::too_many_arguments)]
fn apply_lane_changes(
    ctx: &Ctx<'_>,
    field: &str,
    full: Polyline,
    lanes: &[LaneIdx],
    s0: f64,
    s1: f64,
    changes: &[LaneChangeSpec],
    vclass: VClass,
) -> Result<(Polyline, f64)> {
    let map = ctx.map;
    let mut cur = full;
    let mut s1 = s1;
    let mut lanes: Vec<LaneIdx> = lanes.to_vec();
    let mut done_s = s0;
    for (k, c) in changes.iter().enumerate() {
        let f = format!("{field}.lane_changes[{k}]");
        let at_s = ctx.nonneg(&format!("{f}.at_s"), c.at_s)?;
        let len = ctx.positive(&format!("{f}.length_m"), c.length_m.unwrap_or(LANE_CHANGE_LENGTH_M))?;
        let at = s0 + at_s;
        if at < done_s - 1e-6 {
            return Err(ctx.err(
                format!("{f}.at_s"),
                at_s,
                format!("starts before the previous lane change ends (at_s {:.1} m)", done_s - s0),
            ));
        }
        if at + len > s1 + 1e-6 {
            return Err(ctx.err(
                format!("{f}.at_s"),
                at_s,
                format!(
                    "the lane change (ending at {:.1} m) runs past the end of the path ({:.1} m)",
                    at_s + len,
                    s1 - s0
                ),
            ));
        }
        let p = cur.point_at(at);
        // The lane the actor is on at `at`: the nearest lane of a normal edge of the route,
        // with the point inside it (not beyond its ends, i.e. not in a junction).
        let from = lanes
            .iter()
            .copied()
            .filter(|&l| map.lane_function(l) == EdgeFunction::Normal)
            .filter_map(|l| {
                let sh = &map.lanes[l].shape;
                let pr = sh.project(p)?;
                (pr.s > 1e-6 && pr.s < sh.length() - 1e-6 && pr.distance <= 0.5 * map.lanes[l].width_m + 0.5)
                    .then_some((pr.distance, l))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
            .map(|x| x.1)
            .ok_or_else(|| {
                ctx.err(
                    format!("{f}.at_s"),
                    at_s,
                    format!(
                        "the path is not on a lane of a normal edge there ({:.1}, {:.1}): inside a junction?",
                        p.x, p.y
                    ),
                )
            })?;
        let to = ctx.lane(&format!("{f}.to_lane"), &c.to_lane)?;
        let (lf, lt) = (&map.lanes[from], &map.lanes[to]);
        if lt.edge != lf.edge || lf.index.abs_diff(lt.index) != 1 {
            let neighbours: Vec<&str> = map.edges[lf.edge]
                .lanes
                .iter()
                .map(|&l| &map.lanes[l])
                .filter(|l| l.index.abs_diff(lf.index) == 1)
                .map(|l| l.id.as_str())
                .collect();
            return Err(ctx.err(
                format!("{f}.to_lane"),
                format!("\"{}\"", c.to_lane),
                format!(
                    "not a neighbour of lane `{}` the actor is on at at_s = {at_s} (neighbours: {})",
                    lf.id,
                    if neighbours.is_empty() { "none".to_string() } else { neighbours.join(", ") }
                ),
            ));
        }
        if !lt.allow.contains(vclass) {
            return Err(ctx.err(
                format!("{f}.to_lane"),
                format!("\"{}\"", c.to_lane),
                format!("lane does not allow vClass {}", vclass.sumo_name()),
            ));
        }
        // The route's normal edges from the current one on.
        let pos = lanes.iter().position(|&l| l == from).unwrap_or(0);
        let mut rem: Vec<EdgeIdx> = Vec::new();
        for &l in &lanes[pos..] {
            let e = map.lanes[l].edge;
            if map.edges[e].function == EdgeFunction::Normal && rem.last() != Some(&e) {
                rem.push(e);
            }
        }
        let next_lanes = map
            .route_lanes_for(&rem, Some(to), vclass)
            .map_err(|e| map_err(ctx, &format!("{f}.to_lane"), &format!("\"{}\"", c.to_lane), e))?;
        let next = map.lanes_polyline(&next_lanes);
        let n_a = next.project(p).map_or(0.0, |q| q.s);
        if n_a + len > next.length() {
            return Err(ctx.err(
                format!("{f}.length_m"),
                len,
                format!(
                    "the lane change does not fit on the rest of the route ({:.1} m left)",
                    next.length() - n_a
                ),
            ));
        }
        let end_pt = cur.point_at(s1);
        let mut pts: Vec<Vec2> = cur.slice(0.0, at).points().to_vec();
        let n = (len / 1.0).ceil().max(2.0) as usize;
        for i in 1..=n {
            let u = len * i as f64 / n as f64;
            let w = 0.5 - 0.5 * (std::f64::consts::PI * u / len).cos();
            pts.push(cur.point_at(at + u).lerp(next.point_at(n_a + u), w));
        }
        pts.extend_from_slice(&next.slice(n_a + len, next.length()).points()[1..]);
        let composite = Polyline::new(pts);
        let tail_left = next.length() - next.project(end_pt).map_or(next.length(), |q| q.s);
        s1 = (composite.length() - tail_left).clamp(at + len, composite.length());
        done_s = at + len;
        cur = composite;
        lanes = next_lanes;
    }
    Ok((cur, s1))
}
