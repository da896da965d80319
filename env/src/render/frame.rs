//! One frame's input and the rasterizers' scratch memory: what the camera, BEV and recording
//! code all draw with. Kept out of `render/mod.rs` (whose entry points call into those modules)
//! so the dependency runs one way.

use crate::error::{Error, Result};
use crate::geom::Vec2;
use crate::view::{ActorView, SignView, TrafficLightView};

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
    /// Light and weather, and the seed and tick its lens effects are drawn from.
    pub ambience: Ambience,
}

/// The light and weather a frame is drawn under. Lens effects (rain drops) are a pure function
/// of `seed` and `tick`, so a frame stays the same bytes for the same state.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Ambience {
    pub conditions: crate::conditions::Conditions,
    /// The episode seed.
    pub seed: u64,
    /// The world tick the frame shows.
    pub tick: u64,
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
    pub(super) raster: super::raster::SoftwareRaster,
    pub(super) mask: Vec<u32>,
    pub(super) ss: Vec<u8>,
    pub(super) tris: Vec<super::mesh::Tri3>,
    pub(super) cells: Vec<usize>,
    pub(super) pts: Vec<super::raster::SV>,
    /// Visible pixels of one actor (colour naming in `project_actors`).
    pub(super) px: Vec<[u8; 3]>,
    /// Scratch of the lens effects (the pixels under a rain drop).
    pub(super) lens: Vec<u8>,
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
