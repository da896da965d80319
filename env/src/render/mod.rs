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

mod bev;
mod camera;
mod gallery;
mod image;
mod map;
mod mesh;
mod raster;
#[cfg(test)]
mod record;
mod video;

pub use bev::BevConfig;
pub use camera::{CameraConfig, ProjectedActor};
pub use gallery::write_gallery;
pub use image::Image;
pub use map::RenderMap;
pub use video::GifWriter;

use crate::error::{Error, Result};
use crate::geom::Vec2;
use crate::view::{ActorView, SignView, TrafficLightView};
use std::cell::RefCell;

/// Everything dynamic a frame shows.
#[derive(Debug, Clone, Copy)]
pub struct FrameInput<'a> {
    /// The ego; cameras mount on it, the BEV centres on it.
    pub ego: &'a ActorView,
    /// Other actors (an entry equal to the ego — same id and pose — is skipped).
    pub actors: &'a [ActorView],
    pub lights: &'a [TrafficLightView],
    pub signs: &'a [SignView],
    /// The protocol's local future route points, world frame.
    pub route_points: &'a [Vec2],
}

impl FrameInput<'_> {
    /// Rejects non-finite poses (they would poison the rasterizer's arithmetic).
    pub fn validate(&self) -> Result<()> {
        let p = &self.ego.pose;
        if !(p.pos.is_finite() && p.yaw.is_finite()) {
            return Err(Error::Render(format!("ego pose is not finite: {p:?}")));
        }
        for a in self.actors {
            if !(a.pose.pos.is_finite() && a.pose.yaw.is_finite()) {
                return Err(Error::Render(format!("actor {} pose is not finite: {:?}", a.id, a.pose)));
            }
        }
        for l in self.lights {
            if !(l.stop_line.pos.is_finite() && l.stop_line.yaw.is_finite() && l.lane_width_m.is_finite()) {
                return Err(Error::Render(format!(
                    "traffic light {} / lane {} has a non-finite stop line",
                    l.tl_id, l.lane_id
                )));
            }
        }
        for s in self.signs {
            if !(s.pose.pos.is_finite() && s.pose.yaw.is_finite()) {
                return Err(Error::Render(format!("sign pose is not finite: {:?}", s.pose)));
            }
        }
        if let Some(q) = self.route_points.iter().find(|q| !q.is_finite()) {
            return Err(Error::Render(format!("route point is not finite: {q:?}")));
        }
        Ok(())
    }
}

/// Scratch memory of the rasterizers (depth, ids, supersampling, per-frame triangles). Reuse
/// one per thread; results never depend on what it rendered before.
#[derive(Default)]
pub struct Renderer {
    raster: raster::SoftwareRaster,
    mask: Vec<u32>,
    ss: Vec<u8>,
    tris: Vec<mesh::Tri3>,
    cells: Vec<usize>,
    pts: Vec<raster::SV>,
}

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer").field("raster", &self.raster).finish()
    }
}

impl Renderer {
    pub fn new() -> Self {
        Self::default()
    }
}

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

/// Every actor the camera sees, with its pixel box, centre, distance and visible fraction.
pub fn project_actors(
    map: &RenderMap,
    frame: &FrameInput,
    cfg: &CameraConfig,
) -> Result<Vec<ProjectedActor>> {
    with_renderer(|r| r.project_actors(map, frame, cfg))
}
