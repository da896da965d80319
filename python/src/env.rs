//! `Sim`: the R4 episode (`dh_env::sim::Sim`) for the Python env facade. One call per decision;
//! the GIL is released while the world ticks and renders; images leave as owned numpy arrays.

use crate::errors::to_pyerr;
use crate::json::{from_py, to_py};
use crate::sumo_native::PySumoSession;
use dh_agents::expert::{Expert, ExpertParams};
use dh_env::drive::{
    ActuationBridge, Control, Decision, DecisionFailure, MetaAction, PathAction, Plan, SpeedAction,
};
use dh_env::render::{BevConfig, CameraConfig, GifWriter, Image};
use dh_env::scenario::{LoadOptions, MapCache, Scenario};
use dh_env::sim::{Action, ActionMode, FrameSnapshot, Observation, Sim, SimConfig, StepInfo};
use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

/// One action of the env's mode from a flat row of numbers: `[steer, target]` (decision),
/// `[throttle, brake, steer]` (raw), K (x, y) pairs flattened (waypoints) or `[path, speed]`
/// indices (meta).
pub(crate) fn action_from_row(config: &SimConfig, a: &[f64]) -> dh_env::Result<Action> {
    let bad = |want: String| dh_env::Error::config("action", format!("{a:?}"), want);
    Ok(match (config.action_mode, a) {
        (ActionMode::Decision, [steer, target]) => {
            Action::Decision(Decision { steer: *steer, target_speed_mps: *target })
        }
        (ActionMode::Raw, [throttle, brake, steer]) => {
            Action::Raw(Control { throttle: *throttle, brake: *brake, steer: *steer })
        }
        (ActionMode::Waypoints, flat) if flat.len() == 2 * config.waypoints as usize => {
            Action::Plan(Plan::Waypoints(flat.chunks_exact(2).map(|c| (c[0], c[1])).collect()))
        }
        (ActionMode::Meta, [path, speed]) => {
            let index = |v: f64| (v.fract() == 0.0 && v.abs() < 1e9).then_some(v as i64);
            let path = index(*path).and_then(PathAction::from_index);
            let speed = index(*speed).and_then(SpeedAction::from_index);
            match (path, speed) {
                (Some(path), Some(speed)) => Action::Plan(Plan::Meta(MetaAction { path, speed })),
                _ => return Err(bad("expected [path, speed] with path in 0..=5 and speed in 0..=3".into())),
            }
        }
        (mode, _) => return Err(bad(format!("expected {} numbers", action_width(config, mode)))),
    })
}

/// Numbers in one action row of `mode`.
pub(crate) fn action_width(config: &SimConfig, mode: ActionMode) -> usize {
    match mode {
        ActionMode::Decision | ActionMode::Meta => 2,
        ActionMode::Raw => 3,
        ActionMode::Waypoints => 2 * config.waypoints as usize,
    }
}

/// Networks parsed once per process, shared by every env on the same map.
pub(crate) fn map_cache() -> Arc<MapCache> {
    static CACHE: OnceLock<Arc<MapCache>> = OnceLock::new();
    CACHE.get_or_init(|| Arc::new(MapCache::new())).clone()
}

pub(crate) fn err(py: Python<'_>, e: dh_env::Error) -> PyErr {
    to_pyerr(py, e)
}

#[pyclass(name = "Sim", module = "drivehierarchy._core")]
pub struct PySim {
    inner: Sim,
    expert: Expert,
    /// Turns the expert's decisions into raw controls when the env runs in raw mode.
    expert_bridge: ActuationBridge,
}

#[pymethods]
impl PySim {
    #[new]
    /// `config`: the core's settings (`R4Config.to_core()`, a dict). `text`: the scenario's TOML
    /// standing for the file at `scenario` (an editor's unsaved buffer; relative paths and error
    /// messages still refer to `scenario`).
    #[pyo3(signature = (scenario, config, sumo_home=None, text=None))]
    fn new(
        py: Python<'_>,
        scenario: &str,
        config: &Bound<'_, PyAny>,
        sumo_home: Option<PathBuf>,
        text: Option<&str>,
    ) -> PyResult<Self> {
        let config: SimConfig = from_py("config", config).map_err(|e| err(py, e))?;
        config.validate().map_err(|e| err(py, e))?;
        let load = LoadOptions { sumo_home, cache: Some(map_cache()) };
        let path = Path::new(scenario).to_path_buf();
        let inner = py
            .detach(|| match text {
                None => Sim::new(&path, config, &load),
                Some(t) => Sim::from_scenario(Scenario::load_str(&path, t, &load)?, config),
            })
            .map_err(|e| err(py, e))?;
        let expert = Expert::new(ExpertParams::default()).map_err(|e| err(py, e))?;
        Ok(PySim { inner, expert, expert_bridge: ActuationBridge::new() })
    }

    #[getter]
    fn scenario_id(&self) -> String {
        self.inner.scenario().id.clone()
    }

    #[getter]
    fn category(&self) -> String {
        self.inner.scenario().category.clone()
    }

    #[getter]
    fn route_length_m(&self) -> f64 {
        self.inner.scenario().route_length_m()
    }

    /// Starts an episode: `(observation, info)`. `seed` seeds the world (SUMO, random trips);
    /// `variation` (default: `seed`) the scenario's jitter, 0 = the scenario as written.
    #[pyo3(signature = (seed, variation = None))]
    fn reset<'py>(
        &mut self,
        py: Python<'py>,
        seed: u64,
        variation: Option<u64>,
    ) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyAny>)> {
        let inner = &mut self.inner;
        let v = variation.unwrap_or(seed);
        let (obs, info) = py.detach(|| inner.reset_varied(seed, v)).map_err(|e| err(py, e))?;
        self.expert.reset();
        if let Ok(world) = self.inner.world() {
            self.expert.set_vehicle(world.vehicle_params());
        }
        self.expert_bridge.reset();
        Ok((obs_to_py(py, obs)?, info_to_py(py, &info)?))
    }

    /// A decision given as a raw VLM reply (`None`: no reply, e.g. a transport error), parsed
    /// here by the protocol's reply parser; a failure holds the previous control.
    #[allow(clippy::type_complexity)]
    #[pyo3(signature = (reply))]
    fn step_reply<'py>(
        &mut self,
        py: Python<'py>,
        reply: Option<String>,
    ) -> PyResult<(Bound<'py, PyDict>, f64, bool, bool, Bound<'py, PyAny>)> {
        let config = self.inner.config();
        let action = match config.action_mode {
            ActionMode::Waypoints | ActionMode::Meta => {
                let parsed = match &reply {
                    Some(text) if config.action_mode == ActionMode::Meta => {
                        dh_agents::plan_reply::parse_meta_reply(text)
                    }
                    Some(text) => {
                        dh_agents::plan_reply::parse_waypoints_reply(text, config.waypoints as usize)
                    }
                    None => Err(DecisionFailure::NoReply),
                };
                Action::PlanReply { raw: reply, parsed }
            }
            ActionMode::Decision | ActionMode::Raw => {
                let parsed = match &reply {
                    Some(text) => dh_agents::vlm::parse_for_env(text),
                    None => Err(DecisionFailure::NoReply),
                };
                Action::Reply { raw: reply, parsed }
            }
        };
        let inner = &mut self.inner;
        let out = py.detach(|| inner.step(action)).map_err(|e| err(py, e))?;
        Ok((obs_to_py(py, out.observation)?, out.reward, out.terminated, false, info_to_py(py, &out.info)?))
    }

    /// Every decision of the running episode: decision, tick, raw, parsed, failure, control.
    fn decision_log<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let log = self.inner.decision_log().map_err(|e| err(py, e))?;
        to_py(py, log)
    }

    /// One decision: `(observation, reward, terminated, truncated, info)`.
    #[allow(clippy::type_complexity)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        action: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<(Bound<'py, PyDict>, f64, bool, bool, Bound<'py, PyAny>)> {
        let a = action.as_slice().map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))?;
        let action = action_from_row(self.inner.config(), a).map_err(|e| err(py, e))?;
        let inner = &mut self.inner;
        let out = py.detach(|| inner.step(action)).map_err(|e| err(py, e))?;
        Ok((obs_to_py(py, out.observation)?, out.reward, out.terminated, false, info_to_py(py, &out.info)?))
    }

    /// The privileged expert's action for the current state, in the env's action mode.
    fn expert_action<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let world = self.inner.world().map_err(|e| err(py, e))?;
        let config = self.inner.config();
        match config.action_mode {
            ActionMode::Waypoints => {
                let (n, dt) = (config.waypoints as usize, config.waypoint_dt_s);
                let pts = self.expert.waypoints_in_world(world, self.inner.route(), n, dt);
                return Ok(PyArray1::from_vec(py, pts.iter().flat_map(|&(x, y)| [x, y]).collect()));
            }
            ActionMode::Meta => {
                let m = self.expert.meta_in_world(world, self.inner.route());
                return Ok(PyArray1::from_vec(py, vec![m.path as u8 as f64, m.speed as u8 as f64]));
            }
            ActionMode::Decision | ActionMode::Raw => {}
        }
        let a = self.expert.act_in_world(world, self.inner.route());
        let decision = Decision::from(a);
        let v = match config.action_mode {
            ActionMode::Decision | ActionMode::Waypoints | ActionMode::Meta => {
                vec![decision.steer, decision.target_speed_mps]
            }
            ActionMode::Raw => {
                let speed = world.ego().speed_mps;
                let c = self.expert_bridge.apply(Some(decision), speed);
                vec![c.throttle, c.brake, c.steer]
            }
        };
        Ok(PyArray1::from_vec(py, v))
    }

    /// Renders the current state: `"front"` (the observation's camera or the protocol default),
    /// `"bev"`, or `"chase"`.
    fn render<'py>(&self, py: Python<'py>, kind: &str) -> PyResult<Bound<'py, PyAny>> {
        let cfg = self.inner.config();
        let mut img = Image::default();
        let inner = &self.inner;
        let res = match kind {
            "front" => {
                let cam = cfg.front.unwrap_or_default();
                py.detach(|| inner.render_camera(&cam, &mut img))
            }
            "chase" => {
                let cam = CameraConfig::chase();
                py.detach(|| inner.render_camera(&cam, &mut img))
            }
            "bev" => {
                let bev = cfg.bev.unwrap_or_default();
                py.detach(|| inner.render_bev(&bev, &mut img))
            }
            other => {
                return Err(err(
                    py,
                    dh_env::Error::config("render.kind", other, "expected 'front', 'bev' or 'chase'"),
                ))
            }
        };
        res.map_err(|e| err(py, e))?;
        image_to_py(py, img)
    }

    /// Renders any camera (a full `CameraConfig`, dataclass or dict) at the current state.
    fn render_camera<'py>(&self, py: Python<'py>, config: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let inner = &self.inner;
        render_with(py, "camera", config, |cam: &CameraConfig, img| inner.render_camera(cam, img))
    }

    /// Renders a BEV (a full `BevConfig`, dataclass or dict) at the current state.
    fn render_bev<'py>(&self, py: Python<'py>, config: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let inner = &self.inner;
        render_with(py, "bev", config, |bev: &BevConfig, img| inner.render_bev(bev, img))
    }

    /// What the renderers draw of the current state, to render later (`Frame`).
    fn frame_snapshot(&self, py: Python<'_>) -> PyResult<PyFrame> {
        let inner = &self.inner;
        let snap = py.detach(|| inner.frame_snapshot()).map_err(|e| err(py, e))?;
        Ok(PyFrame { inner: snap })
    }

    /// The six surround cameras (nuScenes-like rig): `{CAM_FRONT: array, ...}`.
    fn render_surround<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (name, cam) in CameraConfig::surround_rig() {
            let mut img = Image::default();
            let inner = &self.inner;
            py.detach(|| inner.render_camera(&cam, &mut img)).map_err(|e| err(py, e))?;
            d.set_item(name, image_to_py(py, img)?)?;
        }
        Ok(d)
    }

    /// Actors visible to a camera: id, bbox_px, center_px, distance_m, visible_fraction, pixel_count,
    /// visible_bbox_px, colour_name, visible_rgb.
    fn project_actors<'py>(
        &self,
        py: Python<'py>,
        config: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyList>> {
        let cam: CameraConfig = from_py("camera", config).map_err(|e| err(py, e))?;
        cam.validate().map_err(|e| err(py, e))?;
        let inner = &self.inner;
        let found = py.detach(|| inner.project_actors(&cam)).map_err(|e| err(py, e))?;
        projected_to_py(py, found)
    }

    /// `(render_camera(cfg), project_actors(cfg))` from one raster pass (same values).
    fn render_and_project<'py>(
        &self,
        py: Python<'py>,
        config: &Bound<'py, PyAny>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyList>)> {
        let cam: CameraConfig = from_py("camera", config).map_err(|e| err(py, e))?;
        cam.validate().map_err(|e| err(py, e))?;
        let mut img = Image::default();
        let inner = &self.inner;
        let found = py.detach(|| inner.render_and_project(&cam, &mut img)).map_err(|e| err(py, e))?;
        Ok((image_to_py(py, img)?, projected_to_py(py, found)?))
    }

    /// The scene score record so far (final once terminated), as a dict.
    fn score<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let rec = self.inner.score_record().map_err(|e| err(py, e))?;
        to_py(py, &rec)
    }

    /// The run log's lines (header, one per tick, end) as dicts, which `rescore` reads.
    fn episode_log<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let log = self.inner.run_log().map_err(|e| err(py, e))?;
        to_py(py, &log.lines().collect::<Vec<_>>())
    }

    /// Writes the run log to `path` as JSONL (`rescore_file` reads it), atomically: a reader
    /// sees the old file or the whole new one.
    fn write_episode_log(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let text = self.inner.episode_log().map_err(|e| err(py, e))?;
        let tmp = path.with_extension("jsonl.tmp");
        std::fs::write(&tmp, text)
            .and_then(|()| std::fs::rename(&tmp, &path))
            .map_err(|e| err(py, dh_env::Error::io(&path, e)))
    }

    #[getter]
    fn trajectory_hash(&self, py: Python<'_>) -> PyResult<String> {
        self.inner.trajectory_hash().map_err(|e| err(py, e))
    }

    /// Background traffic from the next `reset` on: `"none"`, `"idm"` (the Rust IDM model),
    /// or `"sumo"` with `sumo` = the `SumoSession` to run SUMO on (`envs.traffic.transport`).
    #[pyo3(signature = (mode, sumo=None))]
    fn set_traffic(&mut self, py: Python<'_>, mode: &str, sumo: Option<Py<PyAny>>) -> PyResult<()> {
        let session = match (mode, &sumo) {
            ("sumo", Some(obj)) => {
                obj.bind(py).cast::<PySumoSession>().ok().map(|s| s.borrow().session.clone())
            }
            _ => None,
        };
        let model: Option<Box<dyn dh_env::world::TrafficModel>> = match (mode, sumo, session) {
            ("none", None, _) => None,
            ("idm", None, _) => Some(Box::new(
                dh_env::world::idm::IdmTraffic::new(self.inner.scenario()).map_err(|e| err(py, e))?,
            )),
            ("sumo", Some(_), Some(session)) => {
                Some(Box::new(dh_env::world::sumo::SumoCoSim::new(session, self.inner.scenario())))
            }
            (m, s, _) => {
                let why = match m {
                    "sumo" => "mode 'sumo' needs a SumoSession",
                    "none" | "idm" => "only mode 'sumo' takes a SUMO object",
                    _ => "expected 'sumo', 'idm' or 'none'",
                };
                let value = if s.is_some() { format!("{m} (with a SUMO object)") } else { m.to_string() };
                return Err(err(py, dh_env::Error::config("traffic", value, why)));
            }
        };
        self.inner.set_traffic(model);
        Ok(())
    }

    /// The scenario's `[traffic]` mode ("none" when it has no table).
    #[getter]
    fn scenario_traffic_mode(&self) -> &'static str {
        self.inner.scenario().traffic.mode.as_str()
    }

    /// The traffic model in use ("sumo", "idm") or None.
    #[getter]
    fn traffic(&self) -> Option<String> {
        self.inner.traffic_name().map(str::to_owned)
    }

    /// The SUMO route file the co-simulation would load for an episode seed (the demand varied
    /// by `variation`, default `seed`).
    #[pyo3(signature = (seed, variation = None))]
    fn traffic_routes(&self, seed: u64, variation: Option<u64>) -> String {
        let s = self.inner.scenario();
        s.traffic.varied(variation.unwrap_or(seed)).sumo_routes_xml(
            &s.map,
            seed,
            &s.ego,
            &dh_env::scenario::traffic::mirror_specs(&s.actors),
        )
    }

    /// Active actors as rows `[id, x, y, yaw, speed_mps, length_m, width_m, is_traffic, signals]`.
    fn actors_array<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
        let world = self.inner.world().map_err(|e| err(py, e))?;
        let rows: Vec<Vec<f64>> = world
            .actors()
            .iter()
            .map(|a| {
                vec![
                    f64::from(a.id),
                    a.pose.pos.x,
                    a.pose.pos.y,
                    a.pose.yaw,
                    a.speed_mps,
                    a.length_m,
                    a.width_m,
                    if world.is_traffic_actor(a.id) { 1.0 } else { 0.0 },
                    f64::from(world.actor_signals(a.id)),
                ]
            })
            .collect();
        let flat: Vec<f64> = rows.concat();
        let arr = numpy::ndarray::Array2::from_shape_vec((rows.len(), 9), flat)
            .map_err(|e| err(py, dh_env::Error::Simulation(e.to_string())))?;
        Ok(arr.into_pyarray(py))
    }

    /// Active actors (ego excluded, sorted by id) with what `actors_array` leaves out: one dict
    /// each of id, kind, x, y, yaw, speed_mps, length_m, width_m, height_m, color (sRGB),
    /// braking, blinkers, beacon (emergency lights flashing), motion
    /// (`static`/`scripted`/`external`/`traffic`).
    fn actor_views<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let world = self.inner.world().map_err(|e| err(py, e))?;
        let out = PyList::empty(py);
        for a in world.actors() {
            let d = PyDict::new(py);
            let kind = serde_json::to_value(a.kind)
                .map_err(|e| err(py, dh_env::Error::Simulation(e.to_string())))?;
            d.set_item("id", a.id)?;
            d.set_item("kind", kind.as_str().unwrap_or_default())?;
            d.set_item("x", a.pose.pos.x)?;
            d.set_item("y", a.pose.pos.y)?;
            d.set_item("yaw", a.pose.yaw)?;
            d.set_item("speed_mps", a.speed_mps)?;
            d.set_item("length_m", a.length_m)?;
            d.set_item("width_m", a.width_m)?;
            d.set_item("height_m", a.height_m)?;
            d.set_item("color", a.color.map(u32::from).to_vec())?;
            d.set_item("braking", a.braking)?;
            d.set_item("blinkers", a.blinkers)?;
            d.set_item("beacon", a.beacon)?;
            d.set_item("motion", world.actor_motion(a.id).unwrap_or("unknown"))?;
            out.append(d)?;
        }
        Ok(out)
    }

    /// Simulated time of the running episode, seconds.
    #[getter]
    fn time_s(&self, py: Python<'_>) -> PyResult<f64> {
        Ok(self.inner.world().map_err(|e| err(py, e))?.time_s())
    }

    /// The ego as `[x, y, yaw, speed_mps, length_m, width_m]`.
    fn ego_array<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let world = self.inner.world().map_err(|e| err(py, e))?;
        let e = world.ego();
        Ok(PyArray1::from_vec(
            py,
            vec![e.pose.pos.x, e.pose.pos.y, e.pose.yaw, e.speed_mps, e.length_m, e.width_m],
        ))
    }

    /// Light states of every signal head: `[(tl_id, lane_id, colour)]`.
    fn light_states(&self, py: Python<'_>) -> PyResult<Vec<(String, String, String)>> {
        let world = self.inner.world().map_err(|e| err(py, e))?;
        Ok(world
            .lights()
            .iter()
            .map(|l| (l.tl_id.clone(), l.lane_id.clone(), format!("{:?}", l.color).to_lowercase()))
            .collect())
    }
}

fn projected_to_py<'py>(
    py: Python<'py>,
    found: Vec<dh_env::render::ProjectedActor>,
) -> PyResult<Bound<'py, PyList>> {
    let out = PyList::empty(py);

    for a in found {
        let d = PyDict::new(py);
        d.set_item("id", a.id)?;
        d.set_item("bbox_px", a.bbox_px.to_vec())?;
        d.set_item("center_px", a.center_px.to_vec())?;
        d.set_item("distance_m", a.distance_m)?;
        d.set_item("visible_fraction", a.visible_fraction)?;
        d.set_item("pixel_count", a.pixel_count)?;
        d.set_item("visible_bbox_px", a.visible_bbox_px.to_vec())?;
        d.set_item("colour_name", a.colour_name)?;
        d.set_item("visible_rgb", a.visible_rgb.map(u32::from).to_vec())?;
        out.append(d)?;
    }
    Ok(out)
}

/// Animated GIF of RGB frames (H×W×3 uint8), e.g. an episode's front camera.
/// One moment of an episode as the renderers see it (`Sim.frame_snapshot`): renders equal to
/// the `Sim`'s at that moment, whatever the world did since.
#[pyclass(name = "Frame", module = "drivehierarchy._core", frozen)]
pub struct PyFrame {
    inner: FrameSnapshot,
}

#[pymethods]
impl PyFrame {
    fn render_camera<'py>(&self, py: Python<'py>, config: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let inner = &self.inner;
        render_with(py, "camera", config, |cam: &CameraConfig, img| inner.render_camera(cam, img))
    }

    fn render_bev<'py>(&self, py: Python<'py>, config: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let inner = &self.inner;
        render_with(py, "bev", config, |bev: &BevConfig, img| inner.render_bev(bev, img))
    }
}

#[pyclass(name = "GifWriter", module = "drivehierarchy._core")]
pub struct PyGifWriter {
    inner: Option<GifWriter>,
}

#[pymethods]
impl PyGifWriter {
    #[new]
    #[pyo3(signature = (path, fps=4))]
    fn new(py: Python<'_>, path: PathBuf, fps: u32) -> PyResult<Self> {
        Ok(PyGifWriter { inner: Some(GifWriter::create(path, fps).map_err(|e| err(py, e))?) })
    }

    fn push(&mut self, py: Python<'_>, frame: numpy::PyReadonlyArray3<'_, u8>) -> PyResult<()> {
        let view = frame.as_array();
        let shape = view.shape();
        if shape[2] != 3 {
            return Err(err(
                py,
                dh_env::Error::config("frame", format!("{shape:?}"), "expected H×W×3 uint8"),
            ));
        }
        let img =
            Image { width: shape[1] as u32, height: shape[0] as u32, data: view.iter().copied().collect() };
        let w = self
            .inner
            .as_mut()
            .ok_or_else(|| err(py, dh_env::Error::Render("the GIF writer is closed".into())))?;
        py.detach(|| w.push(&img)).map_err(|e| err(py, e))
    }

    /// Finishes the file (also done when the writer is garbage-collected).
    fn close(&mut self) {
        self.inner = None;
    }

    #[getter]
    fn frames(&self) -> usize {
        self.inner.as_ref().map_or(0, |w| w.frames())
    }
}

/// Parses and validates a renderer config (`field` names it in errors), renders with the GIL
/// released and returns the frame as a numpy array: `Sim`'s and `Frame`'s render methods.
fn render_with<'py, C, F>(
    py: Python<'py>,
    field: &str,
    config: &Bound<'py, PyAny>,
    render: F,
) -> PyResult<Bound<'py, PyAny>>
where
    C: serde::de::DeserializeOwned + RenderConfig + Sync,
    F: FnOnce(&C, &mut Image) -> dh_env::Result<()> + Send,
{
    let cfg: C = from_py(field, config).map_err(|e| err(py, e))?;
    cfg.check().map_err(|e| err(py, e))?;
    let mut img = Image::default();
    py.detach(|| render(&cfg, &mut img)).map_err(|e| err(py, e))?;
    image_to_py(py, img)
}

/// The validation both renderer configs have.
trait RenderConfig {
    fn check(&self) -> dh_env::Result<()>;
}

impl RenderConfig for CameraConfig {
    fn check(&self) -> dh_env::Result<()> {
        self.validate()
    }
}

impl RenderConfig for BevConfig {
    fn check(&self) -> dh_env::Result<()> {
        self.validate()
    }
}

fn image_to_py(py: Python<'_>, img: Image) -> PyResult<Bound<'_, PyAny>> {
    let (w, h) = (img.width as usize, img.height as usize);
    let arr = Array3::from_shape_vec((h, w, 3), img.data)
        .map_err(|e| err(py, dh_env::Error::Render(format!("frame buffer: {e}"))))?;
    Ok(arr.into_pyarray(py).into_any())
}

fn obs_to_py(py: Python<'_>, obs: Observation) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    if let Some(img) = obs.front {
        d.set_item("front", image_to_py(py, img)?)?;
    }
    if let Some(img) = obs.bev {
        d.set_item("bev", image_to_py(py, img)?)?;
    }
    d.set_item("prompt", obs.prompt)?;
    d.set_item("state", PyArray1::from_vec(py, obs.state))?;
    Ok(d)
}

fn info_to_py<'py>(py: Python<'py>, info: &StepInfo) -> PyResult<Bound<'py, PyAny>> {
    to_py(py, info)
}

/// Recomputes a scene score from a run log's lines (`Sim.episode_log()`) without simulating;
/// returns the score record.
#[pyfunction]
pub fn rescore<'py>(py: Python<'py>, log: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let lines: Vec<dh_env::score::LogLine> = from_py("episode_log", log).map_err(|e| err(py, e))?;
    let numbered = lines.into_iter().enumerate().map(|(i, l)| (format!("episode_log[{i}]"), l));
    let run = dh_env::score::RunLog::from_lines(numbered, "episode_log").map_err(|e| err(py, e))?;
    let rec = run.rescore().map_err(|e| err(py, e))?;
    to_py(py, &rec)
}

/// Recomputes a scene score from a run-log file (`episode_log.jsonl`); errors name the file
/// and line.
#[pyfunction]
pub fn rescore_file(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyAny>> {
    let rec = py
        .detach(|| dh_env::score::RunLog::read_jsonl(&path).and_then(|run| run.rescore()))
        .map_err(|e| err(py, e))?;
    to_py(py, &rec)
}

/// Validates a scenario file; returns its summary.
#[pyfunction]
#[pyo3(signature = (path, sumo_home=None))]
pub fn validate_scenario<'py>(
    py: Python<'py>,
    path: &str,
    sumo_home: Option<PathBuf>,
) -> PyResult<Bound<'py, PyAny>> {
    let opts = LoadOptions { sumo_home, cache: Some(map_cache()) };
    let s = py.detach(|| dh_env::scenario::validate_with(path, &opts)).map_err(|e| err(py, e))?;
    to_py(py, &s)
}

/// The JSON Schema of scenario files (generated from the Rust types).
#[pyfunction]
pub fn scenario_json_schema(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    to_py(py, &dh_env::scenario::scenario_json_schema())
}

/// The core's default settings (what `R4Config` mirrors).
#[pyfunction]
pub fn default_sim_config(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    to_py(py, &SimConfig::default())
}

/// Registers the folder of the package's shipped maps for `map = "builtin:NAME"` (called once
/// by `drivehierarchy/__init__.py`); `False` when a folder was registered already.
#[pyfunction]
pub fn set_builtin_maps_dir(path: PathBuf) -> bool {
    dh_env::scenario::set_builtin_maps_dir(path)
}

/// The edges and lanes of a road network: `map` is what a scenario's `map` key takes (a
/// path, `sumo:PATH` or `builtin:NAME`).
#[pyfunction]
#[pyo3(signature = (map, sumo_home=None))]
pub fn map_summary<'py>(
    py: Python<'py>,
    map: &str,
    sumo_home: Option<PathBuf>,
) -> PyResult<Bound<'py, PyAny>> {
    use dh_env::map::{EdgeFunction, Network};
    let here = std::path::Path::new("<command line>");
    let path = dh_env::scenario::resolve_map_path(here, map, sumo_home.as_deref()).map_err(|e| err(py, e))?;
    let net = py.detach(|| Network::from_file(&path)).map_err(|e| err(py, e))?;
    let junction = |j: Option<dh_env::map::JunctionIdx>| j.map(|j| net.junctions[j].id.clone());
    let edges: Vec<serde_json::Value> = net
        .edges
        .iter()
        .map(|e| {
            let lanes: Vec<serde_json::Value> = e
                .lanes
                .iter()
                .map(|&l| {
                    let lane = &net.lanes[l];
                    serde_json::json!({
                        "id": lane.id, "index": lane.index, "length_m": lane.length_m,
                        "speed_mps": lane.speed_mps, "width_m": lane.width_m,
                        "allow": lane.allow.sumo_names(),
                    })
                })
                .collect();
            let function = match e.function {
                EdgeFunction::Normal => "normal",
                EdgeFunction::Internal => "internal",
                EdgeFunction::Crossing => "crossing",
                EdgeFunction::WalkingArea => "walkingarea",
                EdgeFunction::Connector => "connector",
            };
            serde_json::json!({
                "id": e.id, "function": function, "from": junction(e.from), "to": junction(e.to),
                "name": e.name, "priority": e.priority, "lanes": lanes,
            })
        })
        .collect();
    let b = net.bounds();
    let out = serde_json::json!({
        "path": path.display().to_string(),
        "bounds": [b.min.x, b.min.y, b.max.x, b.max.y],
        "junctions": net.junctions.len(),
        "traffic_lights": net.tl_ids(),
        "vclasses": dh_env::map::VClassSet::ALL.sumo_names(),
        "edges": edges,
    });
    to_py(py, &out)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySim>()?;
    m.add_class::<PyFrame>()?;
    m.add_class::<PyGifWriter>()?;
    m.add_class::<PySumoSession>()?;
    m.add("LIBSUMO_SUMO_SHIM", dh_env::world::sumo::shim::SHIM_FILE)?;
    m.add("TRACI_SUMO_SHIM", dh_env::world::sumo::shim::TRACI_SHIM_FILE)?;
    m.add_function(wrap_pyfunction!(rescore, m)?)?;
    m.add_function(wrap_pyfunction!(rescore_file, m)?)?;
    m.add_function(wrap_pyfunction!(validate_scenario, m)?)?;
    m.add_function(wrap_pyfunction!(scenario_json_schema, m)?)?;
    m.add_function(wrap_pyfunction!(default_sim_config, m)?)?;
    m.add_function(wrap_pyfunction!(set_builtin_maps_dir, m)?)?;
    m.add_function(wrap_pyfunction!(map_summary, m)?)?;
    m.add("STATE_FIELDS", dh_env::sim::STATE_FIELDS.to_vec())?;
    Ok(())
}
