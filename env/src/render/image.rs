//! The frame type handed to callers: RGB8, row-major, height × width × 3 (HWC).

use crate::error::{Error, Result};
use std::path::Path;

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// RGB8, row-major, `height * width * 3` bytes.
    pub data: Vec<u8>,
}

impl Image {
    /// A black image.
    pub fn new(width: u32, height: u32) -> Self {
        Self { width, height, data: vec![0; width as usize * height as usize * 3] }
    }

    /// Resizes in place, reusing the allocation when it is large enough (contents unspecified).
    pub fn resize(&mut self, width: u32, height: u32) {
        self.width = width;
        self.height = height;
        self.data.resize(width as usize * height as usize * 3, 0);
    }

    /// Pixel at (x, y); `None` outside the image.
    pub fn pixel(&self, x: u32, y: u32) -> Option<[u8; 3]> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let i = (y as usize * self.width as usize + x as usize) * 3;
        Some([self.data[i], self.data[i + 1], self.data[i + 2]])
    }

    fn as_buffer(&self) -> Result<image::RgbImage> {
        image::RgbImage::from_raw(self.width, self.height, self.data.clone()).ok_or_else(|| {
            Error::Render(format!(
                "image buffer of {} bytes does not match {}x{}",
                self.data.len(),
                self.width,
                self.height
            ))
        })
    }

    /// Encodes as PNG bytes.
    pub fn to_png(&self) -> Result<Vec<u8>> {
        self.encode(image::ImageFormat::Png)
    }

    /// Encodes as JPEG bytes with `quality` in 1..=100.
    pub fn to_jpeg(&self, quality: u8) -> Result<Vec<u8>> {
        let mut out = Vec::new();
        let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100));
        self.as_buffer()?.write_with_encoder(enc).map_err(|e| Error::Render(format!("jpeg encode: {e}")))?;
        Ok(out)
    }

    fn encode(&self, fmt: image::ImageFormat) -> Result<Vec<u8>> {
        let mut out = std::io::Cursor::new(Vec::new());
        self.as_buffer()?
            .write_to(&mut out, fmt)
            .map_err(|e| Error::Render(format!("{fmt:?} encode: {e}")))?;
        Ok(out.into_inner())
    }

    /// Writes a PNG, or a JPEG (quality 90) when the extension is `.jpg`/`.jpeg`.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        let bytes = match ext.as_str() {
            "jpg" | "jpeg" => self.to_jpeg(90)?,
            "png" => self.to_png()?,
            other => {
                return Err(Error::Render(format!(
                    "{}: unsupported image extension `{other}` (use .png, .jpg)",
                    path.display()
                )))
            }
        };
        std::fs::write(path, bytes).map_err(|e| Error::io(path, e))
    }

    /// Reads a PNG/JPEG file into RGB8 (used by golden tests).
    pub fn load(path: impl AsRef<Path>) -> Result<Image> {
        let path = path.as_ref();
        let img = image::open(path).map_err(|e| Error::Render(format!("{}: {e}", path.display())))?.to_rgb8();
        Ok(Image { width: img.width(), height: img.height(), data: img.into_raw() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient(w: u32, h: u32) -> Image {
        let mut img = Image::new(w, h);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (i * 7 % 251) as u8;
        }
        img
    }

    #[test]
    fn png_round_trips_and_jpeg_is_a_jfif_stream() {
        let dir = std::env::temp_dir().join(format!("dh_image_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let img = gradient(37, 21);
        img.save(dir.join("a.png")).unwrap();
        assert_eq!(Image::load(dir.join("a.png")).unwrap(), img);
        let jpg = img.to_jpeg(90).unwrap();
        assert_eq!((&jpg[..2], &jpg[jpg.len() - 2..]), (&[0xFF, 0xD8][..], &[0xFF, 0xD9][..]));
        img.save(dir.join("a.jpg")).unwrap();
        let err = img.save(dir.join("a.bmp")).unwrap_err().to_string();
        assert!(err.contains("a.bmp") && err.contains("unsupported image extension `bmp`"), "{err}");
        let back = Image::load(dir.join("a.jpg")).unwrap();
        assert_eq!((back.width, back.height), (37, 21));
        let err = Image::load(dir.join("missing.png")).unwrap_err().to_string();
        assert!(err.contains("missing.png"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_buffer_of_the_wrong_size_is_refused() {
        let mut img = gradient(4, 4);
        img.data.pop();
        assert!(img.to_png().unwrap_err().to_string().contains("does not match 4x4"));
        assert!(img.to_jpeg(80).is_err());
    }
}
