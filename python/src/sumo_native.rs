//! `drivehierarchy._core.SumoSession`: the handle on one SUMO co-simulation's session, handed to
//! `Sim.set_traffic("sumo", ...)` (`envs/traffic/transport.py` builds it). The orchestration and the
//! C++ shim transports live in `dh_env::world::sumo`; the `libsumo` Python module's transport
//! (the fallback) in `traffic.rs`.

use crate::traffic::PyLibsumoTransport;
use dh_env::world::sumo::{self, Flavour, SharedSession, ShimTransport, SumoSession, SumoTransport};
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::MutexGuard;

fn lock(s: &SharedSession) -> MutexGuard<'_, SumoSession> {
    s.lock().unwrap_or_else(|p| p.into_inner())
}

/// One SUMO co-simulation (its transport and SUMO's lifecycle). `transport` is "libsumo" (the
/// C++ shim over libsumocpp: SUMO in this process), "traci" (the shim over libtraci: SUMO as a
/// subprocess) or "libsumo-python" (the `libsumo` module).
#[pyclass(name = "SumoSession", module = "drivehierarchy._core")]
pub struct PySumoSession {
    pub(crate) session: SharedSession,
}

fn wrap(t: Box<dyn SumoTransport>, sumo_binary: PathBuf, extra_args: Vec<String>) -> PySumoSession {
    PySumoSession { session: SumoSession::new(t, sumo_binary, extra_args).shared() }
}

#[pymethods]
impl PySumoSession {
    /// Over a C++ shim: `kind` "libsumo" or "traci", the shim file and SUMO's client library
    /// (`libsumocpp.so` / `libtracicpp.so`), loaded once per process; `SimulationError` with the
    /// reason when they cannot load.
    #[staticmethod]
    #[pyo3(signature = (kind, shim, library, sumo_binary, extra_args=Vec::new()))]
    fn shim(
        kind: &str,
        shim: PathBuf,
        library: PathBuf,
        sumo_binary: PathBuf,
        extra_args: Vec<String>,
    ) -> PyResult<Self> {
        let flavour = match kind {
            "libsumo" => Flavour::Libsumo,
            "traci" => Flavour::Traci,
            other => {
                return Err(pyo3::exceptions::PyValueError::new_err(format!(
                    "SUMO shim kind {other:?}: expected 'libsumo' or 'traci'"
                )))
            }
        };
        let t = ShimTransport::new(flavour, &shim, &library).map_err(|e| {
            crate::errors::SimulationError::new_err(format!("{kind} SUMO transport unavailable: {e}"))
        })?;
        Ok(wrap(Box::new(t), sumo_binary, extra_args))
    }

    /// Over the imported `libsumo` Python module.
    #[staticmethod]
    #[pyo3(signature = (module, sumo_binary, extra_args=Vec::new()))]
    fn libsumo_module(
        py: Python<'_>,
        module: Py<PyAny>,
        sumo_binary: PathBuf,
        extra_args: Vec<String>,
    ) -> PyResult<Self> {
        Ok(wrap(Box::new(PyLibsumoTransport::new(py, module)?), sumo_binary, extra_args))
    }

    /// Stops SUMO (idempotent); the next `reset` starts a fresh simulation.
    fn close(&self) {
        lock(&self.session).close();
    }

    #[getter]
    fn transport(&self) -> &'static str {
        lock(&self.session).transport_kind()
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

    /// Whether an in-process SUMO (libsumo: the shim or the Python module) runs in this process.
    #[staticmethod]
    fn in_process_busy() -> bool {
        sumo::in_process_busy()
    }
}
