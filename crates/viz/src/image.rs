//! An RGB image with the few drawing primitives the pictures need.

use std::path::Path;

use crate::{Error, Result};

/// An 8-bit RGB image, rows top to bottom.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    width: usize,
    height: usize,
    px: Vec<u8>,
}

/// White.
pub const WHITE: [u8; 3] = [255, 255, 255];
/// Black.
pub const BLACK: [u8; 3] = [0, 0, 0];

impl Image {
    /// An image filled with `background`.
    pub fn new(width: usize, height: usize, background: [u8; 3]) -> Image {
        let mut px = Vec::with_capacity(width * height * 3);
        for _ in 0..width * height {
            px.extend_from_slice(&background);
        }
        Image { width, height, px }
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The pixel at column `x`, row `y`.
    pub fn get(&self, x: usize, y: usize) -> [u8; 3] {
        let i = 3 * (y * self.width + x);
        [self.px[i], self.px[i + 1], self.px[i + 2]]
    }

    /// Sets a pixel; coordinates outside the image are ignored.
    pub fn set(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            let i = 3 * (y as usize * self.width + x as usize);
            self.px[i..i + 3].copy_from_slice(&c);
        }
    }

    /// Fills the rectangle `[x, x + w) x [y, y + h)`.
    pub fn fill_rect(&mut self, x: i64, y: i64, w: i64, h: i64, c: [u8; 3]) {
        for yy in y..y + h {
            for xx in x..x + w {
                self.set(xx, yy, c);
            }
        }
    }

    /// A straight line `width` pixels thick.
    pub fn line(&mut self, (x0, y0): (f64, f64), (x1, y1): (f64, f64), c: [u8; 3], width: i64) {
        let steps = ((x1 - x0).abs().max((y1 - y0).abs()).ceil() as usize).max(1);
        for s in 0..=steps {
            let t = s as f64 / steps as f64;
            let (x, y) = (
                (x0 + t * (x1 - x0)).round() as i64,
                (y0 + t * (y1 - y0)).round() as i64,
            );
            self.fill_rect(x - width / 2, y - width / 2, width, width, c);
        }
    }

    /// Text in the 8x8 bitmap font of `font8x8` (ASCII), each glyph
    /// `8 * scale` pixels square, top-left corner at `(x, y)`.
    pub fn text(&mut self, x: i64, y: i64, s: &str, scale: i64, c: [u8; 3]) {
        for (k, ch) in s.chars().enumerate() {
            let glyph = font8x8::legacy::BASIC_LEGACY
                .get(ch as usize)
                .copied()
                .unwrap_or([0; 8]);
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8 {
                    if bits >> col & 1 == 1 {
                        self.fill_rect(
                            x + (k as i64 * 8 + col) * scale,
                            y + row as i64 * scale,
                            scale,
                            scale,
                            c,
                        );
                    }
                }
            }
        }
    }

    /// Copies `other` with its top-left corner at `(x, y)` (clipped).
    pub fn blit(&mut self, other: &Image, x: i64, y: i64) {
        for yy in 0..other.height {
            for xx in 0..other.width {
                self.set(x + xx as i64, y + yy as i64, other.get(xx, yy));
            }
        }
    }

    /// Images side by side on a `background`, top-aligned.
    pub fn hstack(images: &[Image], background: [u8; 3]) -> Image {
        let w = images.iter().map(|i| i.width).sum();
        let h = images.iter().map(|i| i.height).max().unwrap_or(0);
        let mut out = Image::new(w, h, background);
        let mut x = 0;
        for i in images {
            out.blit(i, x, 0);
            x += i.width as i64;
        }
        out
    }

    /// The raw RGB bytes, row by row.
    pub fn pixels(&self) -> &[u8] {
        &self.px
    }

    /// The image encoded as PNG.
    pub fn to_png(&self) -> Result<Vec<u8>> {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, self.width as u32, self.height as u32);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc.write_header().map_err(|e| Error::Png(e.to_string()))?;
            w.write_image_data(&self.px)
                .map_err(|e| Error::Png(e.to_string()))?;
        }
        Ok(out)
    }

    /// Writes the image as a PNG file.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let bytes = self.to_png()?;
        fmaps_mesh_io::atomic::write_atomically(path, |w| w.write_all(&bytes)).map_err(|e| {
            Error::Io {
                path: path.display().to_string(),
                message: e.to_string(),
            }
        })
    }
}
