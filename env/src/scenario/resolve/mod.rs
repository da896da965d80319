//! Scenario file → [`ResolvedScenario`]: every place, route and path turned into world-frame
//! geometry against the map, with errors naming file, TOML field and value. One file per part of
//! the scenario: [`ego`], [`actor`] (actors, obstacles, signs, pacing), [`trigger`] (start
//! triggers, brakes, chains), [`lights`] and [`lane_change`].

mod actor;
mod ego;
mod lane_change;
mod lights;
mod trigger;

pub use actor::default_speed_mps;
pub use ego::EGO_VCLASS;
pub use lane_change::LANE_CHANGE_LENGTH_M;
pub use trigger::{OfRule, OF_RULES};

use crate::geom::{Polyline, Pose, Vec2};
use crate::map::{EdgeFunction, EdgeIdx, LaneIdx, Network, VClass};
use crate::scenario::map_paths::{resolve_map_path, LoadOptions};
use crate::scenario::model::ResolvedScenario;
use crate::scenario::schema::{PlaceSpec, ScenarioFile};
use crate::scenario::tables::{default_size, CATEGORIES, SCENARIO_VERSION};
use crate::view::ActorKind;
use crate::{Error, Result};
use actor::{resolve_actor, resolve_obstacle, resolve_sign};
use ego::resolve_ego;
use lights::resolve_lights;
use std::path::Path;
use std::sync::Arc;
use trigger::check_chains;

/// A start/destination given by coordinates must lie this close to a drivable lane centreline.
pub const SNAP_DISTANCE_M: f64 = 6.0;
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
    let condition_choices =
        crate::scenario::variation_spec::resolve_condition_choices(file, spec.variation.as_ref())?;
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
        conditions: spec.conditions.map(Into::into).unwrap_or_default(),
        condition_choices,
    })
}
