//! The one exception tree of the package and the one mapping from core errors to it.

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;

create_exception!(
    drivehierarchy,
    DriveHierarchyError,
    PyException,
    "Base of every error raised by DriveHierarchy."
);
create_exception!(
    drivehierarchy,
    SimulationError,
    DriveHierarchyError,
    "The simulation was misused or failed."
);
create_exception!(drivehierarchy, RenderError, DriveHierarchyError, "Rendering failed.");

// ScenarioError and ConfigError are also ValueErrors: they always mean bad input.
// pyo3's create_exception! takes one base, so they are built with two bases in Python and
// looked up here at call time.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("DriveHierarchyError", py.get_type::<DriveHierarchyError>())?;
    m.add("SimulationError", py.get_type::<SimulationError>())?;
    m.add("RenderError", py.get_type::<RenderError>())?;
    let builtins = py.import("builtins")?;
    let type_fn = builtins.getattr("type")?;
    let base = py.get_type::<DriveHierarchyError>();
    let value_error = py.get_type::<PyValueError>();
    for name in ["ScenarioError", "ConfigError"] {
        let dict = pyo3::types::PyDict::new(py);
        dict.set_item("__module__", "drivehierarchy")?;
        let cls = type_fn.call1((name, (base.clone(), value_error.clone()), dict))?;
        m.add(name, cls)?;
    }
    Ok(())
}

/// Builds the Python exception of the right class for a core error.
pub(crate) fn to_pyerr(py: Python<'_>, err: dh_env::Error) -> PyErr {
    use dh_env::Error as E;
    let class = match &err {
        E::Scenario { .. } | E::Map { .. } | E::Io { .. } => "ScenarioError",
        E::Config { .. } => "ConfigError",
        E::Simulation(_) => return SimulationError::new_err(err.to_string()),
        E::Render(_) => return RenderError::new_err(err.to_string()),
    };
    match py.import("drivehierarchy._core").and_then(|m| m.getattr(class)) {
        Ok(cls) => PyErr::from_value(match cls.call1((err.to_string(),)) {
            Ok(v) => v,
            Err(e) => return e,
        }),
        Err(e) => e,
    }
}
