//! Readable stills for docs and debugging: the front camera (2× supersampled) and the BEV of
//! one frame, written as PNGs.

use super::{render_bev, render_camera, BevConfig, CameraConfig, FrameInput, Image, RenderMap};
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// Renders `frame` and writes `<dir>/<name>_front.png` and `<dir>/<name>_bev.png` (and
/// `<name>_chase.png` when `chase`); returns the written paths. Creates `dir` if needed.
pub fn write_gallery(
    map: &RenderMap,
    frame: &FrameInput,
    dir: &Path,
    name: &str,
    chase: bool,
) -> Result<Vec<PathBuf>> {
    if name.is_empty() || name.contains(['/', '\\']) {
        return Err(Error::config("gallery.name", name, "must be a plain file stem"));
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut img = Image::default();
    let mut written = Vec::new();
    let mut cams = vec![("front", CameraConfig { supersample: 2, ..CameraConfig::front() })];
    if chase {
        cams.push(("chase", CameraConfig { supersample: 2, ..CameraConfig::chase() }));
    }
    for (tag, cfg) in cams {
        render_camera(map, frame, &cfg, &mut img)?;
        let p = dir.join(format!("{name}_{tag}.png"));
        img.save(&p)?;
        written.push(p);
    }
    render_bev(map, frame, &BevConfig::default(), &mut img)?;
    let p = dir.join(format!("{name}_bev.png"));
    img.save(&p)?;
    written.push(p);
    Ok(written)
}
