//! The compositor: stitches tile pixels into the frame and writes PNGs. A wall's displays
//! are cut out of the frame by [`crate::wall::Wall::split`].

use std::path::Path;

use crate::output::write_bytes;
use anyhow::{bail, Context, Result};

/// An RGBA8 image, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
}

impl Image {
    /// A transparent image.
    pub fn new(width: u32, height: u32) -> Image {
        Image { width, height, rgba: vec![0; width as usize * height as usize * 4] }
    }

    /// Copies a `(x1-x0) x (y1-y0)` block of pixels to `rect = [x0, y0, x1, y1]`.
    pub fn blit(&mut self, rect: [u32; 4], rgba: &[u8]) -> Result<()> {
        let [x0, y0, x1, y1] = rect;
        if x1 > self.width || y1 > self.height || x0 > x1 || y0 > y1 {
            bail!("tile rectangle {rect:?} is outside the {}x{} frame", self.width, self.height);
        }
        let row = (x1 - x0) as usize * 4;
        if rgba.len() != row * (y1 - y0) as usize {
            bail!("tile rectangle {rect:?} got {} bytes of pixels", rgba.len());
        }
        for (i, y) in (y0..y1).enumerate() {
            let at = (y as usize * self.width as usize + x0 as usize) * 4;
            self.rgba[at..at + row].copy_from_slice(&rgba[i * row..(i + 1) * row]);
        }
        Ok(())
    }

    pub fn crop(&self, rect: [u32; 4]) -> Image {
        let [x0, y0, x1, y1] = rect;
        let mut out = Image::new(x1 - x0, y1 - y0);
        let row = (x1 - x0) as usize * 4;
        for (i, y) in (y0..y1).enumerate() {
            let at = (y as usize * self.width as usize + x0 as usize) * 4;
            out.rgba[i * row..(i + 1) * row].copy_from_slice(&self.rgba[at..at + row]);
        }
        out
    }

    /// This image with `right` to its right (a stereo pair side by side; same heights).
    pub fn beside(&self, right: &Image) -> Image {
        let mut out = Image::new(self.width + right.width, self.height.max(right.height));
        out.blit([0, 0, self.width, self.height], &self.rgba).expect("inside");
        out.blit([self.width, 0, out.width, right.height], &right.rgba).expect("inside");
        out
    }

    pub(crate) fn fill(&mut self, rect: [u32; 4], rgba: [u8; 4]) {
        for y in rect[1]..rect[3] {
            for x in rect[0]..rect[2] {
                let at = (y as usize * self.width as usize + x as usize) * 4;
                self.rgba[at..at + 4].copy_from_slice(&rgba);
            }
        }
    }

    pub fn png(&self) -> Result<Vec<u8>> {
        encode_png(self.width, self.height, png::ColorType::Rgba, &self.rgba)
    }

    /// Writes the image as a PNG, atomically.
    pub fn save_png(&self, path: &Path) -> Result<()> {
        write_bytes(path, &self.png()?)
    }
}

/// Encodes 8-bit pixels (`Rgb` or `Rgba`, rows top first) as PNG.
pub fn encode_png(width: u32, height: u32, color: png::ColorType, pixels: &[u8]) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, width, height);
    encoder.set_color(color);
    encoder.set_depth(png::BitDepth::Eight);
    // fdeflate's fast mode: 6 ms for a 1920x1080 frame of the dragon against 82 ms at the
    // crate's default level, for a file 1.9 times larger (`pngbench` example).
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder.write_header().context("PNG encoding failed")?;
    writer.write_image_data(pixels).context("PNG encoding failed")?;
    writer.finish().context("PNG encoding failed")?;
    Ok(out)
}

/// The intersection of two pixel rectangles `[x0, y0, x1, y1)`, if not empty.
pub fn intersection(a: [u32; 4], b: [u32; 4]) -> Option<[u32; 4]> {
    let r = [a[0].max(b[0]), a[1].max(b[1]), a[2].min(b[2]), a[3].min(b[3])];
    (r[0] < r[2] && r[1] < r[3]).then_some(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blit_and_crop_are_inverse() {
        let mut img = Image::new(10, 7);
        let block: Vec<u8> = (0..3 * 2 * 4).map(|i| i as u8).collect();
        img.blit([4, 3, 7, 5], &block).unwrap();
        assert_eq!(img.crop([4, 3, 7, 5]).rgba, block);
        assert!(img.blit([8, 3, 11, 5], &block).is_err());
        assert!(img.blit([4, 3, 7, 5], &block[1..]).is_err());
    }

    #[test]
    fn beside_puts_the_right_image_on_the_right() {
        let (mut l, mut r) = (Image::new(2, 1), Image::new(3, 1));
        l.rgba.fill(1);
        r.rgba.fill(2);
        let both = l.beside(&r);
        assert_eq!((both.width, both.height), (5, 1));
        assert_eq!(both.rgba, [[1u8; 8].as_slice(), &[2u8; 12]].concat());
    }
}
