//! The SUMO co-simulation seam: what both SUMO backends share ([`SumoSync`], [`Static`]) and the
//! Python backend's [`TrafficModel`], whose ticks call the Python object that owns libsumo
//! (`drivehierarchy.envs.traffic.SumoTraffic`). The native backend is `sumo_native.rs`.
//!
//! Per tick: one Python call `tick(movers)` with the ego and the mirrored scenario actors (SUMO
//! front-bumper position, SUMO angle, speed); it moves them in SUMO, steps SUMO once and returns
//! libsumo's subscription results as they come (`vehicle.getAllSubscriptionResults()`, the
//! types of vehicles that departed this step, changed light states). They are turned into the
//! world's [`TrafficFrame`] here, in Rust, so the Python side does no per-vehicle work.

use dh_env::geom::{Pose, Vec2};
use dh_env::map::VClass;
use dh_env::scenario::traffic::{kind_of_vclass, mirror_specs, MirrorSpec, TrafficDemand};
use dh_env::scenario::{LightProgram, ResolvedEgo, ResolvedScenario, PALETTE};
use dh_env::view::ActorKind;
use dh_env::world::{TrafficAgent, TrafficFrame, TrafficInput, TrafficModel};
use dh_env::{Error, Result};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString, PyTuple};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

// libsumo variable ids (`libsumo.constants`).
const VAR_SPEED: i32 = 0x40;
const VAR_POSITION: i32 = 0x42;
const VAR_ANGLE: i32 = 0x43;
const VAR_SIGNALS: i32 = 0x5b;
const TL_RED_YELLOW_GREEN_STATE: i32 = 0x20;
/// The ego counts as on its route within this distance of the route line (the route's edges
/// span a few lanes either side), m.
const EGO_ON_ROUTE_M: f64 = 5.0;

/// A traffic vehicle's attributes that do not change (read once, when it departs).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Static {
    pub key: u64,
    pub kind: ActorKind,
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    pub color: [u8; 3],
}

impl Static {
    /// From SUMO's type attributes; SUMO's default colour (yellow) gets a palette colour.
    pub fn new(key: u64, length_m: f64, width_m: f64, height_m: f64, vclass: &str, color: &[i64]) -> Static {
        let kind = kind_of_vclass(VClass::from_sumo(vclass).unwrap_or(VClass::Passenger));
        let color = if color.len() >= 3 && color != [255, 255, 0, 255] {
            [color[0].clamp(0, 255) as u8, color[1].clamp(0, 255) as u8, color[2].clamp(0, 255) as u8]
        } else {
            PALETTE[key as usize % PALETTE.len()]
        };
        Static { key, kind, length_m, width_m, height_m, color }
    }

    /// The world's agent from SUMO's front-bumper position and SUMO angle (degrees, clockwise
    /// from north).
    pub fn agent(&self, x: f64, y: f64, angle: f64, speed: f64, signals: i64) -> TrafficAgent {
        let yaw = (90.0 - angle).to_radians();
        let fwd = Vec2::new(yaw.cos(), yaw.sin());
        let centre = Vec2::new(x, y) - fwd * (0.5 * self.length_m);
        TrafficAgent {
            key: self.key,
            kind: self.kind,
            length_m: self.length_m,
            width_m: self.width_m,
            height_m: self.height_m,
            color: self.color,
            pose: Pose::new(centre, dh_env::geom::wrap_angle(yaw)),
            speed_mps: speed.max(0.0),
            signals: signals.max(0) as u32,
        }
    }
}

/// One ego/actor placement for SUMO: (id, front x, front y, SUMO angle, speed, moveToXY
/// keepRoute); id 0 is the ego, others are scenario actor ids.
pub(crate) type Mover = (u32, f64, f64, f64, f64, u8);

/// What both SUMO backends share: the scenario's side of the co-simulation (net, demand, ego
/// route, mirrored actors) and the per-tick movers.
#[derive(Debug)]
pub(crate) struct SumoSync {
    pub net: PathBuf,
    pub map: Arc<dh_env::map::Network>,
    pub demand: TrafficDemand,
    pub ego: ResolvedEgo,
    pub mirrors: Vec<MirrorSpec>,
    pub movers: Vec<Mover>,
    /// The scenario's `[[lights]]` overrides.
    pub programs: Vec<LightProgram>,
}

impl SumoSync {
    pub fn new(scenario: &ResolvedScenario) -> SumoSync {
        SumoSync {
            net: scenario.map_path.clone(),
            map: scenario.map.clone(),
            demand: scenario.traffic.clone(),
            ego: scenario.ego.clone(),
            mirrors: mirror_specs(&scenario.actors),
            movers: Vec::new(),
            programs: scenario.lights.clone(),
        }
    }

    /// For each light, the phase and its remaining time that its program (the map's, or the
    /// scenario's `[[lights]]` override) has at episode t = 0: SUMO runs `warmup_s` before
    /// t = 0, so its lights are set to this at the end of the warm-up and then show what the
    /// world's own light model would.
    pub fn light_sync(&self) -> Vec<(String, usize, f64)> {
        let mut out = Vec::new();
        for tl in self.map.tl_ids() {
            let program = match self.programs.iter().find(|p| p.tl_id == tl) {
                Some(p) => p.clone(),
                None => {
                    let Some(logic) = self.map.tl_logic(tl) else { continue };
                    LightProgram {
                        tl_id: tl.to_string(),
                        offset_s: logic.offset_s,
                        phases: logic.phases.clone(),
                        replaced: false,
                    }
                }
            };
            if let Some((i, left)) = program.phase_at(0.0) {
                out.push((tl.to_string(), i, left));
            }
        }
        out
    }

    /// Replacement programs for SUMO (`trafficlight.setProgramLogic`): (light, [(state, s)]).
    pub fn replaced_programs(&self) -> Vec<(String, Vec<(String, f64)>)> {
        self.programs
            .iter()
            .filter(|p| p.replaced)
            .map(|p| (p.tl_id.clone(), p.phases.iter().map(|ph| (ph.state.clone(), ph.duration_s)).collect()))
            .collect()
    }

    /// The SUMO route file of an episode (the demand varied by `variation_seed`).
    pub fn routes_xml(&self, seed: u64, variation_seed: u64) -> String {
        self.demand.varied(variation_seed).sumo_routes_xml(&self.map, seed, &self.ego, &self.mirrors)
    }

    /// Movers for SUMO. The ego near its route is mapped onto the route's edges only
    /// (keepRoute=1, several times cheaper than SUMO's search of the whole net); elsewhere, and
    /// for the scenario's actors, onto any lane (keepRoute=2).
    pub fn fill_movers(&mut self, input: &TrafficInput<'_>) {
        self.movers.clear();
        let sumo = |id: u32, pose: Pose, length: f64, speed: f64, keep: u8| {
            let front = pose.pos + pose.forward() * (0.5 * length);
            (id, front.x, front.y, 90.0 - pose.yaw.to_degrees(), speed, keep)
        };
        let e = input.ego;
        let on_route = self.ego.route.project(e.pose.pos).is_some_and(|p| p.distance <= EGO_ON_ROUTE_M);
        self.movers.push(sumo(0, e.pose, e.length_m, e.speed_mps, if on_route { 1 } else { 2 }));
        for a in input.actors {
            if self.mirrors.binary_search_by_key(&a.id, |m| m.id).is_ok() {
                self.movers.push(sumo(a.id, a.pose, a.length_m, a.speed_mps, 2));
            }
        }
    }
}

/// The world side of the SUMO co-simulation through the Python backend.
#[derive(Debug)]
pub struct SumoBridge {
    obj: Py<PyAny>,
    sync: SumoSync,
    vehicles: HashMap<String, Static>,
    next_key: u64,
    lights: HashMap<String, String>,
}

impl SumoBridge {
    pub fn new(obj: Py<PyAny>, scenario: &ResolvedScenario) -> SumoBridge {
        SumoBridge {
            obj,
            sync: SumoSync::new(scenario),
            vehicles: HashMap::new(),
            next_key: 0,
            lights: HashMap::new(),
        }
    }

    fn read(&mut self, ret: &Bound<'_, PyAny>, out: &mut TrafficFrame) -> PyResult<()> {
        let tuple = ret.cast::<PyTuple>()?;
        let veh = tuple.get_item(0)?;
        let veh = veh.cast::<PyDict>()?;
        let new = tuple.get_item(1)?;
        for item in new.cast::<PyList>()?.iter() {
            let (vid, length_m, width_m, height_m, vclass, color): (String, f64, f64, f64, String, Vec<i64>) =
                item.extract()?;
            let key = self.next_key;
            self.next_key += 1;
            self.vehicles.insert(vid, Static::new(key, length_m, width_m, height_m, &vclass, &color));
        }
        let py = ret.py();
        let (k_pos, k_ang, k_speed, k_sig) = (
            VAR_POSITION.into_pyobject(py)?,
            VAR_ANGLE.into_pyobject(py)?,
            VAR_SPEED.into_pyobject(py)?,
            VAR_SIGNALS.into_pyobject(py)?,
        );
        for (k, v) in veh.iter() {
            let vid = k.cast::<PyString>()?;
            let vid = vid.to_str()?;
            let Some(st) = self.vehicles.get(vid) else { continue };
            let d = v.cast::<PyDict>()?;
            let (x, y): (f64, f64) = field(d, k_pos.as_any(), vid)?.extract()?;
            let angle: f64 = field(d, k_ang.as_any(), vid)?.extract()?;
            let speed: f64 = field(d, k_speed.as_any(), vid)?.extract()?;
            let signals: i64 = field(d, k_sig.as_any(), vid)?.extract()?;
            out.agents.push(st.agent(x, y, angle, speed, signals));
        }
        let lights = tuple.get_item(2)?;
        let k_state = TL_RED_YELLOW_GREEN_STATE.into_pyobject(py)?;
        for (k, v) in lights.cast::<PyDict>()?.iter() {
            let tl = k.cast::<PyString>()?.to_str()?.to_owned();
            let Some(state) = v.cast::<PyDict>()?.get_item(&k_state)? else { continue };
            let state: String = state.extract()?;
            if self.lights.get(&tl) != Some(&state) {
                out.lights.push((tl.clone(), state.clone()));
                self.lights.insert(tl, state);
            }
        }
        Ok(())
    }

    fn call(&mut self, method: &str, extra: Option<(u64, String)>, out: &mut TrafficFrame) -> Result<()> {
        Python::attach(|py| {
            let obj = self.obj.bind(py).clone();
            let movers = PyList::new(py, &self.sync.movers)?;
            let ret = match &extra {
                Some((seed, routes)) => {
                    let net = self.sync.net.to_string_lossy().into_owned();
                    let sync = self.sync.light_sync();
                    let programs = self.sync.replaced_programs();
                    obj.call_method1(
                        method,
                        (net, routes.as_str(), *seed, self.sync.demand.warmup_s, movers, sync, programs),
                    )?
                }
                None => obj.call_method1(method, (movers,))?,
            };
            self.read(&ret, out)
        })
        .map_err(|e: PyErr| Error::Simulation(format!("SUMO co-simulation: {e}")))
    }
}

fn field<'py>(d: &Bound<'py, PyDict>, key: &Bound<'py, PyAny>, vid: &str) -> PyResult<Bound<'py, PyAny>> {
    d.get_item(key)?.ok_or_else(|| {
        pyo3::exceptions::PyKeyError::new_err(format!("SUMO subscription of {vid} lacks {key}"))
    })
}

impl TrafficModel for SumoBridge {
    fn start(&mut self, input: &TrafficInput<'_>, seed: u64, out: &mut TrafficFrame) -> Result<()> {
        self.vehicles.clear();
        self.lights.clear();
        self.next_key = 0;
        let routes = self.sync.routes_xml(seed, input.variation_seed);
        self.sync.fill_movers(input);
        self.call("start", Some((seed, routes)), out)
    }

    fn tick(&mut self, input: &TrafficInput<'_>, out: &mut TrafficFrame) -> Result<()> {
        self.sync.fill_movers(input);
        self.call("tick", None, out)
    }

    fn drives_lights(&self) -> bool {
        true
    }

    fn name(&self) -> &str {
        "sumo"
    }
}
