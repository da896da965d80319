//! `sumo_home()`: the workspace's one `SUMO_HOME` lookup ([`SumoHome::locate_with`]) for Python,
//! with the `sumo` package looked up in this interpreter instead of a `python3` subprocess.

use dh_env::sumo_home::SumoHome;
use pyo3::prelude::*;
use std::ffi::OsString;
use std::path::PathBuf;

/// The folder of this interpreter's `sumo` package (`sumo.SUMO_HOME`), found without importing
/// it (`import sumo` reads the wheel's metadata, 30-130 ms).
fn package_home(py: Python<'_>) -> PyResult<Option<PathBuf>> {
    let spec = py.import("importlib.util")?.call_method1("find_spec", ("sumo",))?;
    if spec.is_none() {
        return Ok(None);
    }
    let origin = spec.getattr("origin")?;
    if origin.is_none() {
        return Ok(None);
    }
    let origin: PathBuf = origin.extract()?;
    Ok(origin.parent().map(PathBuf::from))
}

/// The folder of this interpreter's `sumo` package, else `$SUMO_HOME` if set and non-empty;
/// `None` when neither exists (docs/traffic.md, "Where SUMO is found").
#[pyfunction]
pub fn sumo_home(py: Python<'_>) -> PyResult<Option<OsString>> {
    let mut failed = None;
    let home = SumoHome::locate_with(|| {
        package_home(py).unwrap_or_else(|e| {
            failed = Some(e);
            None
        })
    });
    match failed {
        Some(e) => Err(e),
        None => Ok(home.map(|h| h.0.into_os_string())),
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(sumo_home, m)?)?;
    Ok(())
}
