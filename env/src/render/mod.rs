//! Rendering: perspective cameras (z-buffered scanline rasterizer) and the bird's-eye view, on
//! the CPU, deterministic (same state ⇒ same bytes), without per-frame allocation once warm.
//!
//! Both views compute screen-space geometry and draw it through one backend trait
//! (`raster::RasterBackend`: backdrop rows, convex fills with and without depth, strokes,
//! discs); the scanline `raster::SoftwareRaster` is the backend behind every public entry point.
//!
//! - [`RenderMap`] precomputes a road network's static geometry once per map.
//! - [`FrameInput`] is one tick's dynamic state (plain views, no world references).
//! - [`render_camera`] / [`render_bev`] / [`project_actors`] draw into caller-provided
//!   [`Image`]s using a thread-local [`Renderer`] (its scratch buffers are reused); hold your own
//!   [`Renderer`] to control where scratch memory lives.

mod actors;
mod bev;
mod camera;
mod conditions;
mod frame;
mod gallery;
mod image;
mod map;
mod mesh;
pub mod palette;
#[cfg(test)]
mod palette_tests;
mod people;
mod raster;
#[cfg(test)]
mod record;
mod vehicles;
mod video;

pub use bev::BevConfig;
pub use camera::{CameraConfig, ProjectedActor};
pub use conditions::CameraFault;
pub use frame::{Ambience, FrameInput, Renderer};
pub use gallery::write_gallery;
pub use image::Image;
pub use map::RenderMap;
pub use video::GifWriter;

use crate::error::Result;
use std::cell::RefCell;

thread_local! {
    static RENDERER: RefCell<Renderer> = RefCell::new(Renderer::new());
}

fn with_renderer<T>(f: impl FnOnce(&mut Renderer) -> T) -> T {
    RENDERER.with(|r| match r.try_borrow_mut() {
        Ok(mut r) => f(&mut r),
        // Re-entrant use (never happens in this crate): fall back to fresh scratch.
        Err(_) => f(&mut Renderer::new()),
    })
}

/// Renders a camera into `out` (resized as needed; allocation reused).
pub fn render_camera(map: &RenderMap, frame: &FrameInput, cfg: &CameraConfig, out: &mut Image) -> Result<()> {
    with_renderer(|r| r.render_camera(map, frame, cfg, out))
}

/// Renders the bird's-eye view into `out` (resized as needed; allocation reused).
pub fn render_bev(map: &RenderMap, frame: &FrameInput, cfg: &BevConfig, out: &mut Image) -> Result<()> {
    with_renderer(|r| r.render_bev(map, frame, cfg, out))
}

/// [`project_actors`] and the camera image from one raster pass.
pub fn render_and_project(
    map: &RenderMap,
    frame: &FrameInput,
    cfg: &CameraConfig,
    out: &mut Image,
) -> Result<Vec<ProjectedActor>> {
    with_renderer(|r| r.render_and_project(map, frame, cfg, out))
}

/// Every actor the camera sees, with its pixel box, centre, distance and visible fraction.
pub fn project_actors(
    map: &RenderMap,
    frame: &FrameInput,
    cfg: &CameraConfig,
) -> Result<Vec<ProjectedActor>> {
    with_renderer(|r| r.project_actors(map, frame, cfg))
}
