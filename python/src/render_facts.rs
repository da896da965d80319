//! What the renderer guarantees about colours, for the question generator: the one palette (name,
//! body colour, the HSV range of its name) and the naming of rendered pixels. Pure functions of
//! `dh_env::render::palette`; nothing here renders.

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

/// The body-colour palette: a list of `{name, rgb, hue_deg, saturation, value}` where `rgb` is
/// the colour an actor of that name is painted with and the three ranges (half-open, hue may wrap
/// through 0) are where a rendered colour gets the name.
#[pyfunction]
fn colour_palette(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let out = PyList::empty(py);
    for c in dh_env::render::palette::PALETTE {
        let d = PyDict::new(py);
        d.set_item("name", c.name)?;
        // f32 bounds as the short decimals they were written as, not 0.2700000107…
        let f = |v: f32| (v as f64 * 1000.0).round() / 1000.0;
        d.set_item("rgb", (c.rgb[0], c.rgb[1], c.rgb[2]))?;
        d.set_item("hue_deg", (f(c.range.hue_deg[0]), f(c.range.hue_deg[1])))?;
        d.set_item("saturation", (f(c.range.min_saturation), f(c.range.max_saturation)))?;
        d.set_item("value", (f(c.range.value[0]), f(c.range.value[1])))?;
        out.append(d)?;
    }
    Ok(out)
}

/// The palette name of one sRGB colour (every colour has exactly one).
#[pyfunction]
fn colour_name(rgb: (u8, u8, u8)) -> &'static str {
    dh_env::render::palette::name_of([rgb.0, rgb.1, rgb.2])
}

/// The name a viewer gives an object from its rendered pixels (`[(r, g, b), ...]`): the majority
/// name of the brightest half (sunlit paint). `None` for no pixels. `project_actors` reports the
/// same for each actor's visible body paint as `colour_name`.
#[pyfunction]
fn colour_name_of_pixels(pixels: Vec<(u8, u8, u8)>) -> Option<&'static str> {
    let px: Vec<[u8; 3]> = pixels.into_iter().map(|p| [p.0, p.1, p.2]).collect();
    dh_env::render::palette::name_pixels(&px)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(colour_palette, m)?)?;
    m.add_function(wrap_pyfunction!(colour_name, m)?)?;
    m.add_function(wrap_pyfunction!(colour_name_of_pixels, m)?)?;
    Ok(())
}
