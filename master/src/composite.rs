//! The compositor: stitches tile pixels into the frame, cuts a tile wall's displays out of
//! it, and writes PNGs.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::Deserialize;

use crate::output::write_bytes;

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

    fn fill(&mut self, rect: [u32; 4], rgba: [u8; 4]) {
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

/// A wall of displays, from a TOML file:
///
/// ```toml
/// columns = 3            # displays across
/// rows = 2               # displays down
/// display_width = 1920   # pixels of one display
/// display_height = 1080
/// bezel_x = 60           # pixels hidden between two columns (both bezels together)
/// bezel_y = 60           # pixels hidden between two rows
/// ```
/// The frame covers the whole wall, bezels included, so the picture continues behind a
/// bezel as it would through a window frame; each display shows its own part.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Wall {
    pub columns: u32,
    pub rows: u32,
    pub display_width: u32,
    pub display_height: u32,
    #[serde(default)]
    pub bezel_x: u32,
    #[serde(default)]
    pub bezel_y: u32,
}

impl Wall {
    pub fn load(path: &Path) -> Result<Wall> {
        let bytes = crate::commands::read_input(path)?;
        let text = String::from_utf8(bytes).map_err(|_| anyhow::anyhow!("{}: not UTF-8 text", path.display()))?;
        let wall: Wall =
            toml::from_str(&text).with_context(|| format!("{}: not a valid wall description", path.display()))?;
        wall.validate().with_context(|| format!("{}", path.display()))?;
        Ok(wall)
    }

    fn validate(&self) -> Result<()> {
        if self.columns == 0 || self.rows == 0 || self.display_width == 0 || self.display_height == 0 {
            bail!("columns, rows and display sizes must be at least 1");
        }
        // In u64, where no sum of u32 products can wrap.
        let side = |n: u32, size: u32, bezel: u32| n as u64 * size as u64 + (n as u64 - 1) * bezel as u64;
        let (w, h) =
            (side(self.columns, self.display_width, self.bezel_x), side(self.rows, self.display_height, self.bezel_y));
        crate::cli::check_frame_size(w, h).context("the wall (displays and bezels) is too large")
    }

    /// The frame that covers the wall, bezels included (valid once [`Wall::load`] checked it).
    pub fn frame_size(&self) -> (u32, u32) {
        (
            self.columns * self.display_width + (self.columns - 1) * self.bezel_x,
            self.rows * self.display_height + (self.rows - 1) * self.bezel_y,
        )
    }

    /// Pixel rectangle of display `(col, row)` in the frame.
    pub fn display_rect(&self, col: u32, row: u32) -> [u32; 4] {
        let x0 = col * (self.display_width + self.bezel_x);
        let y0 = row * (self.display_height + self.bezel_y);
        [x0, y0, x0 + self.display_width, y0 + self.display_height]
    }

    /// One image per display (row-major), and an overview of the whole wall with the
    /// bezels drawn opaque black, as the wall looks from the room.
    pub fn split(&self, frame: &Image) -> (Vec<Image>, Image) {
        let mut overview = frame.clone();
        let (w, h) = self.frame_size();
        for c in 1..self.columns {
            let x0 = c * (self.display_width + self.bezel_x) - self.bezel_x;
            overview.fill([x0, 0, x0 + self.bezel_x, h], [0, 0, 0, 255]);
        }
        for r in 1..self.rows {
            let y0 = r * (self.display_height + self.bezel_y) - self.bezel_y;
            overview.fill([0, y0, w, y0 + self.bezel_y], [0, 0, 0, 255]);
        }
        let displays = (0..self.rows)
            .flat_map(|r| (0..self.columns).map(move |c| (c, r)))
            .map(|(c, r)| frame.crop(self.display_rect(c, r)))
            .collect();
        (displays, overview)
    }
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
    fn wall_displays_skip_the_bezels() {
        let wall: Wall =
            toml::from_str("columns = 2\nrows = 2\ndisplay_width = 4\ndisplay_height = 3\nbezel_x = 2\nbezel_y = 1\n")
                .unwrap();
        assert_eq!(wall.frame_size(), (10, 7));
        let mut frame = Image::new(10, 7);
        for (i, px) in frame.rgba.chunks_mut(4).enumerate() {
            px.copy_from_slice(&[(i % 10) as u8, (i / 10) as u8, 0, 255]);
        }
        let (displays, overview) = wall.split(&frame);
        assert_eq!(displays.len(), 4);
        // Display (1, 1) starts after one display and one bezel in each direction.
        assert_eq!(&displays[3].rgba[..4], &[6, 4, 0, 255]);
        // The overview hides the bezel column x = 4..6 and row y = 3.
        let px = |x: usize, y: usize| &overview.rgba[(y * 10 + x) * 4..(y * 10 + x) * 4 + 4];
        assert_eq!(px(4, 0), &[0, 0, 0, 255]);
        assert_eq!(px(0, 3), &[0, 0, 0, 255]);
        assert_eq!(px(6, 4), &[6, 4, 0, 255]);
        assert!(toml::from_str::<Wall>("columns = 2\nrows = 2\ndisplay_width = 4\ndisplay_height = 3\nbezels = 1\n")
            .is_err());
    }

    #[test]
    fn wall_sizes_do_not_wrap() {
        let wall = |text: &str| toml::from_str::<Wall>(text).unwrap().validate();
        // 2 x 2147483649 wraps to 2 in u32 arithmetic.
        let e = wall("columns = 2\nrows = 1\ndisplay_width = 2147483649\ndisplay_height = 10\n").unwrap_err();
        assert!(format!("{e:#}").contains("4294967298x10"), "{e:#}");
        // 100 + 4294967196 wraps to 0 in u32 arithmetic.
        let e =
            wall("columns = 2\nrows = 1\ndisplay_width = 50\ndisplay_height = 10\nbezel_x = 4294967196\n").unwrap_err();
        assert!(format!("{e:#}").contains("at most 16384"), "{e:#}");
        assert!(wall("columns = 3\nrows = 2\ndisplay_width = 1920\ndisplay_height = 1080\nbezel_x = 60\n").is_ok());
        assert!(wall("columns = 9\nrows = 1\ndisplay_width = 1920\ndisplay_height = 1080\n").is_err());
    }
}
