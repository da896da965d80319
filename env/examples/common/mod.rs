//! Scene setup shared by the gallery examples (`render_gallery`, `render_conditions`): the
//! command line, town01's net and render map, actor views and the approach poses they stage.

#![allow(dead_code)] // each example uses its own subset

use dh_env::geom::Pose;
use dh_env::map::Network;
use dh_env::render::{Ambience, FrameInput, RenderMap};
use dh_env::view::{ActorKind, ActorView};
use std::error::Error;
use std::path::{Path, PathBuf};

/// The net, its render map and the output folder from `EXAMPLE TOWN01_NET OUT_DIR`.
pub struct Town {
    pub net: Network,
    pub map: RenderMap,
    pub dir: PathBuf,
}

impl Town {
    pub fn from_args(example: &str) -> Result<Town, Box<dyn Error>> {
        let args: Vec<String> = std::env::args().collect();
        if args.len() < 3 {
            return Err(format!("usage: {example} TOWN01_NET OUT_DIR").into());
        }
        let net = Network::from_file(Path::new(&args[1]))?;
        let map = RenderMap::build(&net);
        let dir = PathBuf::from(&args[2]);
        std::fs::create_dir_all(&dir)?;
        Ok(Town { net, map, dir })
    }

    /// The pose on lane `id`, `before_end_m` before its end (its stop line).
    pub fn approach(&self, id: &str, before_end_m: f64) -> Result<Pose, Box<dyn Error>> {
        let lane = self.net.lane_by_id(id).ok_or_else(|| format!("the net has no lane {id}"))?;
        Ok(self.net.lane_position(lane, self.net.lanes[lane].shape.length() - before_end_m))
    }
}

/// A pose `f` metres ahead of and `l` left of `p`, turned by `dyaw` from it.
pub fn at(p: Pose, f: f64, l: f64, dyaw: f64) -> Pose {
    Pose::new(p.local_to_world(f, l), p.yaw + dyaw)
}

/// An actor at rest with its kind's default size (zero sizes) and no lamps lit.
pub fn view(id: u32, kind: ActorKind, pose: Pose, color: [u8; 3]) -> ActorView {
    ActorView::at_rest(id, kind, pose, color)
}

/// A frame of `ego` and `actors` without signals, signs or route.
pub fn frame<'a>(ego: &'a ActorView, actors: &'a [ActorView], ambience: Ambience) -> FrameInput<'a> {
    FrameInput { ego, actors, lights: &[], signs: &[], route_points: &[], ambience }
}
