//! Tile walls: the wall file (a grid, or displays in any arrangement with their own bezels,
//! optionally placed in the world), its displays' rectangles in the frame, and the off-axis
//! frusta (Kooima's generalised perspective projection) from an eye through the wall or
//! through each display.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::Deserialize;

use crate::composite::{intersection, Image};

/// A wall of displays, from a TOML file, in one of two forms. A regular grid:
///
/// ```toml
/// columns = 3            # displays across
/// rows = 2               # displays down
/// display_width = 1920   # pixels of one display
/// display_height = 1080
/// bezel_x = 60           # pixels hidden between two columns (both bezels together)
/// bezel_y = 60           # pixels hidden between two rows
/// ```
/// or a list of displays in any arrangement, each a rectangle of wall pixels with its own
/// bezels (in pixels, outside its rectangle: one number for all four sides, or `[left, top,
/// right, bottom]`) and an optional name (letters, digits, `-` and `_`; its index if none):
///
/// ```toml
/// [[display]]
/// name = "left"
/// x = 40                 # the top-left pixel of the display's picture, in wall pixels
/// y = 300
/// width = 1080
/// height = 1920
/// bezel = 40
/// [[display]]
/// x = 1200
/// y = 40
/// width = 1920
/// height = 1080
/// bezel = [40, 40, 40, 60]
/// ```
/// The frame covers the wall from pixel (0, 0) to the right and bottom edges of the last
/// bezels, so the picture continues behind a bezel or a gap as it would through a window
/// frame; each display shows its own part. Displays (bezels included) may not overlap.
///
/// Either form may place the wall in the world, as ParaView's `.pvx` and Equalizer's wall
/// descriptions do: `plane` gives the world positions of the frame's bottom-left,
/// bottom-right and top-left corners, and `eye` the viewer's eye (or `render --eye-path`,
/// one per frame, for head tracking). The view is then the off-axis frustum from the eye
/// through the wall ([`Wall::camera_args`]): the camera flags' eye, target, up, field of
/// view and shift come from the wall, and moving the eye moves the picture on the displays
/// as a window's view moves.
///
/// ```toml
/// eye = [0.0, 0.0, 3.0]
/// [plane]
/// bottom_left = [-1.6, -0.5, 0.0]
/// bottom_right = [1.6, -0.5, 0.0]
/// top_left = [-1.6, 1.3, 0.0]
/// ```
/// Live runs (`render --present`) show each display in a window of its own, pixel for
/// pixel, on the X display of the rank that owns it (`DISPLAY` in its environment: mpirun's
/// `-x DISPLAY=...` per rank). A `[window]` table places the wall's windows, and a listed
/// display's own `window` table places its window (its keys win over the wall's):
///
/// ```toml
/// [window]
/// x = 0                  # the wall's pixel (0, 0) goes here on the X screen, so that each
/// y = 0                  # window sits at its display's place on the wall (bezels as gaps)
/// [[display]]
/// x = 40
/// # ...
/// window = { x = 0, y = 0, monitor = "HDMI-1", fullscreen = true }
/// ```
/// A display's own `x` and `y` are its window's position; `monitor` (a name, or an index
/// from 0 in the X server's order) makes them relative to that monitor's top-left corner;
/// `fullscreen = true` makes the window borderless and fullscreen on that monitor (or the
/// one it opens on), the picture at its top-left. Without any, the window manager places
/// the windows.
///
/// All displays lie in that one plane, so one frustum serves them all: it is each display's
/// own off-axis frustum, cut to the display. Displays that stand at angles to each other (a
/// CAVE) give their own corners instead, and each gets a frame and a frustum of its own:
///
/// ```toml
/// eye = [-1.5, 0.0, 1.5]
/// [[display]]
/// name = "front"
/// x = 0
/// y = 0
/// width = 1920
/// height = 1080
/// corners = { bottom_left = [-3.2, -1.8, -3.0], bottom_right = [3.2, -1.8, -3.0], top_left = [-3.2, 1.8, -3.0] }
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Wall {
    pub width: u32,
    pub height: u32,
    pub displays: Vec<Display>,
    pub plane: Option<WallPlane>,
    pub eye: Option<glam::Vec3>,
}

/// Where the wall's frame lies in the world: its corners at pixel (0, H), (W, H) and (0, 0).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WallPlane {
    pub bottom_left: [f32; 3],
    pub bottom_right: [f32; 3],
    pub top_left: [f32; 3],
}

/// One display of a [`Wall`].
#[derive(Clone, Debug, PartialEq)]
pub struct Display {
    /// Names the display's images: `frame-display-<name>.png` (`<col>-<row>` on a grid).
    pub name: String,
    /// The display's pixels in the frame, `[x0, y0, x1, y1)`.
    pub rect: [u32; 4],
    /// Its bezels in pixels: left, top, right, bottom.
    pub bezel: [u32; 4],
    /// Where its picture lies in the world (a listed display's `corners`): with every
    /// display placed so, each gets its own frame and off-axis frustum from the eye, so
    /// displays may stand at angles to each other (a CAVE, a curved wall).
    pub corners: Option<WallPlane>,
    /// Where its window opens in a live run.
    pub window: WindowPlace,
}

/// The wall file as written (either form; [`Wall::load`] checks which).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WallFile {
    columns: Option<u32>,
    rows: Option<u32>,
    display_width: Option<u32>,
    display_height: Option<u32>,
    bezel_x: Option<u32>,
    bezel_y: Option<u32>,
    #[serde(default)]
    display: Vec<DisplayFile>,
    plane: Option<WallPlane>,
    eye: Option<[f32; 3]>,
    window: Option<WindowPlace>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DisplayFile {
    name: Option<String>,
    x: u32,
    y: u32,
    width: u32,
    height: u32,
    #[serde(default)]
    bezel: Bezel,
    corners: Option<WallPlane>,
    window: Option<WindowPlace>,
}

/// Where a display's window opens in a live run (`render --present`); see [`Wall`].
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WindowPlace {
    /// The window's top-left corner on the X screen (or on `monitor`).
    pub x: Option<i32>,
    pub y: Option<i32>,
    pub monitor: Option<Monitor>,
    /// Borderless fullscreen.
    pub fullscreen: Option<bool>,
}

/// A monitor of the X screen, by its name (`xrandr`'s output name) or its index from 0.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum Monitor {
    Index(u32),
    Name(String),
}

impl WindowPlace {
    /// Display `rect`'s window: `own` (the display's table) over `wall` (the wall's, whose
    /// position is that of the wall's pixel (0, 0)).
    fn resolve(wall: Option<&WindowPlace>, own: Option<&WindowPlace>, rect: [u32; 4]) -> Result<WindowPlace> {
        for p in [wall, own].into_iter().flatten() {
            if p.x.is_some() != p.y.is_some() {
                bail!("a window's position needs both x and y");
            }
        }
        let offset = |at: Option<i32>, by: u32| {
            at.map(|a| {
                i32::try_from(by).ok().and_then(|b| a.checked_add(b)).context("a window's position is too large")
            })
            .transpose()
        };
        let wall = wall.cloned().unwrap_or_default();
        let mut place = WindowPlace { x: offset(wall.x, rect[0])?, y: offset(wall.y, rect[1])?, ..wall };
        if let Some(own) = own {
            if own.x.is_some() {
                (place.x, place.y) = (own.x, own.y);
            }
            place.monitor = own.monitor.clone().or(place.monitor);
            place.fullscreen = own.fullscreen.or(place.fullscreen);
        }
        Ok(place)
    }
}

#[derive(Deserialize)]
#[serde(untagged)]
enum Bezel {
    All(u32),
    Sides([u32; 4]),
}

impl Default for Bezel {
    fn default() -> Bezel {
        Bezel::All(0)
    }
}

/// The most displays a wall may have. The largest walls built have a few hundred; each
/// display costs an image per frame and the overlap check compares every pair, so a wall
/// file of a few lines cannot ask for a frame's worth of work per pixel.
pub const MAX_DISPLAYS: u64 = 1024;

impl Wall {
    pub fn load(path: &Path) -> Result<Wall> {
        let bytes = crate::model::read_input(path)?;
        let text = String::from_utf8(bytes).map_err(|_| anyhow::anyhow!("{}: not UTF-8 text", path.display()))?;
        Wall::parse(&text).with_context(|| format!("{}", path.display()))
    }

    /// A wall from the text of a wall file, checked.
    pub fn parse(text: &str) -> Result<Wall> {
        let mut file: WallFile = toml::from_str(text).map_err(|e: toml::de::Error| {
            // toml's own message spans several lines (a snippet and a caret): one line here.
            let at = e.span().map_or(String::new(), |span| {
                let before = &text[..span.start.min(text.len())];
                let line = before.matches('\n').count() + 1;
                let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
                format!(" at line {line}, column {column}")
            });
            let message: Vec<&str> = e.message().lines().map(str::trim).filter(|l| !l.is_empty()).collect();
            anyhow::anyhow!("not a valid wall description{at}: {}", message.join("; "))
        })?;
        let grid = [file.columns, file.rows, file.display_width, file.display_height];
        // Each listed display's own window table (none on a grid).
        let owns: Vec<Option<WindowPlace>> = file.display.iter_mut().map(|d| d.window.take()).collect();
        let (plane, eye) = (file.plane, file.eye.map(glam::Vec3::from));
        let mut wall = if file.display.is_empty() {
            let [Some(columns), Some(rows), Some(w), Some(h)] = grid else {
                bail!("a wall needs columns, rows, display_width and display_height, or a [[display]] list");
            };
            Wall::grid(columns, rows, w, h, file.bezel_x.unwrap_or(0), file.bezel_y.unwrap_or(0))?
        } else {
            if grid.iter().chain(&[file.bezel_x, file.bezel_y]).any(Option::is_some) {
                bail!("a wall is either a grid (columns, rows, ...) or a [[display]] list, not both");
            }
            Wall::listed(file.display)?
        };
        for (i, d) in wall.displays.iter_mut().enumerate() {
            let own = owns.get(i).and_then(Option::as_ref);
            d.window = WindowPlace::resolve(file.window.as_ref(), own, d.rect)
                .with_context(|| format!("display {}", d.name))?;
        }
        (wall.plane, wall.eye) = (plane, eye);
        wall.validate()?;
        let placed = wall.displays.iter().filter(|d| d.corners.is_some()).count();
        if placed > 0 && placed < wall.displays.len() {
            bail!("either every display has its corners or none has");
        }
        if placed > 0 && wall.plane.is_some() {
            bail!("a wall is placed by its plane or by its displays' corners, not both");
        }
        if let Some(eye) = wall.eye {
            if !wall.placed() {
                bail!("an eye needs the wall's plane or its displays' corners");
            }
            wall.check_eye(eye)?;
        }
        Ok(wall)
    }

    /// Whether the wall is placed in the world (a plane, or every display's corners).
    pub fn placed(&self) -> bool {
        self.plane.is_some() || self.per_display()
    }

    /// Whether each display has its own frame and frustum (its corners are given).
    pub fn per_display(&self) -> bool {
        self.displays.first().is_some_and(|d| d.corners.is_some())
    }

    /// An error when `eye` cannot look through the wall (or one of its displays).
    pub fn check_eye(&self, eye: glam::Vec3) -> Result<()> {
        if self.plane.is_some() {
            self.camera_args(&Default::default(), eye)?;
        }
        if self.per_display() {
            for i in 0..self.displays.len() {
                self.display_camera_args(i, &Default::default(), eye)?;
            }
        }
        Ok(())
    }

    /// The camera flags of the off-axis frustum from `eye` through the wall's plane, on top
    /// of `base` (whose clip planes, if given, stay; else they follow the model as for any
    /// eye given on the command line). An error when the wall has no plane or the eye is not
    /// in front of it.
    pub fn camera_args(&self, base: &crate::camera::CameraSpec, eye: glam::Vec3) -> Result<crate::camera::CameraSpec> {
        let plane = self.plane.context("the wall has no plane to look through")?;
        let frustum = kooima(plane, (self.width, self.height), eye).context("the wall's plane")?;
        Ok(frustum.args(base, eye))
    }

    /// [`Wall::camera_args`] through display `i`'s own corners, for a frame of its own.
    pub fn display_camera_args(
        &self,
        i: usize,
        base: &crate::camera::CameraSpec,
        eye: glam::Vec3,
    ) -> Result<crate::camera::CameraSpec> {
        let d = &self.displays[i];
        let corners = d.corners.with_context(|| format!("display {} has no corners", d.name))?;
        let [x0, y0, x1, y1] = d.rect;
        let frustum = kooima(corners, (x1 - x0, y1 - y0), eye).with_context(|| format!("display {}", d.name))?;
        Ok(frustum.args(base, eye))
    }

    /// The wall's rightward direction in the world (a stereo pair's eyes lie along it): its
    /// plane's, or its first display's.
    pub fn right(&self) -> Option<glam::Vec3> {
        let p = self.plane.or(self.displays.first().and_then(|d| d.corners))?;
        Some((glam::Vec3::from(p.bottom_right) - glam::Vec3::from(p.bottom_left)).normalize())
    }

    /// A regular grid of `columns x rows` displays of `w x h` pixels, `bx` and `by` pixels
    /// of bezel between two of them.
    pub fn grid(columns: u32, rows: u32, w: u32, h: u32, bx: u32, by: u32) -> Result<Wall> {
        if columns == 0 || rows == 0 || w == 0 || h == 0 {
            bail!("columns, rows and display sizes must be at least 1");
        }
        if columns as u64 * rows as u64 > MAX_DISPLAYS {
            bail!("a grid of {columns}x{rows} displays; a wall has at most {MAX_DISPLAYS}");
        }
        // In u64, where no sum of u32 products can wrap.
        let side = |n: u32, size: u32, bezel: u32| n as u64 * size as u64 + (n as u64 - 1) * bezel as u64;
        let (fw, fh) = (side(columns, w, bx), side(rows, h, by));
        crate::cli::check_frame_size(fw, fh).context("the wall (displays and bezels) is too large")?;
        let displays = (0..rows)
            .flat_map(|r| (0..columns).map(move |c| (c, r)))
            .map(|(c, r)| {
                let (x0, y0) = (c * (w + bx), r * (h + by));
                // Each display owns half the bezel between it and a neighbour.
                let bezel = [
                    if c > 0 { bx - bx / 2 } else { 0 },
                    if r > 0 { by - by / 2 } else { 0 },
                    if c + 1 < columns { bx / 2 } else { 0 },
                    if r + 1 < rows { by / 2 } else { 0 },
                ];
                Display {
                    name: format!("{c}-{r}"),
                    rect: [x0, y0, x0 + w, y0 + h],
                    bezel,
                    corners: None,
                    window: WindowPlace::default(),
                }
            })
            .collect();
        Ok(Wall { width: fw as u32, height: fh as u32, displays, plane: None, eye: None })
    }

    fn listed(list: Vec<DisplayFile>) -> Result<Wall> {
        if list.len() as u64 > MAX_DISPLAYS {
            bail!("{} displays; a wall has at most {MAX_DISPLAYS}", list.len());
        }
        let (mut width, mut height) = (0u64, 0u64);
        let mut displays = Vec::with_capacity(list.len());
        for (i, d) in list.into_iter().enumerate() {
            let name = d.name.unwrap_or_else(|| i.to_string());
            let what = format!("display {} ({name})", i + 1);
            if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') {
                bail!("{what}: a name is letters, digits, - and _");
            }
            if displays.iter().any(|o: &Display| o.name == name) {
                bail!("{what}: the name {name} is used twice");
            }
            if d.width == 0 || d.height == 0 {
                bail!("{what}: width and height must be at least 1");
            }
            let bezel = match d.bezel {
                Bezel::All(b) => [b; 4],
                Bezel::Sides(s) => s,
            };
            if bezel[0] > d.x || bezel[1] > d.y {
                bail!("{what}: its bezel reaches left of or above the wall's pixel (0, 0)");
            }
            let (x1, y1) = (d.x as u64 + d.width as u64, d.y as u64 + d.height as u64);
            width = width.max(x1 + bezel[2] as u64);
            height = height.max(y1 + bezel[3] as u64);
            crate::cli::check_frame_size(width, height).with_context(|| format!("{what}: the wall is too large"))?;
            let rect = [d.x, d.y, x1 as u32, y1 as u32];
            displays.push(Display { name, rect, bezel, corners: d.corners, window: WindowPlace::default() });
        }
        Ok(Wall { width: width as u32, height: height as u32, displays, plane: None, eye: None })
    }

    /// Displays whose bezels overlap another display (the size was checked as the wall was
    /// laid out, by [`Wall::grid`] or [`Wall::listed`]).
    fn validate(&self) -> Result<()> {
        for (i, a) in self.displays.iter().enumerate() {
            for b in &self.displays[..i] {
                if intersection(a.outer(), b.outer()).is_some() {
                    bail!("displays {} and {} overlap (bezels included)", b.name, a.name);
                }
            }
        }
        Ok(())
    }

    /// The frame that covers the wall, bezels included.
    pub fn frame_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// One image per display (in the wall's order), and an overview of the whole wall as it
    /// looks from the room: the displays' pictures, everything else (bezels, gaps) black.
    pub fn split(&self, frame: &Image) -> (Vec<Image>, Image) {
        let mut overview = Image::new(self.width, self.height);
        overview.fill([0, 0, self.width, self.height], [0, 0, 0, 255]);
        let displays: Vec<Image> = self.displays.iter().map(|d| frame.crop(d.rect)).collect();
        for (d, img) in self.displays.iter().zip(&displays) {
            overview.blit(d.rect, &img.rgba).expect("a display lies inside its wall");
        }
        (displays, overview)
    }
}

/// An off-axis frustum as camera flags: the target, up, vertical field of view and shift.
struct Frustum {
    target: glam::Vec3,
    up: glam::Vec3,
    fovy: f32,
    shift: [f32; 2],
}

impl Frustum {
    fn args(&self, base: &crate::camera::CameraSpec, eye: glam::Vec3) -> crate::camera::CameraSpec {
        crate::camera::CameraSpec {
            view: crate::camera::ViewPreset::Front,
            eye: Some(eye),
            target: Some(self.target),
            up: Some(self.up),
            fovy: Some(self.fovy),
            shift: Some(self.shift),
            ..base.clone()
        }
    }
}

/// Kooima's generalised perspective projection as a camera: the eye looks along the normal
/// of the rectangle `p` (a picture of `size` pixels), up its vertical, with the vertical
/// field of view of its height and the shift that moves the window onto it.
fn kooima(p: WallPlane, size: (u32, u32), eye: glam::Vec3) -> Result<Frustum> {
    let (bl, br, tl) =
        (glam::Vec3::from(p.bottom_left), glam::Vec3::from(p.bottom_right), glam::Vec3::from(p.top_left));
    let (across, up) = (br - bl, tl - bl);
    let (w, h) = (across.length(), up.length());
    if !(w > 0.0 && h > 0.0 && eye.is_finite() && bl.is_finite() && br.is_finite() && tl.is_finite()) {
        bail!("three distinct finite corners are needed");
    }
    let (vr, vu) = (across / w, up / h);
    if vr.dot(vu).abs() > 1e-3 {
        bail!("not a rectangle (its bottom and left edges are not square)");
    }
    // Pixels are square: the rectangle must have the picture's shape.
    let (fw, fh) = (size.0 as f32, size.1 as f32);
    if ((w / h) / (fw / fh) - 1.0).abs() > 0.01 {
        bail!("{w} x {h} in the world is not the shape of its {}x{} pixels", size.0, size.1);
    }
    let vn = vr.cross(vu);
    let d = vn.dot(eye - bl);
    if d.is_nan() || d <= 0.0 {
        bail!("the eye {eye} is not in front of it (on the side its corners face, counter-clockwise)");
    }
    let (l, r) = (vr.dot(bl - eye), vr.dot(br - eye));
    let (b, t) = (vu.dot(bl - eye), vu.dot(tl - eye));
    let fovy = 2.0 * ((t - b) * 0.5 / d).atan().to_degrees();
    let shift = [(r + l) / (r - l), (t + b) / (t - b)];
    Ok(Frustum { target: eye - vn, up: vu, fovy, shift })
}

impl Display {
    /// The display's rectangle with its bezels.
    pub fn outer(&self) -> [u32; 4] {
        let [x0, y0, x1, y1] = self.rect;
        let [l, t, r, b] = self.bezel;
        [x0 - l, y0 - t, x1 + r, y1 + b]
    }
}

/// What the fuzz target `parse_wall` checks (the fuzzer and the workspace's regression test
/// over `fuzz/regressions/` run this): any bytes parse into a wall or are refused, never
/// panic, hang or allocate without bound, and a wall that parses has at most
/// [`MAX_DISPLAYS`] displays, each inside its frame, and splits a frame of its size.
pub fn fuzz_wall(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(wall) = Wall::parse(text) else { return };
    let (w, h) = wall.frame_size();
    assert!(wall.displays.len() as u64 <= MAX_DISPLAYS);
    for d in &wall.displays {
        let [x0, y0, x1, y1] = d.rect;
        assert!(x0 < x1 && y0 < y1 && x1 <= w && y1 <= h, "display {} outside its {w}x{h} wall", d.name);
    }
    // Splitting a frame allocates the frame and every display: only for small walls here.
    if (w as u64) * (h as u64) <= 1 << 20 {
        let (images, overview) = wall.split(&Image::new(w, h));
        assert_eq!((images.len(), overview.width, overview.height), (wall.displays.len(), w, h));
    }
    if let Some(eye) = wall.eye {
        let _ = wall.check_eye(eye);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wall_displays_skip_the_bezels() {
        let wall =
            Wall::parse("columns = 2\nrows = 2\ndisplay_width = 4\ndisplay_height = 3\nbezel_x = 2\nbezel_y = 1\n")
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
        assert!(Wall::parse("columns = 2\nrows = 2\ndisplay_width = 4\ndisplay_height = 3\nbezels = 1\n").is_err());
        assert_eq!(wall.displays[3].name, "1-1");
        assert_eq!(wall.displays[3].outer(), [5, 3, 10, 7]);
        assert_eq!(wall.displays[0].outer(), [0, 0, 5, 3]);
    }

    #[test]
    fn wall_sizes_do_not_wrap() {
        let wall = Wall::parse;
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

    const LISTED: &str = "[[display]]\nname = \"portrait\"\nx = 2\ny = 3\nwidth = 3\nheight = 5\nbezel = 2\n\
                          [[display]]\nx = 8\ny = 1\nwidth = 4\nheight = 2\nbezel = [1, 1, 3, 0]\n";

    #[test]
    fn listed_displays_take_any_arrangement_with_their_own_bezels() {
        let wall = Wall::parse(LISTED).unwrap();
        // The frame reaches the right edge of the second display's bezel (12 + 3) and the
        // bottom of the first's (8 + 2).
        assert_eq!(wall.frame_size(), (15, 10));
        let portrait = Display {
            name: "portrait".into(),
            rect: [2, 3, 5, 8],
            bezel: [2; 4],
            corners: None,
            window: Default::default(),
        };
        assert_eq!(wall.displays[0], portrait);
        let second = Display {
            name: "1".into(),
            rect: [8, 1, 12, 3],
            bezel: [1, 1, 3, 0],
            corners: None,
            window: Default::default(),
        };
        assert_eq!(wall.displays[1], second);
        let mut frame = Image::new(15, 10);
        for (i, px) in frame.rgba.chunks_mut(4).enumerate() {
            px.copy_from_slice(&[(i % 15) as u8, (i / 15) as u8, 7, 255]);
        }
        let (displays, overview) = wall.split(&frame);
        assert_eq!((displays[0].width, displays[0].height), (3, 5));
        assert_eq!(&displays[0].rgba[..4], &[2, 3, 7, 255]);
        assert_eq!(&displays[1].rgba[displays[1].rgba.len() - 4..], &[11, 2, 7, 255]);
        let px = |x: usize, y: usize| overview.rgba[(y * 15 + x) * 4..(y * 15 + x) * 4 + 4].to_vec();
        // Pictures where the displays are; bezels and the gaps between displays black.
        assert_eq!(px(4, 7), [4, 7, 7, 255]);
        assert_eq!(px(9, 2), [9, 2, 7, 255]);
        for (x, y) in [(1, 3), (5, 5), (7, 1), (12, 1), (14, 9), (0, 0)] {
            assert_eq!(px(x, y), [0, 0, 0, 255], "({x}, {y})");
        }
    }

    #[test]
    fn windows_are_placed_by_the_wall_and_by_each_display() {
        // The wall's [window] puts its pixel (0, 0) at (100, 50): each window at its display's place.
        let grid = Wall::parse(
            "columns = 2\nrows = 1\ndisplay_width = 10\ndisplay_height = 10\nbezel_x = 4\n[window]\nx = 100\ny = 50\n",
        )
        .unwrap();
        let at = |w: &Wall, i: usize| (w.displays[i].window.x, w.displays[i].window.y);
        assert_eq!((at(&grid, 0), at(&grid, 1)), ((Some(100), Some(50)), (Some(114), Some(50))));
        // A display's own table wins; the wall's fullscreen and monitor are kept where it is silent.
        let listed = Wall::parse(&format!(
            "[window]\nfullscreen = true\nmonitor = 1\n{LISTED}window = {{ x = 7, y = 8, monitor = \"DP-2\" }}\n"
        ))
        .unwrap();
        assert_eq!(
            listed.displays[0].window,
            WindowPlace { fullscreen: Some(true), monitor: Some(Monitor::Index(1)), ..Default::default() }
        );
        assert_eq!(
            listed.displays[1].window,
            WindowPlace { x: Some(7), y: Some(8), monitor: Some(Monitor::Name("DP-2".into())), fullscreen: Some(true) }
        );
        // Without a [window] table the window manager places them.
        assert_eq!(Wall::parse(LISTED).unwrap().displays[0].window, WindowPlace::default());
        let err = |text: &str| format!("{:#}", Wall::parse(text).unwrap_err());
        assert!(err(&format!("{LISTED}window = {{ x = 3 }}\n"))
            .contains("display 1: a window's position needs both x and y"));
        assert!(err("columns = 1\nrows = 1\ndisplay_width = 10\ndisplay_height = 10\n[window]\nx = 2147483647\ny = 0\n[display]\n").contains("not a valid"));
        assert!(err(
            "columns = 2\nrows = 1\ndisplay_width = 10\ndisplay_height = 10\n[window]\nx = 2147483647\ny = 0\n"
        )
        .contains("too large"));
        assert!(err("columns = 1\nrows = 1\ndisplay_width = 10\ndisplay_height = 10\n[window]\nsize = 3\n")
            .contains("unknown field"));
    }

    #[test]
    fn bad_display_lists_are_named() {
        let err = |text: &str| format!("{:#}", Wall::parse(text).unwrap_err());
        let overlap = LISTED.replace("x = 8", "x = 7");
        assert!(err(&overlap).contains("displays portrait and 1 overlap"), "{}", err(&overlap));
        assert!(err(&LISTED.replace("\"portrait\"", "\"a/b\"")).contains("display 1 (a/b): a name"));
        assert!(err(&LISTED.replace("\"portrait\"", "\"1\"")).contains("used twice"));
        assert!(err(&LISTED.replace("x = 2", "x = 1")).contains("left of or above"));
        assert!(err(&LISTED.replace("width = 3", "width = 0")).contains("at least 1"));
        assert!(err(&format!("columns = 2\n{LISTED}")).contains("not both"));
        assert!(err("rows = 2\n").contains("needs columns"));
        assert!(err(&LISTED.replace("x = 8", "x = 20000")).contains("too large"));
        let unknown = err(&LISTED.replace("bezel = 2", "bezels = 2"));
        assert!(
            unknown.starts_with("not a valid wall description at line 7, column 1: unknown field `bezels`"),
            "{unknown}"
        );
        assert_eq!(unknown.lines().count(), 1);
    }

    /// The camera of a wall's camera flags, with clip planes 0.1 and 100.
    fn camera_of(a: &crate::camera::CameraSpec) -> codec::view::Camera {
        codec::view::Camera {
            eye: a.eye.unwrap(),
            target: a.target.unwrap(),
            up: a.up.unwrap(),
            fovy: a.fovy.unwrap(),
            near: 0.1,
            far: 100.0,
            shift: a.shift.unwrap(),
        }
    }

    /// A wall in the world is a window: a point on its plane at wall pixel (x, y) projects
    /// to pixel (x, y) from any eye in front of it; an eye behind it is refused.
    #[test]
    fn a_planar_wall_is_a_window_from_any_eye() {
        let text = format!(
            "eye = [0.0, 0.0, 2.0]\n{LISTED}[plane]\nbottom_left = [-1.5, -1.0, 0.0]\nbottom_right = [3.0, -1.0, 0.0]\n\
             top_left = [-1.5, 2.0, 0.0]\n"
        );
        let wall = Wall::parse(&text).unwrap();
        assert_eq!(wall.frame_size(), (15, 10));
        let world = |x: f32, y: f32| glam::Vec3::new(-1.5 + 4.5 * x / 15.0, 2.0 - 3.0 * y / 10.0, 0.0);
        for eye in [glam::Vec3::new(0.0, 0.0, 2.0), glam::Vec3::new(-4.0, 3.0, 0.5), glam::Vec3::new(0.75, 0.5, 9.0)] {
            let vp = camera_of(&wall.camera_args(&Default::default(), eye).unwrap()).view_proj(15.0 / 10.0);
            for (x, y) in [(0.0, 0.0), (15.0, 10.0), (4.0, 7.5), (12.0, 1.0)] {
                let c = vp * world(x, y).extend(1.0);
                let (px, py) = ((c.x / c.w + 1.0) * 0.5 * 15.0, (1.0 - c.y / c.w) * 0.5 * 10.0);
                assert!((px - x).abs() < 1e-3 && (py - y).abs() < 1e-3, "eye {eye}: ({x}, {y}) -> ({px}, {py})");
            }
        }
        // The centred eye looks straight at the wall's centre: no shift.
        let centred = wall.camera_args(&Default::default(), glam::Vec3::new(0.75, 0.5, 3.0)).unwrap();
        assert!(centred.shift.unwrap().iter().all(|s| s.abs() < 1e-6));
        let behind = wall.camera_args(&Default::default(), glam::Vec3::new(0.0, 0.0, -1.0)).unwrap_err();
        assert!(format!("{behind:#}").contains("not in front of it"), "{behind:#}");
        let squashed = text.replace("top_left = [-1.5, 2.0, 0.0]", "top_left = [-1.5, 5.0, 0.0]");
        assert!(format!("{:#}", Wall::parse(&squashed).unwrap_err()).contains("shape"));
        let no_plane = format!("eye = [0.0, 0.0, 2.0]\n{LISTED}");
        assert!(format!("{:#}", Wall::parse(&no_plane).unwrap_err()).contains("needs the wall's plane"));
    }

    /// The bundled wall files load, and the irregular one's commented world placement fits
    /// its pixels.
    #[test]
    fn bundled_walls_load() {
        let grid = Wall::parse(include_str!("../../assets/wall.toml")).unwrap();
        assert_eq!((grid.frame_size(), grid.displays.len()), ((3 * 1920 + 2 * 60, 2 * 1080 + 60), 6));
        let text = include_str!("../../assets/wall-irregular.toml");
        let wall = Wall::parse(text).unwrap();
        assert_eq!((wall.frame_size(), wall.displays.len()), ((3160, 2300), 3));
        let setting = |l: &&str| {
            ["eye =", "[plane]", "bottom_left =", "bottom_right =", "top_left ="].iter().any(|p| l.starts_with(p))
        };
        let placed: String =
            text.lines().map(|l| l.strip_prefix("# ").filter(setting).unwrap_or(l)).map(|l| format!("{l}\n")).collect();
        let placed = Wall::parse(&placed).unwrap();
        assert!(placed.plane.is_some() && placed.eye.is_some());
    }

    /// Each display placed by its own corners is a window of its own: a point on it at its
    /// pixel (x, y) projects to (x, y) of its frame, whatever the angle between displays.
    #[test]
    fn displays_placed_at_an_angle_are_windows_of_their_own() {
        let text = "eye = [-1.5, 0.5, 1.5]\n\
                    [[display]]\nx = 0\ny = 0\nwidth = 8\nheight = 6\n\
                    corners = { bottom_left = [-3.0, -2.25, -3.0], bottom_right = [3.0, -2.25, -3.0], top_left = [-3.0, 2.25, -3.0] }\n\
                    [[display]]\nx = 8\ny = 0\nwidth = 8\nheight = 6\n\
                    corners = { bottom_left = [3.0, -2.25, -3.0], bottom_right = [3.0, -2.25, 3.0], top_left = [3.0, 2.25, -3.0] }\n";
        let wall = Wall::parse(text).unwrap();
        assert!(wall.per_display() && wall.placed());
        for i in 0..2 {
            let c = wall.displays[i].corners.unwrap();
            let (bl, br, tl) =
                (glam::Vec3::from(c.bottom_left), glam::Vec3::from(c.bottom_right), glam::Vec3::from(c.top_left));
            for eye in [glam::Vec3::new(-1.5, 0.5, 1.5), glam::Vec3::new(0.0, -1.0, 0.0)] {
                let vp =
                    camera_of(&wall.display_camera_args(i, &Default::default(), eye).unwrap()).view_proj(8.0 / 6.0);
                for (x, y) in [(0.0, 0.0), (8.0, 6.0), (3.0, 4.5)] {
                    let p = tl + (br - bl) * (x / 8.0) - (tl - bl) * (y / 6.0);
                    let q = vp * p.extend(1.0);
                    let (px, py) = ((q.x / q.w + 1.0) * 4.0, (1.0 - q.y / q.w) * 3.0);
                    assert!(
                        (px - x).abs() < 1e-3 && (py - y).abs() < 1e-3,
                        "display {i}, eye {eye}: ({x}, {y}) -> ({px}, {py})"
                    );
                }
            }
        }
        let mixed = text.replacen("corners = { bottom_left = [3.0", "# corners = { bottom_left = [3.0", 1);
        assert!(format!("{:#}", Wall::parse(&mixed).unwrap_err()).contains("every display has its corners"));
        let behind = text.replace("eye = [-1.5, 0.5, 1.5]", "eye = [4.0, 0.0, 0.0]");
        assert!(format!("{:#}", Wall::parse(&behind).unwrap_err()).contains("not in front of it"));
    }
}
