//! serde ↔ Python, by `pythonize`: settings come in as the package's frozen dataclasses or as
//! dicts and are read by the same serde types the core uses; results leave as plain dicts,
//! lists and numbers. No JSON text crosses the seam.

use pyo3::prelude::*;
use pyo3::types::PyString;
use pythonize::{pythonize, Depythonizer};
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_path_to_error::Segment;

/// A Rust value as Python data. It goes through `serde_json::Value` first, so every result has
/// the form the JSON records have (a non-finite float is `None`, as in a written record).
pub(crate) fn to_py<'py, T: Serialize + ?Sized>(py: Python<'py>, v: &T) -> PyResult<Bound<'py, PyAny>> {
    let value = serde_json::to_value(v)
        .map_err(|e| crate::errors::to_pyerr(py, dh_env::Error::Simulation(e.to_string())))?;
    Ok(pythonize(py, &value)?)
}

/// Reads a setting given as a dataclass instance or a mapping with serde. `what` names it in
/// errors, which are ConfigErrors naming the field (`camera.width`) and the value found there.
pub(crate) fn from_py<T: DeserializeOwned>(what: &str, obj: &Bound<'_, PyAny>) -> dh_env::Result<T> {
    let plain = plain(obj).map_err(|e| dh_env::Error::config(what, repr(obj), e.to_string()))?;
    let mut de = Depythonizer::from_object(&plain);
    serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path();
        let (field, value) = if path.iter().next().is_none() {
            (what.to_owned(), repr(&plain))
        } else {
            (
                format!("{what}.{path}"),
                at_path(&plain, path.iter()).map_or_else(|| repr(&plain), |v| repr(&v)),
            )
        };
        dh_env::Error::config(field, value, e.into_inner().to_string())
    })
}

/// A dataclass instance as a dict (`dataclasses.asdict`, nested ones too); anything else as is.
fn plain<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let dataclasses = obj.py().import("dataclasses")?;
    let is_instance = !obj.is_instance_of::<pyo3::types::PyType>()
        && dataclasses.getattr("is_dataclass")?.call1((obj,))?.is_truthy()?;
    if is_instance {
        dataclasses.getattr("asdict")?.call1((obj,))
    } else {
        Ok(obj.clone())
    }
}

/// The value at a deserializer's error path (`None` past a missing key: the error is about the
/// mapping, which the caller shows instead).
fn at_path<'a, 'py>(
    root: &Bound<'py, PyAny>,
    path: impl Iterator<Item = &'a Segment>,
) -> Option<Bound<'py, PyAny>> {
    let mut v = root.clone();
    for seg in path {
        v = match seg {
            Segment::Seq { index } => v.get_item(index).ok()?,
            Segment::Map { key } => v.get_item(PyString::new(root.py(), key)).ok()?,
            Segment::Enum { .. } | Segment::Unknown => return Some(v),
        };
    }
    Some(v)
}

fn repr(obj: &Bound<'_, PyAny>) -> String {
    obj.repr().map_or_else(|_| "<unprintable>".to_owned(), |r| r.to_string())
}
