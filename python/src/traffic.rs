//! The `libsumo` Python module as a [`SumoTransport`]: the fallback when the C++ shims were not
//! built. The orchestration (`dh_env::world::sumo`) is the same as for every transport; this file
//! only carries its calls to the module (`libsumo.vehicle.moveToXY`, `simulationStep`, ...)
//! and reads the subscription results (`vehicle.getAllSubscriptionResults()`) in Rust, so
//! Python does no per-vehicle work.

use dh_env::world::sumo::{Placed, SumoTransport, TypeInfo, VehicleState};
use dh_env::{Error, Result};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString, PyTuple};
use std::collections::HashMap;

// libsumo variable ids (`libsumo.constants`).
const VAR_SPEED: i32 = 0x40;
const VAR_POSITION: i32 = 0x42;
const VAR_ANGLE: i32 = 0x43;
const VAR_SIGNALS: i32 = 0x5b;

/// The module's functions a tick uses, looked up once.
#[derive(Debug)]
struct Fns {
    move_to_xy: Py<PyAny>,
    step: Py<PyAny>,
    departed: Py<PyAny>,
    results: Py<PyAny>,
    light_state: Py<PyAny>,
    traci_exception: Py<PyAny>,
}

/// SUMO through the `libsumo` Python module (in this process: one simulation per process).
#[derive(Debug)]
pub struct PyLibsumoTransport {
    ls: Py<PyAny>,
    fns: Fns,
    tracked: HashMap<String, u64>,
    light_ids: Vec<String>,
    open: bool,
}

fn err(what: &str, e: PyErr) -> Error {
    Error::Simulation(format!("SUMO co-simulation: {what}: {e}"))
}

impl PyLibsumoTransport {
    /// Over the imported `libsumo` module.
    pub fn new(py: Python<'_>, ls: Py<PyAny>) -> PyResult<PyLibsumoTransport> {
        let m = ls.bind(py);
        let fns = Fns {
            move_to_xy: m.getattr("vehicle")?.getattr("moveToXY")?.unbind(),
            step: m.getattr("simulationStep")?.unbind(),
            departed: m.getattr("simulation")?.getattr("getDepartedIDList")?.unbind(),
            results: m.getattr("vehicle")?.getattr("getAllSubscriptionResults")?.unbind(),
            light_state: m.getattr("trafficlight")?.getattr("getRedYellowGreenState")?.unbind(),
            traci_exception: m.getattr("TraCIException")?.unbind(),
        };
        Ok(PyLibsumoTransport { ls, fns, tracked: HashMap::new(), light_ids: Vec::new(), open: false })
    }

    fn call<T>(
        &self,
        what: &dyn Fn() -> String,
        f: impl FnOnce(Python<'_>, &Bound<'_, PyAny>) -> PyResult<T>,
    ) -> Result<T> {
        if !self.open {
            return Err(Error::Simulation(
                "SUMO is not running (the traffic was closed); call reset()".into(),
            ));
        }
        Python::attach(|py| f(py, self.ls.bind(py))).map_err(|e| err(&what(), e))
    }
}

impl SumoTransport for PyLibsumoTransport {
    fn kind(&self) -> &'static str {
        "libsumo-python"
    }

    fn in_process(&self) -> bool {
        true
    }

    fn start(&mut self, cmd: &[String]) -> std::result::Result<(), String> {
        self.close();
        self.tracked.clear();
        Python::attach(|py| {
            let ls = self.ls.bind(py);
            ls.call_method1("start", (cmd.to_vec(),))?;
            self.light_ids = ls.getattr("trafficlight")?.call_method0("getIDList")?.extract()?;
            Ok(())
        })
        .map_err(|e: PyErr| {
            self.close_inner();
            e.to_string()
        })?;
        self.open = true;
        Ok(())
    }

    fn close(&mut self) {
        if self.open {
            self.open = false;
            self.close_inner();
        }
    }

    fn time_s(&mut self) -> Result<f64> {
        self.call(&|| "reading the time".into(), |_, ls| {
            ls.getattr("simulation")?.call_method0("getTime")?.extract()
        })
    }

    fn light_ids(&mut self) -> Result<Vec<String>> {
        Ok(self.light_ids.clone())
    }

    fn set_program(&mut self, tl: &str, phases: &[(String, f64)]) -> Result<()> {
        self.call(&|| format!("setting the program of light {tl}"), |py, ls| {
            let tls = ls.getattr("trafficlight")?;
            let phase_cls = tls.getattr("Phase")?;
            let list = PyList::empty(py);
            for (state, d) in phases {
                list.append(phase_cls.call1((*d, state.as_str()))?)?;
            }
            let logic = tls.getattr("Logic")?.call1(("dh_override", 0, 0, list))?;
            tls.call_method1("setProgramLogic", (tl, logic))?;
            tls.call_method1("setProgram", (tl, "dh_override"))?;
            Ok(())
        })
    }

    fn set_phase(&mut self, tl: &str, phase: usize, remaining_s: f64) -> Result<()> {
        self.call(&|| format!("setting the phase of light {tl}"), |_, ls| {
            let tls = ls.getattr("trafficlight")?;
            tls.call_method1("setPhase", (tl, phase))?;
            tls.call_method1("setPhaseDuration", (tl, remaining_s))?;
            Ok(())
        })
    }

    fn add(&mut self, vid: &str, route: &str, vtype: &str) -> Result<()> {
        self.call(&|| format!("add {vid}"), |py, ls| {
            let kw = PyDict::new(py);
            kw.set_item("typeID", vtype)?;
            kw.set_item("depart", "now")?;
            ls.getattr("vehicle")?.call_method("add", (vid, route), Some(&kw))?;
            Ok(())
        })
    }

    fn remove(&mut self, vid: &str) -> Result<()> {
        self.call(&|| format!("remove {vid}"), |_, ls| {
            ls.getattr("vehicle")?.call_method1("remove", (vid,))?;
            Ok(())
        })
    }

    fn move_to_xy(&mut self, vid: &str, x: f64, y: f64, angle: f64, keep_route: u8) -> Result<Placed> {
        let fns = &self.fns;
        self.call(&|| format!("moveToXY {vid}"), |py, _| {
            match fns.move_to_xy.bind(py).call1((vid, "", -1, x, y, angle, keep_route)) {
                Ok(_) => Ok(Placed::Yes),
                Err(e) if e.is_instance(py, fns.traci_exception.bind(py)) => Ok(Placed::Unmappable),
                Err(e) => Err(e),
            }
        })
    }

    fn step(&mut self, departed: &mut Vec<String>) -> Result<()> {
        let fns = &self.fns;
        let ids: Vec<String> = self.call(&|| "simulationStep".into(), |py, _| {
            fns.step.bind(py).call0()?;
            fns.departed.bind(py).call0()?.extract()
        })?;
        *departed = ids;
        Ok(())
    }

    fn vehicle_type(&mut self, vid: &str) -> Result<String> {
        self.call(&|| format!("type of {vid}"), |_, ls| {
            ls.getattr("vehicle")?.call_method1("getTypeID", (vid,))?.extract()
        })
    }

    fn type_info(&mut self, vtype: &str) -> Result<TypeInfo> {
        self.call(&|| format!("vehicle type {vtype}"), |_, ls| {
            let vt = ls.getattr("vehicletype")?;
            let color: Vec<i64> = vt.call_method1("getColor", (vtype,))?.extract()?;
            let mut c = [0i64; 4];
            for (d, s) in c.iter_mut().zip(&color) {
                *d = *s;
            }
            Ok(TypeInfo {
                length_m: vt.call_method1("getLength", (vtype,))?.extract()?,
                width_m: vt.call_method1("getWidth", (vtype,))?.extract()?,
                height_m: vt.call_method1("getHeight", (vtype,))?.extract()?,
                vclass: vt.call_method1("getVehicleClass", (vtype,))?.extract()?,
                color: c,
            })
        })
    }

    fn track(&mut self, vid: &str, key: u64) -> Result<()> {
        self.call(&|| format!("tracking {vid}"), |py, ls| {
            let vars = PyTuple::new(py, [VAR_POSITION, VAR_ANGLE, VAR_SPEED, VAR_SIGNALS])?;
            ls.getattr("vehicle")?.call_method1("subscribe", (vid, vars))?;
            Ok(())
        })?;
        self.tracked.insert(vid.to_string(), key);
        Ok(())
    }

    fn read(&mut self, out: &mut Vec<VehicleState>) -> Result<()> {
        out.clear();
        let (fns, tracked) = (&self.fns, &self.tracked);
        self.call(&|| "reading the vehicles".into(), |py, _| {
            let all = fns.results.bind(py).call0()?;
            let (k_pos, k_ang, k_speed, k_sig) = (
                VAR_POSITION.into_pyobject(py)?,
                VAR_ANGLE.into_pyobject(py)?,
                VAR_SPEED.into_pyobject(py)?,
                VAR_SIGNALS.into_pyobject(py)?,
            );
            // libsumo's results come in id order (a std::map), as the shim reads them.
            for (k, v) in all.cast::<PyDict>()?.iter() {
                let vid = k.cast::<PyString>()?;
                let vid = vid.to_str()?;
                let Some(&key) = tracked.get(vid) else { continue };
                let d = v.cast::<PyDict>()?;
                let (x, y): (f64, f64) = field(d, k_pos.as_any(), vid)?.extract()?;
                out.push(VehicleState {
                    key,
                    x,
                    y,
                    angle: field(d, k_ang.as_any(), vid)?.extract()?,
                    speed: field(d, k_speed.as_any(), vid)?.extract()?,
                    signals: field(d, k_sig.as_any(), vid)?.extract()?,
                    _pad: 0,
                });
            }
            Ok(())
        })
    }

    fn light_states(&mut self, out: &mut Vec<String>) -> Result<()> {
        let (fns, ids) = (&self.fns, &self.light_ids);
        let states: Vec<String> = self.call(&|| "reading the lights".into(), |py, _| {
            ids.iter().map(|tl| fns.light_state.bind(py).call1((tl.as_str(),))?.extract()).collect()
        })?;
        *out = states;
        Ok(())
    }
}

impl PyLibsumoTransport {
    fn close_inner(&self) {
        // SUMO may already be gone (e.g. it failed mid-episode, or never started).
        Python::attach(|py| {
            let _ = self.ls.bind(py).call_method0("close");
        });
    }
}

impl Drop for PyLibsumoTransport {
    fn drop(&mut self) {
        self.close();
    }
}

fn field<'py>(d: &Bound<'py, PyDict>, key: &Bound<'py, PyAny>, vid: &str) -> PyResult<Bound<'py, PyAny>> {
    d.get_item(key)?.ok_or_else(|| {
        pyo3::exceptions::PyKeyError::new_err(format!("SUMO subscription of {vid} lacks {key}"))
    })
}
