//! The native SUMO backend: libsumo's C++ API driven from Rust, so a co-simulated tick never
//! enters Python.
//!
//! SUMO lives in `libsumocpp.so` (shipped by the `eclipse-sumo` wheel) behind a small C shim
//! (`python/sumo_shim/dh_sumo_shim.cpp`, built by `python/build.rs` next to `_core`). Both are
//! loaded at runtime, only when a SUMO-mode env asks for the native backend: importing
//! `drivehierarchy` never pulls SUMO's libraries in. libsumocpp is loaded `RTLD_LOCAL` (the shim
//! finds it by its soname), so its symbols stay out of the global scope and cannot bind to or
//! from the `libsumo` Python module's own copy of SUMO.
//!
//! Semantics are the Python backend's (`envs/traffic/sumo.py`): same command line, warm-up,
//! light sync, movers, departure keys and vehicle order, so both backends yield the same traffic.

use crate::traffic::{Mover, Static, SumoSync};
use dh_env::scenario::ResolvedScenario;
use dh_env::world::{TrafficFrame, TrafficInput, TrafficModel};
use dh_env::{Error, Result};
use libloading::os::unix::{Library, RTLD_LOCAL, RTLD_NOW};
use pyo3::prelude::*;
use std::collections::{BTreeSet, HashMap};
use std::ffi::{c_char, c_int, CStr, CString};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

/// The shim's file name inside the package directory.
pub const SHIM_FILE: &str = "_dh_sumo_shim.so";
const STEP_LENGTH_S: f64 = 0.05;
const EGO_ID: &str = "dh_ego";
const EGO_ROUTE: &str = "dh_ego_route";

#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
struct RawVehicle {
    key: u64,
    x: f64,
    y: f64,
    angle: f64,
    speed: f64,
    signals: i32,
    _pad: i32,
}

#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
struct RawNew {
    key: u64,
    length: f64,
    width: f64,
    height: f64,
    color: [i32; 4],
    vclass: [c_char; 32],
}

/// The shim's entry points (see the C++ file for what each does).
struct Api {
    error: unsafe extern "C" fn() -> *const c_char,
    start: unsafe extern "C" fn(*const *const c_char, i32) -> c_int,
    close: unsafe extern "C" fn() -> c_int,
    time: unsafe extern "C" fn() -> f64,
    add: unsafe extern "C" fn(*const c_char, *const c_char, *const c_char) -> c_int,
    remove: unsafe extern "C" fn(*const c_char) -> c_int,
    move_to: unsafe extern "C" fn(*const c_char, f64, f64, f64, i32) -> c_int,
    step: unsafe extern "C" fn() -> c_int,
    vehicle_count: unsafe extern "C" fn() -> usize,
    read: unsafe extern "C" fn(*mut RawVehicle, usize, *mut usize) -> c_int,
    new_count: unsafe extern "C" fn() -> usize,
    take_new: unsafe extern "C" fn(*mut RawNew, usize) -> usize,
    tl_count: unsafe extern "C" fn() -> usize,
    tl_id: unsafe extern "C" fn(usize) -> *const c_char,
    read_lights: unsafe extern "C" fn() -> c_int,
    tl_state: unsafe extern "C" fn(usize) -> *const c_char,
    set_phase: unsafe extern "C" fn(*const c_char, i32, f64) -> c_int,
    set_program: unsafe extern "C" fn(*const c_char, usize, *const *const c_char, *const f64) -> c_int,
    // Never unloaded: SUMO's globals outlive any one simulation.
    _libs: [Library; 2],
}

impl std::fmt::Debug for Api {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Api(libsumocpp + shim)")
    }
}

/// The loaded libraries (leaked: never unloaded). Only a successful load is kept, so a failed
/// one (a missing file) can be retried.
static API: Mutex<Option<&'static Api>> = Mutex::new(None);
/// libsumo holds one simulation per process.
static BUSY: AtomicBool = AtomicBool::new(false);
static TMP_SEQ: AtomicU64 = AtomicU64::new(0);

fn load(shim: &Path, libsumocpp: &Path) -> std::result::Result<Api, String> {
    // SAFETY: loading runs the libraries' initialisers; libsumocpp and the shim are SUMO's own
    // and ours, built against the same (pinned) SUMO release.
    #[allow(unsafe_code)]
    unsafe {
        let sumo = Library::open(Some(libsumocpp), RTLD_NOW | RTLD_LOCAL)
            .map_err(|e| format!("cannot load {}: {e}", libsumocpp.display()))?;
        let lib = Library::open(Some(shim), RTLD_NOW | RTLD_LOCAL)
            .map_err(|e| format!("cannot load {}: {e}", shim.display()))?;
        macro_rules! sym {
            ($name:literal) => {
                *lib.get(concat!($name, "\0").as_bytes()).map_err(|e| format!("{}: {e}", shim.display()))?
            };
        }
        Ok(Api {
            error: sym!("dh_sumo_error"),
            start: sym!("dh_sumo_start"),
            close: sym!("dh_sumo_close"),
            time: sym!("dh_sumo_time"),
            add: sym!("dh_sumo_add"),
            remove: sym!("dh_sumo_remove"),
            move_to: sym!("dh_sumo_move"),
            step: sym!("dh_sumo_step"),
            vehicle_count: sym!("dh_sumo_vehicle_count"),
            read: sym!("dh_sumo_read"),
            new_count: sym!("dh_sumo_new_count"),
            take_new: sym!("dh_sumo_take_new"),
            tl_count: sym!("dh_sumo_tl_count"),
            tl_id: sym!("dh_sumo_tl_id"),
            read_lights: sym!("dh_sumo_read_lights"),
            tl_state: sym!("dh_sumo_tl_state"),
            set_phase: sym!("dh_sumo_set_phase"),
            set_program: sym!("dh_sumo_set_program"),
            _libs: [sumo, lib],
        })
    }
}

/// Loads libsumocpp and the shim once per process (later calls reuse the first success; the
/// files must still exist).
fn api(shim: &Path, libsumocpp: &Path) -> std::result::Result<&'static Api, String> {
    if !shim.is_file() {
        return Err(format!("the native SUMO shim {} was not built", shim.display()));
    }
    if !libsumocpp.is_file() {
        return Err(format!("libsumocpp {} does not exist", libsumocpp.display()));
    }
    let mut slot = API.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(api) = *slot {
        return Ok(api);
    }
    let api: &'static Api = Box::leak(Box::new(load(shim, libsumocpp)?));
    *slot = Some(api);
    Ok(api)
}

/// Whether a native SUMO simulation runs in this process.
pub fn busy() -> bool {
    BUSY.load(Ordering::SeqCst)
}

fn cstr(s: &str) -> Result<CString> {
    CString::new(s).map_err(|_| Error::Simulation(format!("SUMO argument with a NUL byte: {s:?}")))
}

// Every unsafe block below calls a shim entry point with valid NUL-terminated strings and buffers
// of the stated length; the shim catches every C++ exception at its boundary.
#[allow(unsafe_code)]
impl Api {
    fn check(&self, rc: c_int, what: &str) -> Result<()> {
        if rc == 0 {
            return Ok(());
        }
        Err(Error::Simulation(format!("SUMO co-simulation: {what}: {}", self.last_error())))
    }

    fn last_error(&self) -> String {
        unsafe { CStr::from_ptr((self.error)()) }.to_string_lossy().into_owned()
    }

    fn start(&self, args: &[String]) -> std::result::Result<(), String> {
        let owned: Vec<CString> = args
            .iter()
            .map(|a| CString::new(a.as_str()).map_err(|e| e.to_string()))
            .collect::<std::result::Result<_, _>>()?;
        let ptrs: Vec<*const c_char> = owned.iter().map(|c| c.as_ptr()).collect();
        if unsafe { (self.start)(ptrs.as_ptr(), ptrs.len() as i32) } == 0 {
            Ok(())
        } else {
            Err(self.last_error())
        }
    }

    fn close(&self) {
        unsafe { (self.close)() };
    }

    fn add(&self, vid: &str, route: &str, vtype: &str) -> Result<()> {
        let (v, r, t) = (cstr(vid)?, cstr(route)?, cstr(vtype)?);
        self.check(unsafe { (self.add)(v.as_ptr(), r.as_ptr(), t.as_ptr()) }, &format!("add {vid}"))
    }

    fn remove(&self, vid: &str) -> Result<()> {
        let v = cstr(vid)?;
        self.check(unsafe { (self.remove)(v.as_ptr()) }, &format!("remove {vid}"))
    }

    /// `Ok(false)` when SUMO cannot map the vehicle there (a TraCIException).
    fn move_to(&self, vid: &CStr, m: &Mover) -> Result<bool> {
        let rc = unsafe { (self.move_to)(vid.as_ptr(), m.1, m.2, m.3, i32::from(m.5)) };
        if rc == 1 {
            return Ok(false);
        }
        self.check(rc, &format!("moveToXY {}", vid.to_string_lossy()))?;
        Ok(true)
    }

    fn step(&self) -> Result<()> {
        self.check(unsafe { (self.step)() }, "simulationStep")
    }

    fn time(&self) -> f64 {
        unsafe { (self.time)() }
    }

    fn read(&self, buf: &mut Vec<RawVehicle>) -> Result<()> {
        let cap = unsafe { (self.vehicle_count)() };
        buf.resize(cap, RawVehicle::default());
        let mut n = 0usize;
        self.check(unsafe { (self.read)(buf.as_mut_ptr(), cap, &mut n) }, "reading the vehicles")?;
        buf.truncate(n);
        Ok(())
    }

    fn take_new(&self, buf: &mut Vec<RawNew>) {
        let cap = unsafe { (self.new_count)() };
        buf.resize(cap, RawNew::default());
        let n = unsafe { (self.take_new)(buf.as_mut_ptr(), cap) };
        buf.truncate(n);
    }

    fn light_ids(&self) -> Vec<String> {
        let n = unsafe { (self.tl_count)() };
        (0..n).map(|i| unsafe { CStr::from_ptr((self.tl_id)(i)) }.to_string_lossy().into_owned()).collect()
    }

    fn read_lights(&self) -> Result<()> {
        self.check(unsafe { (self.read_lights)() }, "reading the lights")
    }

    fn light_state(&self, i: usize) -> &CStr {
        unsafe { CStr::from_ptr((self.tl_state)(i)) }
    }

    fn set_phase(&self, tl: &str, phase: usize, remaining_s: f64) -> Result<()> {
        let t = cstr(tl)?;
        let rc = unsafe { (self.set_phase)(t.as_ptr(), phase as i32, remaining_s) };
        self.check(rc, &format!("setting the phase of light {tl}"))
    }

    /// Installs a replacement program (`[[lights]] phases`) and switches the light to it.
    fn set_program(&self, tl: &str, phases: &[(String, f64)]) -> Result<()> {
        let t = cstr(tl)?;
        let states = phases.iter().map(|(s, _)| cstr(s)).collect::<Result<Vec<_>>>()?;
        let ptrs: Vec<*const c_char> = states.iter().map(|s| s.as_ptr()).collect();
        let durations: Vec<f64> = phases.iter().map(|p| p.1).collect();
        let rc = unsafe { (self.set_program)(t.as_ptr(), ptrs.len(), ptrs.as_ptr(), durations.as_ptr()) };
        self.check(rc, &format!("setting the program of light {tl}"))
    }
}

/// The process's native SUMO simulation (shared by `NativeSumo` and the world's bridge).
#[derive(Debug)]
pub struct NativeSession {
    api: &'static Api,
    sumo_binary: PathBuf,
    extra_args: Vec<String>,
    running: bool,
    tmp: Option<PathBuf>,
    /// Scenario actor ids with a SUMO double.
    mirrors: BTreeSet<u32>,
    mirror_ids: HashMap<u32, CString>,
    /// Ego (0) / actor ids taken out of SUMO because moveToXY could not map them.
    out: BTreeSet<u32>,
    ego_id: CString,
    pub steps: u64,
}

impl NativeSession {
    /// Loads the libraries (once per process); fails with the reason when they cannot load.
    pub fn new(
        shim: &Path,
        libsumocpp: &Path,
        sumo_binary: PathBuf,
        extra_args: Vec<String>,
    ) -> std::result::Result<NativeSession, String> {
        Ok(NativeSession {
            api: api(shim, libsumocpp)?,
            sumo_binary,
            extra_args,
            running: false,
            tmp: None,
            mirrors: BTreeSet::new(),
            mirror_ids: HashMap::new(),
            out: BTreeSet::new(),
            ego_id: CString::new(EGO_ID).expect("no NUL"),
            steps: 0,
        })
    }

    pub fn running(&self) -> bool {
        self.running
    }

    pub fn sumo_time_s(&self) -> f64 {
        if self.running {
            self.api.time()
        } else {
            0.0
        }
    }

    /// Stops SUMO (idempotent).
    pub fn close(&mut self) {
        if self.running {
            self.running = false;
            self.api.close();
            BUSY.store(false, Ordering::SeqCst);
        }
        if let Some(tmp) = self.tmp.take() {
            let _ = std::fs::remove_dir_all(tmp);
        }
    }

    fn start(&mut self, net: &Path, routes_xml: &str, seed: u64) -> Result<()> {
        self.close();
        if BUSY.swap(true, Ordering::SeqCst) {
            return Err(Error::Simulation(
                "libsumo runs one simulation per process and another SUMO env in this process is \
                 running; close it first, or vectorise SUMO envs over processes \
                 (gymnasium.vector.AsyncVectorEnv)"
                    .into(),
            ));
        }
        let tmp = std::env::temp_dir().join(format!(
            "dh_sumo_{}_{}",
            std::process::id(),
            TMP_SEQ.fetch_add(1, Ordering::SeqCst)
        ));
        let io = |e: std::io::Error| Error::Simulation(format!("SUMO co-simulation: {}: {e}", tmp.display()));
        let prepared = std::fs::create_dir_all(&tmp)
            .and_then(|()| std::fs::write(tmp.join("traffic.rou.xml"), routes_xml))
            .map_err(io);
        self.tmp = Some(tmp.clone());
        if let Err(e) = prepared {
            BUSY.store(false, Ordering::SeqCst);
            self.close();
            return Err(e);
        }
        let routes = tmp.join("traffic.rou.xml");
        let errlog = tmp.join("sumo_errors.log");
        let path = |p: &Path| p.to_string_lossy().into_owned();
        let mut cmd: Vec<String> = vec![path(&self.sumo_binary)];
        for (k, v) in [
            ("--net-file", path(net)),
            ("--route-files", path(&routes)),
            ("--step-length", STEP_LENGTH_S.to_string()),
            ("--seed", (seed % (1 << 31)).to_string()),
            ("--begin", "0".into()),
            ("--collision.action", "none".into()),
            ("--no-step-log", "true".into()),
            ("--no-warnings", "true".into()),
            ("--error-log", path(&errlog)),
        ] {
            cmd.push(k.into());
            cmd.push(v);
        }
        cmd.extend(self.extra_args.iter().cloned());
        if let Err(exc) = self.api.start(&cmd) {
            // libsumo may hold a half-loaded net: close it so the next start is clean.
            self.api.close();
            let said = std::fs::read_to_string(&errlog).unwrap_or_default();
            let said = said.trim();
            BUSY.store(false, Ordering::SeqCst);
            self.close();
            let mut msg = format!("SUMO failed to start on {}: {exc}", net.display());
            if !said.is_empty() {
                msg.push_str("\nSUMO said:\n");
                msg.push_str(said);
            }
            return Err(Error::Simulation(msg));
        }
        self.running = true;
        self.mirrors.clear();
        self.out.clear();
        self.steps = 0;
        Ok(())
    }

    /// Places the ego and the mirrored actors (as `SumoTraffic._move`).
    fn move_all(&mut self, movers: &[Mover]) -> Result<()> {
        if movers.len().saturating_sub(1) != self.mirrors.len() {
            // A scenario actor left the world: its SUMO double leaves too.
            let present: BTreeSet<u32> = movers.iter().map(|m| m.0).collect();
            let gone: Vec<u32> = self.mirrors.difference(&present).copied().collect();
            for ident in gone {
                if !self.out.remove(&ident) {
                    self.api.remove(&mirror_id(ident))?;
                }
                self.mirrors.remove(&ident);
            }
        }
        for m in movers {
            if m.0 != 0 && !self.mirrors.contains(&m.0) {
                let vid = mirror_id(m.0);
                self.api.add(&vid, EGO_ROUTE, &vid)?;
                self.mirrors.insert(m.0);
            }
            let vid = if m.0 == 0 {
                &self.ego_id
            } else {
                &*self.mirror_ids.entry(m.0).or_insert_with(|| CString::new(mirror_id(m.0)).expect("no NUL"))
            };
            let name = vid.to_str().expect("ASCII id");
            if self.out.contains(&m.0) {
                // Out of SUMO since it could not be mapped: try it again at its new place.
                if self.api.add(name, EGO_ROUTE, if m.0 == 0 { EGO_ID } else { name }).is_err() {
                    continue;
                }
                self.out.remove(&m.0);
            }
            // keepRoute=1 maps onto SUMO's copy of the route, which a keepRoute=2 placement
            // replaced; then the ego is placed anywhere.
            if !self.api.move_to(vid, m)?
                && !(m.5 == 1 && self.api.move_to(vid, &(m.0, m.1, m.2, m.3, m.4, 2))?)
            {
                // SUMO cannot place it (off its network, too far from a lane its class may
                // use): it leaves SUMO until it can be mapped again.
                let _ = self.api.remove(name);
                self.out.insert(m.0);
            }
        }
        Ok(())
    }

    fn step(&mut self, movers: &[Mover]) -> Result<()> {
        if !self.running {
            return Err(Error::Simulation(
                "SUMO is not running (the traffic was closed); call reset()".into(),
            ));
        }
        self.move_all(movers)?;
        self.api.step()?;
        self.steps += 1;
        Ok(())
    }
}

impl Drop for NativeSession {
    fn drop(&mut self) {
        self.close();
    }
}

fn mirror_id(ident: u32) -> String {
    format!("dh_actor_{ident}")
}

/// A shared handle on the session.
pub type SharedSession = Arc<Mutex<NativeSession>>;

fn lock(s: &SharedSession) -> MutexGuard<'_, NativeSession> {
    s.lock().unwrap_or_else(|p| p.into_inner())
}

/// The world side of the native SUMO co-simulation.
#[derive(Debug)]
pub struct NativeSumoBridge {
    session: SharedSession,
    sync: SumoSync,
    vehicles: HashMap<u64, Static>,
    lights: HashMap<String, String>,
    light_ids: Vec<String>,
    raw: Vec<RawVehicle>,
    raw_new: Vec<RawNew>,
}

impl NativeSumoBridge {
    pub fn new(session: SharedSession, scenario: &ResolvedScenario) -> NativeSumoBridge {
        NativeSumoBridge {
            session,
            sync: SumoSync::new(scenario),
            vehicles: HashMap::new(),
            lights: HashMap::new(),
            light_ids: Vec::new(),
            raw: Vec::new(),
            raw_new: Vec::new(),
        }
    }

    /// Turns the shim's state after a step into the world's frame.
    fn read(&mut self, api: &Api, out: &mut TrafficFrame) -> Result<()> {
        api.take_new(&mut self.raw_new);
        for n in &self.raw_new {
            // The shim NUL-terminates `vclass` within its 32 bytes.
            let vclass: Vec<u8> = n.vclass.iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
            let vclass = String::from_utf8_lossy(&vclass);
            let color = n.color.map(i64::from);
            self.vehicles.insert(n.key, Static::new(n.key, n.length, n.width, n.height, &vclass, &color));
        }
        api.read(&mut self.raw)?;
        for v in &self.raw {
            let Some(st) = self.vehicles.get(&v.key) else { continue };
            out.agents.push(st.agent(v.x, v.y, v.angle, v.speed, i64::from(v.signals)));
        }
        api.read_lights()?;
        for (i, tl) in self.light_ids.iter().enumerate() {
            let state = api.light_state(i).to_bytes();
            if self.lights.get(tl).map(String::as_bytes) != Some(state) {
                let state = String::from_utf8_lossy(state).into_owned();
                out.lights.push((tl.clone(), state.clone()));
                self.lights.insert(tl.clone(), state);
            }
        }
        Ok(())
    }
}

impl TrafficModel for NativeSumoBridge {
    fn start(&mut self, input: &TrafficInput<'_>, seed: u64, out: &mut TrafficFrame) -> Result<()> {
        self.vehicles.clear();
        self.lights.clear();
        let routes = self.sync.routes_xml(seed, input.variation_seed);
        self.sync.fill_movers(input);
        let session = self.session.clone();
        let mut s = lock(&session);
        s.start(&self.sync.net, &routes, seed)?;
        let api = s.api;
        self.light_ids = api.light_ids();
        for (tl, phases) in self.sync.replaced_programs() {
            if !self.light_ids.contains(&tl) {
                return Err(Error::Simulation(format!("light override: SUMO has no traffic light {tl:?}")));
            }
            api.set_program(&tl, &phases)?;
        }
        api.add(EGO_ID, EGO_ROUTE, "dh_ego")?;
        // Python's round (the Python backend's): ties to even.
        let warmup = (self.sync.demand.warmup_s / STEP_LENGTH_S).round_ties_even() as u64;
        for _ in 0..warmup {
            s.step(&self.sync.movers)?;
        }
        // Also without a warm-up: `[[lights]]` overrides start where the world's model does.
        let known: BTreeSet<&str> = self.light_ids.iter().map(String::as_str).collect();
        for (tl, phase, remaining) in self.sync.light_sync() {
            if known.contains(tl.as_str()) {
                api.set_phase(&tl, phase, remaining)?;
            }
        }
        self.read(api, out)
    }

    fn tick(&mut self, input: &TrafficInput<'_>, out: &mut TrafficFrame) -> Result<()> {
        self.sync.fill_movers(input);
        let session = self.session.clone();
        let mut s = lock(&session);
        s.step(&self.sync.movers)?;
        let api = s.api;
        self.read(api, out)
    }

    fn drives_lights(&self) -> bool {
        true
    }

    fn name(&self) -> &str {
        "sumo"
    }
}

/// `drivehierarchy._core.NativeSumo`: the process's native SUMO simulation, handed to
/// `Sim.set_traffic("sumo", ...)` (`envs/traffic/native.py` builds it).
#[pyclass(name = "NativeSumo", module = "drivehierarchy._core")]
pub struct PyNativeSumo {
    pub(crate) session: SharedSession,
}

#[pymethods]
impl PyNativeSumo {
    /// Loads libsumocpp and the shim (once per process); `SimulationError` with the reason when
    /// they cannot load.
    #[new]
    #[pyo3(signature = (shim, libsumocpp, sumo_binary, extra_args=Vec::new()))]
    fn new(
        shim: PathBuf,
        libsumocpp: PathBuf,
        sumo_binary: PathBuf,
        extra_args: Vec<String>,
    ) -> PyResult<Self> {
        let session = NativeSession::new(&shim, &libsumocpp, sumo_binary, extra_args).map_err(|e| {
            crate::errors::SimulationError::new_err(format!("native SUMO backend unavailable: {e}"))
        })?;
        Ok(PyNativeSumo { session: Arc::new(Mutex::new(session)) })
    }

    /// Stops SUMO (idempotent); the next `reset` starts a fresh simulation.
    fn close(&self) {
        lock(&self.session).close();
    }

    #[getter]
    fn running(&self) -> bool {
        lock(&self.session).running()
    }

    #[getter]
    fn sumo_time_s(&self) -> f64 {
        lock(&self.session).sumo_time_s()
    }

    #[getter]
    fn steps(&self) -> u64 {
        lock(&self.session).steps
    }

    /// Whether a native SUMO simulation runs in this process.
    #[staticmethod]
    fn busy() -> bool {
        busy()
    }
}
