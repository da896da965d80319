//! The C++ shim transports: libsumo in this process, or TraCI to a `sumo` subprocess.
//!
//! SUMO's client libraries (`libsumocpp.so`, `libtracicpp.so` of the `eclipse-sumo` wheel) sit
//! behind one small C shim (`env/sumo_shim/dh_sumo_shim.cpp`, built twice by `env/build.rs`).
//! Both are loaded at runtime, only when a SUMO co-simulation starts: nothing links SUMO. The
//! library is loaded `RTLD_LOCAL` first (the shim finds it by its soname), so its symbols stay out
//! of the global scope and cannot bind to or from another copy of SUMO in the process (e.g. the
//! `libsumo` Python module's).

use super::transport::{Placed, SumoTransport, TypeInfo, VehicleState};
pub use crate::sumo_home::SumoHome;
use crate::{Error, Result};
use libloading::os::unix::{Library, RTLD_LOCAL, RTLD_NOW};
use std::ffi::{c_char, c_int, CStr, CString};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// The libsumo shim's file name (beside `_core` in the Python package).
pub const SHIM_FILE: &str = "_dh_sumo_shim.so";
/// The libtraci shim's file name.
pub const TRACI_SHIM_FILE: &str = "_dh_sumo_traci.so";
/// Where `env/build.rs` put the shims of this build (`None`: SUMO's headers were not found).
pub const BUILT_SHIM_DIR: Option<&str> = option_env!("DH_SUMO_SHIM_DIR");

/// Which SUMO client library a shim wraps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Flavour {
    /// `libsumocpp.so`: SUMO in this process (one simulation per process).
    Libsumo,
    /// `libtracicpp.so`: SUMO as a subprocess over TraCI (any number per process).
    Traci,
}

impl Flavour {
    pub fn shim_file(self) -> &'static str {
        match self {
            Flavour::Libsumo => SHIM_FILE,
            Flavour::Traci => TRACI_SHIM_FILE,
        }
    }
    fn library(self) -> &'static str {
        match self {
            Flavour::Libsumo => "libsumocpp.so",
            Flavour::Traci => "libtracicpp.so",
        }
    }
}

impl SumoHome {
    /// A client library of this installation (`lib64`, else `lib`).
    pub fn library(&self, flavour: Flavour) -> PathBuf {
        let name = flavour.library();
        let libs = [self.0.join("lib64").join(name), self.0.join("lib").join(name)];
        libs.iter().find(|p| p.is_file()).unwrap_or(&libs[0]).clone()
    }
}

#[repr(C)]
#[derive(Debug, Clone, Copy)]
struct RawType {
    length: f64,
    width: f64,
    height: f64,
    color: [i32; 4],
    vclass: [c_char; 32],
}

/// A shim's entry points (see the C++ file for what each does).
struct Api {
    error: unsafe extern "C" fn() -> *const c_char,
    switch: unsafe extern "C" fn(*const c_char) -> c_int,
    start: unsafe extern "C" fn(*const *const c_char, i32, *const c_char) -> c_int,
    close: unsafe extern "C" fn(*const c_char) -> c_int,
    time: unsafe extern "C" fn(*mut f64) -> c_int,
    add: unsafe extern "C" fn(*const c_char, *const c_char, *const c_char) -> c_int,
    remove: unsafe extern "C" fn(*const c_char) -> c_int,
    move_to: unsafe extern "C" fn(*const c_char, f64, f64, f64, i32) -> c_int,
    step: unsafe extern "C" fn() -> c_int,
    departed_count: unsafe extern "C" fn() -> usize,
    departed_id: unsafe extern "C" fn(usize) -> *const c_char,
    vehicle_type: unsafe extern "C" fn(*const c_char, *mut *const c_char) -> c_int,
    type_info: unsafe extern "C" fn(*const c_char, *mut RawType) -> c_int,
    track: unsafe extern "C" fn(*const c_char, u64) -> c_int,
    tracked_count: unsafe extern "C" fn() -> usize,
    read: unsafe extern "C" fn(*mut VehicleState, usize, *mut usize) -> c_int,
    tl_count: unsafe extern "C" fn() -> usize,
    tl_id: unsafe extern "C" fn(usize) -> *const c_char,
    read_lights: unsafe extern "C" fn() -> c_int,
    tl_state: unsafe extern "C" fn(usize) -> *const c_char,
    set_phase: unsafe extern "C" fn(*const c_char, i32, f64) -> c_int,
    set_program: unsafe extern "C" fn(*const c_char, usize, *const *const c_char, *const f64) -> c_int,
    // Never unloaded: SUMO's globals outlive any one simulation.
    _libs: [Library; 2],
}

/// The loaded shims (leaked: never unloaded), one per flavour. Only a successful load is kept,
/// so a failed one (a missing file) can be retried.
static APIS: Mutex<Vec<(Flavour, &'static Api)>> = Mutex::new(Vec::new());
/// Serialises calls into the shims: their session selection (`dh_sumo_switch`) and libtraci's
/// current connection are process-wide.
static CALLS: Mutex<()> = Mutex::new(());
static LABELS: AtomicU64 = AtomicU64::new(0);

fn load(flavour: Flavour, shim: &Path, lib: &Path) -> std::result::Result<Api, String> {
    // SAFETY: loading runs the libraries' initialisers; the SUMO library and the shim are SUMO's
    // own and ours, built against the same (pinned) SUMO release.
    #[allow(unsafe_code)]
    unsafe {
        let sumo = Library::open(Some(lib), RTLD_NOW | RTLD_LOCAL)
            .map_err(|e| format!("cannot load {}: {e}", lib.display()))?;
        let shim_lib = Library::open(Some(shim), RTLD_NOW | RTLD_LOCAL)
            .map_err(|e| format!("cannot load {}: {e}", shim.display()))?;
        macro_rules! sym {
            ($name:literal) => {
                *shim_lib
                    .get(concat!($name, "\0").as_bytes())
                    .map_err(|e| format!("{} ({flavour:?}): {e}", shim.display()))?
            };
        }
        Ok(Api {
            error: sym!("dh_sumo_error"),
            switch: sym!("dh_sumo_switch"),
            start: sym!("dh_sumo_start"),
            close: sym!("dh_sumo_close"),
            time: sym!("dh_sumo_time"),
            add: sym!("dh_sumo_add"),
            remove: sym!("dh_sumo_remove"),
            move_to: sym!("dh_sumo_move"),
            step: sym!("dh_sumo_step"),
            departed_count: sym!("dh_sumo_departed_count"),
            departed_id: sym!("dh_sumo_departed_id"),
            vehicle_type: sym!("dh_sumo_vehicle_type"),
            type_info: sym!("dh_sumo_type_info"),
            track: sym!("dh_sumo_track"),
            tracked_count: sym!("dh_sumo_tracked_count"),
            read: sym!("dh_sumo_read"),
            tl_count: sym!("dh_sumo_tl_count"),
            tl_id: sym!("dh_sumo_tl_id"),
            read_lights: sym!("dh_sumo_read_lights"),
            tl_state: sym!("dh_sumo_tl_state"),
            set_phase: sym!("dh_sumo_set_phase"),
            set_program: sym!("dh_sumo_set_program"),
            _libs: [sumo, shim_lib],
        })
    }
}

/// Loads a shim and its SUMO library once per process (later calls reuse the first success;
/// the files must still exist).
fn api(flavour: Flavour, shim: &Path, lib: &Path) -> std::result::Result<&'static Api, String> {
    if !shim.is_file() {
        return Err(format!("the SUMO shim {} was not built", shim.display()));
    }
    if !lib.is_file() {
        return Err(format!("{} does not exist", lib.display()));
    }
    let mut apis = APIS.lock().unwrap_or_else(|p| p.into_inner());
    if let Some((_, api)) = apis.iter().find(|(f, _)| *f == flavour) {
        return Ok(api);
    }
    let api: &'static Api = Box::leak(Box::new(load(flavour, shim, lib)?));
    apis.push((flavour, api));
    Ok(api)
}

fn cstr(s: &str) -> Result<CString> {
    CString::new(s).map_err(|_| Error::Simulation(format!("SUMO argument with a NUL byte: {s:?}")))
}

/// A SUMO client through a shim: libsumo (in process) or TraCI (a subprocess).
pub struct ShimTransport {
    api: &'static Api,
    flavour: Flavour,
    label: CString,
    open: bool,
    tl_count: usize,
}

impl std::fmt::Debug for ShimTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ShimTransport({:?}, {:?})", self.flavour, self.label)
    }
}

impl ShimTransport {
    /// Loads the shim `shim` and SUMO's client library `lib` (once per process per flavour);
    /// fails with the reason when they cannot load.
    pub fn new(flavour: Flavour, shim: &Path, lib: &Path) -> std::result::Result<ShimTransport, String> {
        let label = match flavour {
            Flavour::Libsumo => "default".to_string(),
            Flavour::Traci => format!("dh{}", LABELS.fetch_add(1, Ordering::SeqCst)),
        };
        Ok(ShimTransport {
            api: api(flavour, shim, lib)?,
            flavour,
            label: CString::new(label).expect("no NUL"),
            open: false,
            tl_count: 0,
        })
    }

    /// From this build's shims (`BUILT_SHIM_DIR`) and a SUMO installation.
    pub fn built(flavour: Flavour, home: &SumoHome) -> std::result::Result<ShimTransport, String> {
        let dir = BUILT_SHIM_DIR.ok_or("this build found no SUMO headers: the SUMO shims were not built")?;
        ShimTransport::new(flavour, &Path::new(dir).join(flavour.shim_file()), &home.library(flavour))
    }

    fn last_error(&self) -> String {
        // SAFETY: the shim returns a NUL-terminated string it owns until its next call.
        #[allow(unsafe_code)]
        unsafe { CStr::from_ptr((self.api.error)()) }.to_string_lossy().into_owned()
    }

    fn check(&self, rc: c_int, what: &dyn Fn() -> String) -> Result<()> {
        if rc == 0 {
            Ok(())
        } else {
            Err(Error::Simulation(format!("SUMO co-simulation: {}: {}", what(), self.last_error())))
        }
    }

    /// Selects this session in the shim (libtraci: its connection) and holds the shim's lock.
    fn enter(&self) -> Result<std::sync::MutexGuard<'static, ()>> {
        let guard = CALLS.lock().unwrap_or_else(|p| p.into_inner());
        if !self.open {
            return Err(Error::Simulation(
                "SUMO is not running (the traffic was closed); call reset()".into(),
            ));
        }
        // SAFETY (all unsafe blocks below): shim entry points called with valid NUL-terminated
        // strings and buffers of the stated length; the shim catches every C++ exception.
        #[allow(unsafe_code)]
        let rc = unsafe { (self.api.switch)(self.label.as_ptr()) };
        self.check(rc, &|| "selecting the session".into())?;
        Ok(guard)
    }
}

#[allow(unsafe_code)]
impl SumoTransport for ShimTransport {
    fn kind(&self) -> &'static str {
        match self.flavour {
            Flavour::Libsumo => "libsumo",
            Flavour::Traci => "traci",
        }
    }

    fn in_process(&self) -> bool {
        self.flavour == Flavour::Libsumo
    }

    fn start(&mut self, cmd: &[String]) -> std::result::Result<(), String> {
        self.close();
        let owned: Vec<CString> = cmd
            .iter()
            .map(|a| CString::new(a.as_str()).map_err(|e| e.to_string()))
            .collect::<std::result::Result<_, _>>()?;
        let ptrs: Vec<*const c_char> = owned.iter().map(|c| c.as_ptr()).collect();
        let _guard = CALLS.lock().unwrap_or_else(|p| p.into_inner());
        let rc = unsafe { (self.api.start)(ptrs.as_ptr(), ptrs.len() as i32, self.label.as_ptr()) };
        if rc != 0 {
            let msg = self.last_error();
            // libsumo may hold a half-loaded net: close it so the next start is clean.
            unsafe { (self.api.close)(self.label.as_ptr()) };
            return Err(msg);
        }
        self.open = true;
        self.tl_count = unsafe { (self.api.tl_count)() };
        Ok(())
    }

    fn close(&mut self) {
        if self.open {
            self.open = false;
            let _guard = CALLS.lock().unwrap_or_else(|p| p.into_inner());
            unsafe { (self.api.close)(self.label.as_ptr()) };
        }
    }

    fn time_s(&mut self) -> Result<f64> {
        let _g = self.enter()?;
        let mut t = 0.0;
        self.check(unsafe { (self.api.time)(&mut t) }, &|| "reading the time".into())?;
        Ok(t)
    }

    fn light_ids(&mut self) -> Result<Vec<String>> {
        let _g = self.enter()?;
        let n = unsafe { (self.api.tl_count)() };
        Ok((0..n)
            .map(|i| unsafe { CStr::from_ptr((self.api.tl_id)(i)) }.to_string_lossy().into_owned())
            .collect())
    }

    fn set_program(&mut self, tl: &str, phases: &[(String, f64)]) -> Result<()> {
        let t = cstr(tl)?;
        let states = phases.iter().map(|(s, _)| cstr(s)).collect::<Result<Vec<_>>>()?;
        let ptrs: Vec<*const c_char> = states.iter().map(|s| s.as_ptr()).collect();
        let durations: Vec<f64> = phases.iter().map(|p| p.1).collect();
        let _g = self.enter()?;
        let rc = unsafe { (self.api.set_program)(t.as_ptr(), ptrs.len(), ptrs.as_ptr(), durations.as_ptr()) };
        self.check(rc, &|| format!("setting the program of light {tl}"))
    }

    fn set_phase(&mut self, tl: &str, phase: usize, remaining_s: f64) -> Result<()> {
        let t = cstr(tl)?;
        let _g = self.enter()?;
        let rc = unsafe { (self.api.set_phase)(t.as_ptr(), phase as i32, remaining_s) };
        self.check(rc, &|| format!("setting the phase of light {tl}"))
    }

    fn add(&mut self, vid: &str, route: &str, vtype: &str) -> Result<()> {
        let (v, r, t) = (cstr(vid)?, cstr(route)?, cstr(vtype)?);
        let _g = self.enter()?;
        self.check(unsafe { (self.api.add)(v.as_ptr(), r.as_ptr(), t.as_ptr()) }, &|| format!("add {vid}"))
    }

    fn remove(&mut self, vid: &str) -> Result<()> {
        let v = cstr(vid)?;
        let _g = self.enter()?;
        self.check(unsafe { (self.api.remove)(v.as_ptr()) }, &|| format!("remove {vid}"))
    }

    fn move_to_xy(&mut self, vid: &str, x: f64, y: f64, angle: f64, keep_route: u8) -> Result<Placed> {
        let v = cstr(vid)?;
        let _g = self.enter()?;
        let rc = unsafe { (self.api.move_to)(v.as_ptr(), x, y, angle, i32::from(keep_route)) };
        if rc == 1 {
            return Ok(Placed::Unmappable);
        }
        self.check(rc, &|| format!("moveToXY {vid}"))?;
        Ok(Placed::Yes)
    }

    fn step(&mut self, departed: &mut Vec<String>) -> Result<()> {
        let _g = self.enter()?;
        self.check(unsafe { (self.api.step)() }, &|| "simulationStep".into())?;
        departed.clear();
        let n = unsafe { (self.api.departed_count)() };
        for i in 0..n {
            departed
                .push(unsafe { CStr::from_ptr((self.api.departed_id)(i)) }.to_string_lossy().into_owned());
        }
        Ok(())
    }

    fn vehicle_type(&mut self, vid: &str) -> Result<String> {
        let v = cstr(vid)?;
        let _g = self.enter()?;
        let mut out: *const c_char = std::ptr::null();
        self.check(unsafe { (self.api.vehicle_type)(v.as_ptr(), &mut out) }, &|| format!("type of {vid}"))?;
        Ok(unsafe { CStr::from_ptr(out) }.to_string_lossy().into_owned())
    }

    fn type_info(&mut self, vtype: &str) -> Result<TypeInfo> {
        let t = cstr(vtype)?;
        let _g = self.enter()?;
        let mut raw = RawType { length: 0.0, width: 0.0, height: 0.0, color: [0; 4], vclass: [0; 32] };
        self.check(unsafe { (self.api.type_info)(t.as_ptr(), &mut raw) }, &|| {
            format!("vehicle type {vtype}")
        })?;
        // The shim NUL-terminates `vclass` within its 32 bytes.
        let vclass: Vec<u8> = raw.vclass.iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
        Ok(TypeInfo {
            length_m: raw.length,
            width_m: raw.width,
            height_m: raw.height,
            vclass: String::from_utf8_lossy(&vclass).into_owned(),
            color: raw.color.map(i64::from),
        })
    }

    fn track(&mut self, vid: &str, key: u64) -> Result<()> {
        let v = cstr(vid)?;
        let _g = self.enter()?;
        self.check(unsafe { (self.api.track)(v.as_ptr(), key) }, &|| format!("tracking {vid}"))
    }

    fn read(&mut self, out: &mut Vec<VehicleState>) -> Result<()> {
        let _g = self.enter()?;
        let cap = unsafe { (self.api.tracked_count)() };
        out.resize(cap, VehicleState::default());
        let mut n = 0usize;
        self.check(unsafe { (self.api.read)(out.as_mut_ptr(), cap, &mut n) }, &|| {
            "reading the vehicles".into()
        })?;
        out.truncate(n);
        Ok(())
    }

    fn light_states(&mut self, out: &mut Vec<String>) -> Result<()> {
        let _g = self.enter()?;
        self.check(unsafe { (self.api.read_lights)() }, &|| "reading the lights".into())?;
        out.resize(self.tl_count, String::new());
        for (i, s) in out.iter_mut().enumerate() {
            let state = unsafe { CStr::from_ptr((self.api.tl_state)(i)) }.to_bytes();
            if s.as_bytes() != state {
                *s = String::from_utf8_lossy(state).into_owned();
            }
        }
        Ok(())
    }
}

impl Drop for ShimTransport {
    fn drop(&mut self) {
        self.close();
    }
}
