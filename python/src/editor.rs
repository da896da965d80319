//! What the scenario editor draws, all from the world's own code: a network's geometry, lane
//! snapping, and a scenario's resolved geometry (ego route, actor paths, triggers) from the text
//! being edited. The page never re-implements any of it.

use crate::env::{err, map_cache};
use crate::json::to_py;
use dh_env::geom::{Pose, Vec2};
use dh_env::map::{EdgeFunction, Network};
use dh_env::scenario::{
    resolve_map_path, ActorMotion, LightProgram, LoadOptions, ResolvedScenario, Scenario, Summary, Trigger,
};
use pyo3::prelude::*;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::sync::Arc;

fn pt(p: Vec2) -> Value {
    json!([p.x, p.y])
}

fn pose(p: Pose) -> Value {
    json!({"x": p.pos.x, "y": p.pos.y, "yaw": p.yaw})
}

fn function_name(f: EdgeFunction) -> &'static str {
    match f {
        EdgeFunction::Normal => "normal",
        EdgeFunction::Internal => "internal",
        EdgeFunction::Crossing => "crossing",
        EdgeFunction::WalkingArea => "walkingarea",
        EdgeFunction::Connector => "connector",
    }
}

fn load_map(py: Python<'_>, map: &str, sumo_home: Option<&Path>) -> PyResult<(PathBuf, Arc<Network>)> {
    let here = Path::new("<command line>");
    let path = resolve_map_path(here, map, sumo_home).map_err(|e| err(py, e))?;
    let cache = map_cache();
    let net = py.detach(|| cache.get_or_load(&path)).map_err(|e| err(py, e))?;
    Ok((path, net))
}

/// A network's drawable geometry: lanes with their centre-line shapes, junction
/// outlines, signal heads at their stop lines, and each light's program.
#[pyfunction]
#[pyo3(signature = (map, sumo_home=None))]
pub fn map_geometry<'py>(
    py: Python<'py>,
    map: &str,
    sumo_home: Option<PathBuf>,
) -> PyResult<Bound<'py, PyAny>> {
    let (path, net) = load_map(py, map, sumo_home.as_deref())?;
    let lanes: Vec<Value> = net
        .lanes
        .iter()
        .map(|l| {
            let edge = &net.edges[l.edge];
            json!({
                "id": l.id, "edge": edge.id, "function": function_name(edge.function),
                "index": l.index, "width_m": l.width_m, "length_m": l.length_m,
                "speed_mps": l.speed_mps, "allow": l.allow.sumo_names(), "drivable": l.is_drivable(),
                "shape": l.shape.points().iter().map(|&p| pt(p)).collect::<Vec<_>>(),
            })
        })
        .collect();
    let junctions: Vec<Value> = net
        .junctions
        .iter()
        .map(|j| {
            json!({
                "id": j.id, "kind": j.kind, "pos": pt(j.pos),
                "shape": j.shape.iter().map(|&p| pt(p)).collect::<Vec<_>>(),
            })
        })
        .collect();
    let heads: Vec<Value> = dh_env::map::signal_heads(&net)
        .iter()
        .map(|h| {
            json!({
                "tl_id": h.tl_id, "lane": net.lanes[h.lane].id,
                "link_indices": h.link_indices.to_vec(), "stop_line": pose(net.stop_line(h.lane)),
            })
        })
        .collect();
    let programs: Vec<Value> = net
        .tl_ids()
        .iter()
        .filter_map(|id| net.tl_logic(id))
        .map(|l| {
            json!({
                "id": l.id, "kind": l.kind, "program_id": l.program_id, "offset_s": l.offset_s,
                "cycle_s": l.cycle_s(),
                "phases": l.phases.iter().map(|p| json!({"duration_s": p.duration_s, "state": p.state}))
                    .collect::<Vec<_>>(),
            })
        })
        .collect();
    let b = net.bounds();
    let out = json!({
        "path": path.display().to_string(),
        "bounds": [b.min.x, b.min.y, b.max.x, b.max.y],
        "lanes": lanes, "junctions": junctions, "signal_heads": heads, "programs": programs,
    });
    to_py(py, &out)
}

/// The lane nearest to a world point, as a scenario place: `(lane id, s, distance)`, or `None`
/// when no lane lies within `max_dist_m`. `vclass` (a SUMO class, e.g. "passenger",
/// "pedestrian") keeps only lanes that allow it; internal (junction) lanes are skipped unless
/// `internal` is set.
#[pyfunction]
#[pyo3(signature = (map, x, y, max_dist_m=10.0, vclass=None, internal=false, sumo_home=None))]
#[allow(clippy::too_many_arguments)]
pub fn snap_to_lane(
    py: Python<'_>,
    map: &str,
    x: f64,
    y: f64,
    max_dist_m: f64,
    vclass: Option<&str>,
    internal: bool,
    sumo_home: Option<PathBuf>,
) -> PyResult<Option<(String, f64, f64)>> {
    let (_, net) = load_map(py, map, sumo_home.as_deref())?;
    let class = match vclass {
        None => None,
        Some(v) => Some(dh_env::map::VClass::from_sumo(v).ok_or_else(|| {
            err(
                py,
                dh_env::Error::config("vclass", v, "not a SUMO vehicle class (e.g. passenger, pedestrian)"),
            )
        })?),
    };
    let p = Vec2 { x, y };
    if !p.is_finite() {
        return Err(err(py, dh_env::Error::config("point", format!("({x}, {y})"), "must be finite")));
    }
    let hit = net.nearest_lane(p, max_dist_m, class, internal);
    Ok(hit.map(|(i, pr)| (net.lanes[i].id.clone(), pr.s, pr.distance)))
}

fn trigger_json(t: &Trigger, names: &[String]) -> Value {
    match t {
        Trigger::Time(s) => json!({"kind": "time", "time_s": s}),
        Trigger::EgoWithin { radius_m, point } => {
            json!({"kind": "ego_distance", "radius_m": radius_m, "point": pt(*point)})
        }
        Trigger::EgoEta { eta_s, point, route_s } => {
            json!({"kind": "ego_eta", "eta_s": eta_s, "point": pt(*point), "route_s": route_s})
        }
        Trigger::After { actor, event, delay_s } => json!({
            "kind": "after", "actor": names.get(*actor), "event": format!("{event:?}").to_lowercase(),
            "delay_s": delay_s,
        }),
    }
}

/// Phases shown per light at most (a 1 s program over a long window stays drawable).
const MAX_SCHEDULE: usize = 4000;

/// Every light's program as the episode runs it (the scenario's `[[lights]]` override resolved
/// against the map — `start_phase` turned into an offset — else the map's program) and its phases
/// over episode time [0, `horizon_s`] as `[t0, t1, phase index]`, by the world's own
/// `LightProgram::phase_at`: the editor draws the program over time from it.
fn lights_json(s: &ResolvedScenario, horizon_s: f64) -> Vec<Value> {
    s.map
        .tl_ids()
        .iter()
        .filter_map(|id| {
            let program = match s.lights.iter().find(|l| l.tl_id == *id) {
                Some(l) => l.clone(),
                None => {
                    let l = s.map.tl_logic(id)?;
                    LightProgram {
                        tl_id: l.id.clone(),
                        offset_s: l.offset_s,
                        phases: l.phases.clone(),
                        replaced: false,
                    }
                }
            };
            let mut schedule = Vec::new();
            let mut t = 0.0;
            while t < horizon_s && schedule.len() < MAX_SCHEDULE {
                let Some((i, left)) = program.phase_at(t) else { break };
                // A phase's end is found again from just past it (left is 0 at a cycle's end).
                let end = (t + left.max(1e-6)).min(horizon_s);
                schedule.push(json!([t, end, i]));
                t = end;
            }
            Some(json!({
                "tl_id": id, "offset_s": program.offset_s,
                "overridden": s.lights.iter().any(|l| l.tl_id == *id),
                "cycle_s": program.phases.iter().map(|p| p.duration_s.max(0.0)).sum::<f64>(),
                "phases": program.phases.iter().map(|p| json!({"duration_s": p.duration_s, "state": p.state}))
                    .collect::<Vec<_>>(),
                "schedule": schedule,
            }))
        })
        .collect()
}

fn scenario_json(s: &ResolvedScenario) -> Value {
    let names: Vec<String> = s.actors.iter().map(|a| a.name.clone()).collect();
    let actors: Vec<Value> = s
        .actors
        .iter()
        .map(|a| {
            let motion = match &a.motion {
                ActorMotion::Static { pose: p } => json!({"kind": "static", "pose": pose(*p)}),
                ActorMotion::External { pose: p } => json!({"kind": "external", "pose": pose(*p)}),
                ActorMotion::Scripted(sp) => json!({
                    "kind": "scripted",
                    "path": sp.path.points().iter().map(|&p| pt(p)).collect::<Vec<_>>(),
                    "length_m": sp.path.length(),
                    "legs": sp.legs,
                    "trigger": trigger_json(&sp.trigger, &names),
                    "start": pose(Pose::new(sp.path.point_at(0.0), sp.path.heading_at(0.0))),
                }),
            };
            json!({
                "name": a.name, "kind": a.kind, "length_m": a.length_m, "width_m": a.width_m,
                "color": a.color, "motion": motion,
                // The class whose lanes the actor keeps to (the editor's off-road warning).
                "vclass": dh_env::scenario::vclass_of(a.kind).sumo_name(),
            })
        })
        .collect();
    json!({
        "summary": Summary::of(s),
        "scenario_duration_s": s.scenario_duration_s(),
        "ego": {
            "start": pose(s.ego.start),
            "start_lane": s.map.lanes[s.ego.start_lane].id,
            "destination": pt(s.ego.destination),
            "route": s.ego.route.points().iter().map(|&p| pt(p)).collect::<Vec<_>>(),
            "length_m": s.ego.params.length_m,
            "width_m": s.ego.params.width_m,
        },
        "actors": actors,
        // The episode's timeout (2 × the scenario duration) is as far as a preview can go.
        "lights": lights_json(s, 2.0 * s.scenario_duration_s()),
    })
}

/// Validates scenario text as if it were the file at `path` (relative map paths and error
/// messages refer to `path`, which need not exist) and returns its resolved geometry:
/// the `validate` summary, the ego's start, destination and route, every actor's path and
/// trigger, and every light's program with its phases over the episode's timeout. Errors are
/// raised as `scenario validate` prints them.
#[pyfunction]
#[pyo3(signature = (path, text, sumo_home=None))]
pub fn scenario_geometry<'py>(
    py: Python<'py>,
    path: &str,
    text: &str,
    sumo_home: Option<PathBuf>,
) -> PyResult<Bound<'py, PyAny>> {
    let opts = LoadOptions { sumo_home, cache: Some(map_cache()) };
    let s = py.detach(|| Scenario::load_str(path, text, &opts)).map_err(|e| err(py, e))?;
    to_py(py, &scenario_json(&s))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(map_geometry, m)?)?;
    m.add_function(wrap_pyfunction!(snap_to_lane, m)?)?;
    m.add_function(wrap_pyfunction!(scenario_geometry, m)?)?;
    Ok(())
}
