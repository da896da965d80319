//! Episode videos as animated GIFs (no external encoder needed).

use super::Image;
use crate::error::{Error, Result};
use image::codecs::gif::{GifEncoder, Repeat};
use image::{Delay, Frame, RgbaImage};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Streams frames into an animated GIF; every frame must have the first frame's size.
pub struct GifWriter {
    enc: GifEncoder<BufWriter<File>>,
    path: PathBuf,
    delay_ms: u32,
    size: Option<(u32, u32)>,
    frames: usize,
}

impl std::fmt::Debug for GifWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GifWriter").field("path", &self.path).field("frames", &self.frames).finish()
    }
}

impl GifWriter {
    /// Creates `path`; `fps` in 1..=50 (GIF delays are in 10 ms steps).
    pub fn create(path: impl AsRef<Path>, fps: u32) -> Result<Self> {
        if !(1..=50).contains(&fps) {
            return Err(Error::config("video.fps", fps, "must be 1..=50"));
        }
        let path = path.as_ref().to_path_buf();
        let file = File::create(&path).map_err(|e| Error::io(&path, e))?;
        let mut enc = GifEncoder::new_with_speed(BufWriter::new(file), 10);
        enc.set_repeat(Repeat::Infinite).map_err(|e| Error::Render(format!("{}: {e}", path.display())))?;
        Ok(GifWriter { enc, path, delay_ms: 1000 / fps, size: None, frames: 0 })
    }

    pub fn push(&mut self, img: &Image) -> Result<()> {
        let size = *self.size.get_or_insert((img.width, img.height));
        if size != (img.width, img.height) {
            return Err(Error::Render(format!(
                "{}: frame {} is {}x{}, the video is {}x{}",
                self.path.display(),
                self.frames,
                img.width,
                img.height,
                size.0,
                size.1
            )));
        }
        let mut rgba = Vec::with_capacity(img.data.len() / 3 * 4);
        for px in img.data.chunks_exact(3) {
            rgba.extend_from_slice(&[px[0], px[1], px[2], 255]);
        }
        let buf = RgbaImage::from_raw(img.width, img.height, rgba)
            .ok_or_else(|| Error::Render(format!("frame {} has a bad buffer size", self.frames)))?;
        let frame = Frame::from_parts(buf, 0, 0, Delay::from_numer_denom_ms(self.delay_ms, 1));
        self.enc.encode_frame(frame).map_err(|e| Error::Render(format!("{}: {e}", self.path.display())))?;
        self.frames += 1;
        Ok(())
    }

    /// Number of frames written so far.
    pub fn frames(&self) -> usize {
        self.frames
    }
}
