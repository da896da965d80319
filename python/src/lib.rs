//! The `drivehierarchy._core` extension module: thin wrappers over the pure-Rust crates.

use pyo3::prelude::*;

mod benchmark;
mod editor;
mod env;
mod errors;
mod facts;
mod json;
mod network;
mod render_facts;
mod sumo_home;
mod sumo_native;
mod traffic;
mod vector;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    facts::register(m)?;
    env::register(m)?;
    editor::register(m)?;
    benchmark::register(m)?;
    network::register(m)?;
    sumo_home::register(m)?;
    render_facts::register(m)?;
    vector::register(m)?;
    Ok(())
}
