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
        // Where the bad input is, as the core error knows it (None where unknown or when the
        // error was raised from Python); readers use these, never the message text.
        for attr in LOCATION_ATTRS {
            dict.set_item(attr, py.None())?;
        }
        let cls = type_fn.call1((name, (base.clone(), value_error.clone()), dict))?;
        m.add(name, cls)?;
    }
    Ok(())
}

/// The attributes of `ScenarioError` and `ConfigError` (see `_core.pyi`).
const LOCATION_ATTRS: [&str; 6] = ["file", "line", "column", "field", "value", "reason"];

/// (file, line, column, field, value, reason) of a core error, as far as it has them.
type Location<'a> =
    (Option<&'a str>, Option<usize>, Option<usize>, Option<&'a str>, Option<&'a str>, Option<String>);

fn location(err: &dh_env::Error) -> Location<'_> {
    use dh_env::Error as E;
    match err {
        E::Scenario { file, at, field, value, message } => (
            Some(file),
            at.map(|(l, _)| l),
            at.map(|(_, c)| c),
            Some(field),
            Some(value),
            Some(message.clone()),
        ),
        E::Map { file, message } => (Some(file), None, None, None, None, Some(message.clone())),
        E::Config { field, value, message } => {
            (None, None, None, Some(field), Some(value), Some(message.clone()))
        }
        E::Io { path, source } => (Some(path), None, None, None, None, Some(source.to_string())),
        E::Simulation(_) | E::Render(_) => (None, None, None, None, None, None),
    }
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
    let build = || -> PyResult<Bound<'_, PyAny>> {
        let exc = py.import("drivehierarchy._core")?.getattr(class)?.call1((err.to_string(),))?;
        let (file, line, column, field, value, reason) = location(&err);
        exc.setattr("file", file)?;
        exc.setattr("line", line)?;
        exc.setattr("column", column)?;
        exc.setattr("field", field)?;
        exc.setattr("value", value)?;
        exc.setattr("reason", reason)?;
        Ok(exc)
    };
    match build() {
        Ok(exc) => PyErr::from_value(exc),
        Err(e) => e,
    }
}
