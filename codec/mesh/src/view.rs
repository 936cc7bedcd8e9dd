//! Camera, screen and tile-grid conventions (written in `DESIGN.md` and the README), and the
//! screen box of a triangle clipped to the view frustum.
//!
//! - Right-handed world; projection `Mat4::perspective_rh(fovy, W/H, near, far)` (depth 0..1)
//!   times `Mat4::look_at_rh(eye, target, up)`.
//! - Pixels: `px = (x_ndc + 1) / 2 * W`, `py = (1 - y_ndc) / 2 * H`, origin top-left.
//! - Tile `(i, j)` of a `C x R` grid covers pixels `[i*W/C, (i+1)*W/C) x [j*H/R, (j+1)*H/R)`
//!   (integer division); its index is `j*C + i`. The column of pixel `p` is therefore
//!   `((p + 1) * C - 1) / W`, the largest `i` with `i*W/C <= p`.

use glam::{Mat4, Vec3, Vec4};
use rayon::prelude::*;
use thiserror::Error;

/// Why a view or grid is unusable.
#[derive(Debug, Error, PartialEq)]
pub enum ViewError {
    #[error("screen size {0}x{1} must be at least 1x1")]
    ZeroSize(u32, u32),
    #[error("a {cols}x{rows} tile grid does not fit a {width}x{height} screen (at most one tile per pixel)")]
    GridTooLarge { cols: u32, rows: u32, width: u32, height: u32 },
    #[error("tile grid {0}x{1} must be at least 1x1")]
    ZeroGrid(u32, u32),
    #[error("camera eye and target are the same point")]
    EyeIsTarget,
    #[error("camera up vector is zero or parallel to the view direction")]
    BadUp,
    #[error("vertical field of view must be in (0, 180) degrees, not {0}")]
    Fovy(f32),
    #[error("clip planes must satisfy 0 < near < far, not near {0}, far {1}")]
    ClipPlanes(f32, f32),
    #[error("camera values must be finite")]
    NonFinite,
}

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub fovy: f32,
    pub near: f32,
    pub far: f32,
    /// Lens shift in normalised device coordinates: the image window moves by `shift[0]`
    /// half-widths right and `shift[1]` half-heights up, the eye and view direction staying,
    /// which makes the frustum off-axis (asymmetric). Any off-axis frustum (a wall display
    /// seen from a tracked eye, a stereo eye converging on a focal plane) is a symmetric one
    /// of the same vertical extent and aspect looking perpendicular to the image plane, so
    /// shifted. Zero for an ordinary camera.
    pub shift: [f32; 2],
}

impl Camera {
    pub const DEFAULT_FOVY: f32 = 45.0;

    /// The default camera: looks down -Z at the center of the bounding box's sphere, far
    /// enough back that the whole sphere is in view at this aspect ratio (width / height).
    pub fn framing(bbox_min: [f32; 3], bbox_max: [f32; 3], aspect: f32) -> Camera {
        let (lo, hi) = (Vec3::from(bbox_min), Vec3::from(bbox_max));
        let center = (lo + hi) * 0.5;
        let radius = ((hi - lo).length() * 0.5).max(1e-6);
        let half_v = (Self::DEFAULT_FOVY * 0.5).to_radians();
        let half_h = (half_v.tan() * aspect).atan();
        let dist = radius / half_v.min(half_h).sin();
        Camera {
            eye: center + Vec3::Z * dist,
            target: center,
            up: Vec3::Y,
            fovy: Self::DEFAULT_FOVY,
            near: (dist - radius) * 0.5,
            far: dist + radius * 2.0,
            shift: [0.0; 2],
        }
    }

    /// A three-quarter view: from `azimuth` degrees about the up axis (+Y) away from the
    /// default camera's side (+Z; 45 is a quarter turn towards +X) and 30 degrees above, the
    /// eye as close as keeps every corner of the bounding box inside the frustum with
    /// `margin` (a fraction of the half-width and half-height) to spare, so the model fills
    /// the frame rather than its bounding sphere.
    pub fn three_quarter(bbox_min: [f32; 3], bbox_max: [f32; 3], aspect: f32, azimuth: f32, margin: f32) -> Camera {
        let (lo, hi) = (Vec3::from(bbox_min), Vec3::from(bbox_max));
        let corners: Vec<[f32; 3]> = (0..8)
            .map(|i| {
                [
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                ]
            })
            .collect();
        Self::three_quarter_fit(bbox_min, bbox_max, &corners, aspect, azimuth, margin)
    }

    /// [`Camera::three_quarter`] fitted to `points` (the model's vertices, inside the box)
    /// rather than to the box's corners: closer, as a model rarely fills its box's silhouette.
    pub fn three_quarter_fit(
        bbox_min: [f32; 3],
        bbox_max: [f32; 3],
        points: &[[f32; 3]],
        aspect: f32,
        azimuth: f32,
        margin: f32,
    ) -> Camera {
        let (lo, hi) = (Vec3::from(bbox_min), Vec3::from(bbox_max));
        let center = (lo + hi) * 0.5;
        let (az, el) = (azimuth.to_radians(), 30f32.to_radians());
        let d = Vec3::new(az.sin() * el.cos(), el.sin(), az.cos() * el.cos());
        let right = Vec3::Y.cross(d).normalize();
        let up = d.cross(right);
        let tv = (Self::DEFAULT_FOVY * 0.5).to_radians().tan() * (1.0 - margin);
        let th = (Self::DEFAULT_FOVY * 0.5).to_radians().tan() * aspect * (1.0 - margin);
        // A point at offset p from the target is at depth dist - p.d: inside when its
        // sideways offsets over that depth are within the half-angles' tangents. Then the
        // target moves to centre the points' screen extent, and the distance is fitted again
        // (twice: the extent shifts a little as the depths change).
        let mut center = center;
        let mut dist = 0f32;
        for pass in 0..3 {
            let offsets = points.iter().map(|&p| Vec3::from(p) - center);
            dist = offsets
                .clone()
                .map(|p| p.dot(d) + (p.dot(right).abs() / th).max(p.dot(up).abs() / tv))
                .fold(1e-6f32, f32::max);
            if pass == 2 {
                break;
            }
            let (mut x, mut y) = ((f32::MAX, f32::MIN), (f32::MAX, f32::MIN));
            for p in offsets {
                let z = (dist - p.dot(d)).max(1e-6);
                let (sx, sy) = (p.dot(right) / z, p.dot(up) / z);
                (x, y) = ((x.0.min(sx), x.1.max(sx)), (y.0.min(sy), y.1.max(sy)));
            }
            center += (right * (x.0 + x.1) * 0.5 + up * (y.0 + y.1) * 0.5) * dist;
        }
        let depths = points.iter().map(|&p| dist - (Vec3::from(p) - center).dot(d));
        let (nearest, farthest) = depths.fold((f32::MAX, 0f32), |(a, b), z| (a.min(z), b.max(z)));
        let radius = ((hi - lo).length() * 0.5).max(1e-6);
        Camera {
            eye: center + d * dist,
            target: center,
            up: Vec3::Y,
            fovy: Self::DEFAULT_FOVY,
            near: (nearest * 0.5).max(radius * 1e-3),
            far: farthest * 1.5 + radius * 1e-3,
            shift: [0.0; 2],
        }
    }

    pub fn validate(&self) -> Result<(), ViewError> {
        let vals = [self.eye.to_array(), self.target.to_array(), self.up.to_array()];
        if !vals.iter().flatten().chain(&[self.fovy, self.near, self.far]).chain(&self.shift).all(|v| v.is_finite()) {
            return Err(ViewError::NonFinite);
        }
        let dir = self.target - self.eye;
        if dir.length_squared() == 0.0 {
            return Err(ViewError::EyeIsTarget);
        }
        if self.up.cross(dir).length_squared() <= 1e-12 * dir.length_squared() * self.up.length_squared() {
            return Err(ViewError::BadUp);
        }
        if !(self.fovy > 0.0 && self.fovy < 180.0) {
            return Err(ViewError::Fovy(self.fovy));
        }
        if !(self.near > 0.0 && self.far > self.near) {
            return Err(ViewError::ClipPlanes(self.near, self.far));
        }
        Ok(())
    }

    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        // The shift moves clip x by -shift_x * w (so NDC x by -shift_x): the window's centre
        // comes to the screen's.
        let shift = Mat4::from_translation(Vec3::new(-self.shift[0], -self.shift[1], 0.0));
        shift
            * Mat4::perspective_rh(self.fovy.to_radians(), aspect, self.near, self.far)
            * Mat4::look_at_rh(self.eye, self.target, self.up)
    }

    /// The eye `offset` world units along the camera's right axis, looking parallel to this
    /// one, with its window shifted so that its frustum meets this camera's at the plane
    /// `focus` units ahead (the target's distance for a stereo pair converging on it): the
    /// left eye of a pair `separation` apart is `stereo_eye(-separation / 2, ...)`.
    pub fn stereo_eye(&self, offset: f32, focus: f32, aspect: f32) -> Camera {
        let dir = (self.target - self.eye).normalize();
        let right = dir.cross(self.up).normalize();
        let half_width = focus * (self.fovy.to_radians() * 0.5).tan() * aspect;
        // A point on the focal plane straight ahead of this camera lies `-offset` to the
        // eye's right, at NDC x = -offset / half_width; the shift brings it back to where
        // this camera sees it.
        Camera {
            eye: self.eye + right * offset,
            target: self.target + right * offset,
            shift: [self.shift[0] - offset / half_width, self.shift[1]],
            ..*self
        }
    }
}

/// A conservative pixel rectangle `[x0, y0, x1, y1)` that holds the projection of the box
/// `lo..hi` under `view_proj` on a `width x height` screen, or `None` when the box is wholly
/// off screen to one side. A box reaching behind the eye plane gives the whole screen.
pub fn box_screen_rect(lo: [f32; 3], hi: [f32; 3], view_proj: Mat4, width: u32, height: u32) -> Option<[u32; 4]> {
    let (w, h) = (width as f32, height as f32);
    let mut min = [f32::INFINITY; 2];
    let mut max = [f32::NEG_INFINITY; 2];
    for corner in 0..8 {
        let pick = |axis: usize| if corner & (1 << axis) == 0 { lo[axis] } else { hi[axis] };
        let clip = view_proj * Vec4::new(pick(0), pick(1), pick(2), 1.0);
        if clip.w.is_nan() || clip.w <= 0.0 {
            return Some([0, 0, width, height]);
        }
        let (px, py) = ((clip.x / clip.w + 1.0) * 0.5 * w, (1.0 - clip.y / clip.w) * 0.5 * h);
        min = [min[0].min(px), min[1].min(py)];
        max = [max[0].max(px), max[1].max(py)];
    }
    if !(min[0].is_finite() && min[1].is_finite() && max[0].is_finite() && max[1].is_finite()) {
        return Some([0, 0, width, height]);
    }
    // One pixel of margin against rounding.
    let x0 = (min[0].floor() - 1.0).clamp(0.0, w) as u32;
    let y0 = (min[1].floor() - 1.0).clamp(0.0, h) as u32;
    let x1 = (max[0].ceil() + 1.0).clamp(0.0, w) as u32;
    let y1 = (max[1].ceil() + 1.0).clamp(0.0, h) as u32;
    (x0 < x1 && y0 < y1).then_some([x0, y0, x1, y1])
}

/// A screen of `width x height` pixels cut into `cols x rows` tiles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileGrid {
    pub width: u32,
    pub height: u32,
    pub cols: u32,
    pub rows: u32,
}

impl TileGrid {
    pub fn new(width: u32, height: u32, cols: u32, rows: u32) -> Result<TileGrid, ViewError> {
        if width == 0 || height == 0 {
            return Err(ViewError::ZeroSize(width, height));
        }
        if cols == 0 || rows == 0 {
            return Err(ViewError::ZeroGrid(cols, rows));
        }
        if cols > width || rows > height || cols > u16::MAX as u32 || rows > u16::MAX as u32 {
            return Err(ViewError::GridTooLarge { cols, rows, width, height });
        }
        Ok(TileGrid { width, height, cols, rows })
    }

    pub fn tiles(&self) -> usize {
        (self.cols * self.rows) as usize
    }

    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }

    /// Pixel rectangle `[x0, x1) x [y0, y1)` of tile `index`.
    pub fn tile_rect(&self, index: usize) -> [u32; 4] {
        let (i, j) = (index as u64 % self.cols as u64, index as u64 / self.cols as u64);
        let (w, h, c, r) = (self.width as u64, self.height as u64, self.cols as u64, self.rows as u64);
        [(i * w / c) as u32, (j * h / r) as u32, ((i + 1) * w / c) as u32, ((j + 1) * h / r) as u32]
    }

    /// The tile column of a pixel x coordinate (clamped to the screen).
    #[inline]
    pub fn col(&self, px: f32) -> u16 {
        // Clamped to >= 0 first, so the truncating cast is the floor (without a libm call).
        let p = (px.max(0.0) as u64).min(self.width as u64 - 1);
        (((p + 1) * self.cols as u64 - 1) / self.width as u64) as u16
    }

    #[inline]
    pub fn row(&self, py: f32) -> u16 {
        let p = (py.max(0.0) as u64).min(self.height as u64 - 1);
        (((p + 1) * self.rows as u64 - 1) / self.height as u64) as u16
    }

    /// The tiles covered by a pixel-space box.
    #[inline]
    pub fn tiles_of(&self, b: &PixelBox) -> TileBox {
        TileBox { c0: self.col(b.xmin), c1: self.col(b.xmax), r0: self.row(b.ymin), r1: self.row(b.ymax) }
    }
}

/// A box in pixel coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelBox {
    pub xmin: f32,
    pub xmax: f32,
    pub ymin: f32,
    pub ymax: f32,
}

/// An inclusive rectangle of tiles: columns `c0..=c1`, rows `r0..=r1`. The one empty box is
/// [`TileBox::EMPTY`]; build no other.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileBox {
    pub c0: u16,
    pub c1: u16,
    pub r0: u16,
    pub r1: u16,
}

impl TileBox {
    /// The empty box. Its corners are such that [`TileBox::union`] needs no test for it.
    pub const EMPTY: TileBox = TileBox { c0: u16::MAX, c1: 0, r0: u16::MAX, r1: 0 };

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.c0 > self.c1 || self.r0 > self.r1
    }

    #[inline]
    pub fn contains(&self, c: u16, r: u16) -> bool {
        c >= self.c0 && c <= self.c1 && r >= self.r0 && r <= self.r1
    }

    #[inline]
    pub fn union(&self, o: &TileBox) -> TileBox {
        // Boxes are either non-empty or `EMPTY`, whose corners lose every min and max.
        TileBox { c0: self.c0.min(o.c0), c1: self.c1.max(o.c1), r0: self.r0.min(o.r0), r1: self.r1.max(o.r1) }
    }

    /// The tiles in both boxes.
    #[inline]
    pub fn intersect(&self, o: &TileBox) -> TileBox {
        let b = TileBox { c0: self.c0.max(o.c0), c1: self.c1.min(o.c1), r0: self.r0.max(o.r0), r1: self.r1.min(o.r1) };
        if b.is_empty() {
            TileBox::EMPTY
        } else {
            b
        }
    }

    #[inline]
    pub fn area(&self) -> usize {
        if self.is_empty() {
            0
        } else {
            (self.c1 - self.c0 + 1) as usize * (self.r1 - self.r0 + 1) as usize
        }
    }

    /// Position of tile `(c, r)` in this box's row-major order.
    #[inline]
    pub fn index_of(&self, c: u16, r: u16) -> usize {
        (r - self.r0) as usize * (self.c1 - self.c0 + 1) as usize + (c - self.c0) as usize
    }
}

/// The pixel box of a triangle (clip-space corners) clipped to the view frustum, or `None`
/// when nothing of it is inside. Corners wholly inside take the fast path; the rest are
/// clipped against the six planes in homogeneous coordinates (Sutherland-Hodgman).
pub fn clipped_pixel_box(c: [Vec4; 3], width: u32, height: u32) -> Option<PixelBox> {
    let d = plane_distances;
    let ds = c.map(d);
    let mut inside = true;
    for p in 0..6 {
        if ds.iter().all(|d| d[p] < 0.0) {
            return None;
        }
        inside &= ds.iter().all(|d| d[p] >= 0.0);
    }
    let mut poly: [Vec4; 9] = [Vec4::ZERO; 9];
    let mut n = 3;
    poly[..3].copy_from_slice(&c);
    if !inside {
        let mut next = [Vec4::ZERO; 9];
        for p in 0..6 {
            let mut m = 0;
            for i in 0..n {
                let (a, b) = (poly[i], poly[(i + 1) % n]);
                let (da, db) = (d(a)[p], d(b)[p]);
                if da >= 0.0 {
                    next[m] = a;
                    m += 1;
                }
                if (da >= 0.0) != (db >= 0.0) {
                    next[m] = a + (b - a) * (da / (da - db));
                    m += 1;
                }
            }
            n = m;
            poly[..n].copy_from_slice(&next[..n]);
            if n == 0 {
                return None;
            }
        }
    }
    let mut b = PixelBox { xmin: f32::INFINITY, xmax: f32::NEG_INFINITY, ymin: f32::INFINITY, ymax: f32::NEG_INFINITY };
    for v in &poly[..n] {
        if v.w <= 0.0 {
            continue;
        }
        let (px, py) = pixel(*v, width, height);
        b.xmin = b.xmin.min(px);
        b.xmax = b.xmax.max(px);
        b.ymin = b.ymin.min(py);
        b.ymax = b.ymax.max(py);
    }
    (b.xmin <= b.xmax && b.ymin <= b.ymax).then_some(b)
}

/// A grid's tile column of every pixel column and tile row of every pixel row, so that a
/// vertex's tile costs two loads instead of two 64-bit divisions (measured: a third of the
/// projection's time on the dragon).
pub struct PixelTiles {
    grid: TileGrid,
    cols: Vec<u16>,
    rows: Vec<u16>,
}

impl PixelTiles {
    pub fn new(grid: &TileGrid) -> PixelTiles {
        PixelTiles {
            grid: *grid,
            cols: (0..grid.width).map(|x| grid.col(x as f32)).collect(),
            rows: (0..grid.height).map(|y| grid.row(y as f32)).collect(),
        }
    }

    /// [`TileGrid::col`] and [`TileGrid::row`] of a pixel.
    #[inline]
    fn tile(&self, px: f32, py: f32) -> (u16, u16) {
        // Clamped to >= 0 first, so the truncating cast is the floor, as in `col`.
        let x = (px.max(0.0) as usize).min(self.cols.len() - 1);
        let y = (py.max(0.0) as usize).min(self.rows.len() - 1);
        (self.cols[x], self.rows[y])
    }
}

/// What every triangle through a vertex needs to find its tile box without clipping: on
/// which side of each frustum plane the vertex lies, and its tile. Six bytes, so that the
/// triangle pass reads little; the clip-space position is recomputed in the rare case that
/// a triangle needs clipping.
#[derive(Clone, Copy, Debug)]
pub struct ClipVertex {
    /// Bit `p` set: outside plane `p` (distance < 0), in [`clipped_pixel_box`]'s order.
    outside: u8,
    /// Inside all six planes with `w > 0`: a triangle of three such vertices needs no
    /// clipping, and its box is the box of their tiles.
    fast: bool,
    /// Its pixel's tile column and row; meaningful only when `fast`.
    col: u16,
    row: u16,
}

impl ClipVertex {
    /// Inside all six planes, in front of the eye.
    #[inline]
    pub fn is_inside(&self) -> bool {
        self.fast
    }

    /// The vertex at world position `p`.
    #[inline]
    pub fn project(p: [f32; 3], view_proj: Mat4, tiles: &PixelTiles) -> ClipVertex {
        ClipVertex::new(clip_position(p, view_proj), tiles)
    }

    #[inline]
    pub fn new(clip: Vec4, tiles: &PixelTiles) -> ClipVertex {
        let d = plane_distances(clip);
        let (mut outside, mut inside) = (0u8, 0u8);
        for (p, d) in d.iter().enumerate() {
            outside |= ((*d < 0.0) as u8) << p;
            inside |= ((*d >= 0.0) as u8) << p;
        }
        let fast = inside == 0x3f && clip.w > 0.0;
        let (col, row) = if fast {
            let (px, py) = pixel(clip, tiles.grid.width, tiles.grid.height);
            tiles.tile(px, py)
        } else {
            (0, 0)
        };
        ClipVertex { outside, fast, col, row }
    }
}

/// A world position in clip space.
#[inline]
pub fn clip_position(p: [f32; 3], view_proj: Mat4) -> Vec4 {
    view_proj * Vec3::from(p).extend(1.0)
}

/// Plane distances, >= 0 inside: x+w, w-x, y+w, w-y, z, w-z (depth 0..1).
#[inline]
pub fn plane_distances(v: Vec4) -> [f32; 6] {
    [v.w + v.x, v.w - v.x, v.w + v.y, v.w - v.y, v.z, v.w - v.z]
}

/// The pixel of a clip-space point with `w > 0`.
#[inline]
fn pixel(v: Vec4, width: u32, height: u32) -> (f32, f32) {
    ((v.x / v.w + 1.0) * 0.5 * width as f32, (1.0 - v.y / v.w) * 0.5 * height as f32)
}

/// A triangle's tile box `[t]`: empty when all three corners are outside one plane, the box
/// of the corners' tiles when all three are inside every plane, and otherwise the tiles of
/// [`clipped_pixel_box`] of its clip-space corners, which `clip` gives. The first two cases
/// give what the third would (a pixel's column and row grow with its coordinates, so the
/// tile of the smallest x is the smallest column), without clipping or dividing per
/// triangle; a test checks them against it.
#[inline]
pub fn triangle_tile_box(v: [&ClipVertex; 3], clip: impl FnOnce() -> [Vec4; 3], grid: &TileGrid) -> TileBox {
    let [a, b, c] = v;
    if a.outside & b.outside & c.outside != 0 {
        TileBox::EMPTY
    } else if a.fast && b.fast && c.fast {
        TileBox {
            c0: a.col.min(b.col).min(c.col),
            c1: a.col.max(b.col).max(c.col),
            r0: a.row.min(b.row).min(c.row),
            r1: a.row.max(b.row).max(c.row),
        }
    } else {
        clipped_pixel_box(clip(), grid.width, grid.height).map_or(TileBox::EMPTY, |b| grid.tiles_of(&b))
    }
}

/// The tile box `[t]` of every triangle: vertices projected, each triangle clipped to the
/// frustum and its pixel box mapped to tiles; empty for triangles wholly outside. This is
/// pass 1 shared by the BFT tile sort, the independent-triangle sort and the benchmarks.
pub fn triangle_tile_boxes(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    view_proj: Mat4,
    grid: &TileGrid,
) -> Vec<TileBox> {
    let mut boxes = Vec::new();
    triangle_tile_boxes_into(positions, triangles, view_proj, grid, &mut Vec::new(), &mut boxes);
    boxes
}

/// [`triangle_tile_boxes`] into buffers a frame loop keeps (`clip` receives the projected
/// vertices), in parallel.
pub fn triangle_tile_boxes_into(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    view_proj: Mat4,
    grid: &TileGrid,
    clip: &mut Vec<ClipVertex>,
    boxes: &mut Vec<TileBox>,
) {
    let pixel_tiles = PixelTiles::new(grid);
    positions
        .par_iter()
        .with_min_len(4096)
        .map(|p| ClipVertex::project(*p, view_proj, &pixel_tiles))
        .collect_into_vec(clip);
    let clip = &*clip;
    triangles
        .par_iter()
        .with_min_len(4096)
        .map(|t| {
            let corners = || t.map(|s| clip_position(positions[s as usize], view_proj));
            triangle_tile_box(t.map(|s| &clip[s as usize]), corners, grid)
        })
        .collect_into_vec(boxes);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_every_pixel_once_for_uneven_sizes() {
        for (w, h, c, r) in [(1920, 1080, 8, 8), (1000, 7, 3, 7), (17, 13, 5, 4), (64, 64, 64, 64), (100, 1, 1, 1)] {
            let g = TileGrid::new(w, h, c, r).unwrap();
            for x in 0..w {
                let col = g.col(x as f32 + 0.5) as u32;
                let rect = g.tile_rect(col as usize);
                assert!(rect[0] <= x && x < rect[2], "pixel {x} in column {col} of {w}/{c}");
            }
            for y in 0..h {
                let row = g.row(y as f32 + 0.25) as u32;
                let rect = g.tile_rect((row * c) as usize);
                assert!(rect[1] <= y && y < rect[3]);
            }
        }
    }

    #[test]
    fn grid_and_camera_errors() {
        assert_eq!(TileGrid::new(0, 10, 1, 1), Err(ViewError::ZeroSize(0, 10)));
        // The default camera frames the box; a box to the side is off screen; one around the
        // eye covers it all.
        let cam = Camera::framing([0.0; 3], [1.0; 3], 2.0);
        let vp = cam.view_proj(2.0);
        let r = box_screen_rect([0.0; 3], [1.0; 3], vp, 200, 100).unwrap();
        assert!(r[0] > 0 && r[2] < 200 && r[1] < r[3], "{r:?}");
        assert_eq!(box_screen_rect([100.0, 0.0, 0.0], [101.0, 1.0, 1.0], vp, 200, 100), None);
        assert_eq!(box_screen_rect([-10.0; 3], [10.0; 3], vp, 200, 100), Some([0, 0, 200, 100]));
        assert!(matches!(TileGrid::new(8, 8, 16, 1), Err(ViewError::GridTooLarge { .. })));
        assert_eq!(TileGrid::new(8, 8, 0, 1), Err(ViewError::ZeroGrid(0, 1)));
        let mut cam = Camera::framing([0.0; 3], [1.0; 3], 1.0);
        assert_eq!(cam.validate(), Ok(()));
        cam.target = cam.eye;
        assert_eq!(cam.validate(), Err(ViewError::EyeIsTarget));
        let mut cam = Camera::framing([0.0; 3], [1.0; 3], 1.0);
        cam.up = cam.target - cam.eye;
        assert_eq!(cam.validate(), Err(ViewError::BadUp));
    }

    /// The eight corners of the box `lo..hi` in normalized device coordinates under `vp`.
    fn corners_ndc(lo: [f32; 3], hi: [f32; 3], vp: Mat4) -> Vec<glam::Vec4> {
        (0..8)
            .map(|i| {
                let p = Vec3::new(
                    if i & 1 == 0 { lo[0] } else { hi[0] },
                    if i & 2 == 0 { lo[1] } else { hi[1] },
                    if i & 4 == 0 { lo[2] } else { hi[2] },
                );
                let c = vp * p.extend(1.0);
                c / c.w
            })
            .collect()
    }

    #[test]
    fn default_camera_sees_the_whole_box() {
        let (lo, hi) = ([-1.0, 2.0, 0.5], [3.0, 2.5, 4.0]);
        for aspect in [0.5, 1.0, 16.0 / 9.0] {
            let cam = Camera::framing(lo, hi, aspect);
            for n in corners_ndc(lo, hi, cam.view_proj(aspect)) {
                assert!(n.x.abs() <= 1.0 && n.y.abs() <= 1.0 && n.z >= 0.0 && n.z <= 1.0, "{n:?}");
            }
        }
    }

    #[test]
    fn three_quarter_view_fills_the_frame_with_the_box() {
        let (lo, hi) = ([-1.0, 2.0, 0.5], [3.0, 2.5, 4.0]);
        for aspect in [0.5, 1.0, 16.0 / 9.0] {
            let cam = Camera::three_quarter(lo, hi, aspect, 45.0, 0.05);
            assert_eq!(cam.validate(), Ok(()));
            let mut widest = 0f32;
            for n in corners_ndc(lo, hi, cam.view_proj(aspect)) {
                assert!(n.x.abs() <= 0.951 && n.y.abs() <= 0.951 && n.z >= 0.0 && n.z <= 1.0, "{n:?}");
                widest = widest.max(n.x.abs()).max(n.y.abs());
            }
            // Some corner touches the margin: the box fills the frame.
            assert!(widest > 0.94, "aspect {aspect}: {widest}");
            // Seen from above, right and in front of the centre.
            let dir = cam.eye - cam.target;
            assert!(dir.x > 0.0 && dir.y > 0.0 && dir.z > 0.0);
        }
    }

    /// A camera at the origin looking down -Z, 60 degrees high.
    fn down_z() -> Camera {
        Camera { eye: Vec3::ZERO, target: -Vec3::Z, up: Vec3::Y, fovy: 60.0, near: 0.5, far: 50.0, shift: [0.0; 2] }
    }

    fn ndc(cam: &Camera, aspect: f32, p: Vec3) -> Vec3 {
        let c = cam.view_proj(aspect) * p.extend(1.0);
        c.truncate() / c.w
    }

    /// A shift moves the picture, not the eye: NDC positions move by exactly the shift.
    #[test]
    fn a_shift_moves_the_window() {
        let cam = down_z();
        let shifted = Camera { shift: [0.25, -0.5], ..cam };
        for p in [Vec3::new(0.3, -0.2, -4.0), Vec3::new(-1.0, 2.0, -9.0)] {
            let (a, b) = (ndc(&cam, 1.5, p), ndc(&shifted, 1.5, p));
            assert!((b - a - Vec3::new(-0.25, 0.5, 0.0)).abs().max_element() < 1e-5, "{a} {b}");
        }
        assert_eq!(Camera { shift: [f32::NAN, 0.0], ..cam }.validate(), Err(ViewError::NonFinite));
    }

    /// Stereo eyes converge on the focal plane: a point on it projects where the centre
    /// camera sees it for both eyes; a point beyond it has positive parallax (further right
    /// in the right eye), one before it negative.
    #[test]
    fn stereo_eyes_meet_on_the_focal_plane() {
        let cam = Camera {
            eye: Vec3::new(1.0, 2.0, 8.0),
            target: Vec3::new(0.5, 0.0, 0.0),
            up: Vec3::Y,
            fovy: 50.0,
            near: 0.5,
            far: 50.0,
            shift: [0.1, 0.0],
        };
        let aspect = 16.0 / 9.0;
        let dir = (cam.target - cam.eye).normalize();
        let focus = cam.eye.distance(cam.target);
        let (left, right) = (cam.stereo_eye(-0.2, focus, aspect), cam.stereo_eye(0.2, focus, aspect));
        assert!((left.eye.distance(right.eye) - 0.4).abs() < 1e-5);
        let side = dir.cross(Vec3::Y).normalize();
        let up = side.cross(dir);
        for (x, y) in [(0.0, 0.0), (1.0, -0.5), (-2.0, 1.0)] {
            let on = cam.eye + dir * focus + side * x + up * y;
            let (c, l, r) = (ndc(&cam, aspect, on), ndc(&left, aspect, on), ndc(&right, aspect, on));
            assert!((l.truncate() - c.truncate()).abs().max_element() < 1e-4, "{c} {l}");
            assert!((r.truncate() - c.truncate()).abs().max_element() < 1e-4, "{c} {r}");
            let far = cam.eye + (on - cam.eye) * 2.0;
            assert!(ndc(&right, aspect, far).x > ndc(&left, aspect, far).x + 0.01);
            let near = cam.eye + (on - cam.eye) * 0.5;
            assert!(ndc(&right, aspect, near).x < ndc(&left, aspect, near).x - 0.01);
        }
    }

    /// The per-vertex shortcuts of [`triangle_tile_box`] give what clipping every triangle
    /// gives: triangles wholly inside, wholly outside, across the near plane and through the
    /// eye, on uneven grids.
    #[test]
    fn triangle_tile_box_equals_clipping() {
        let cam = down_z();
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let (mut fast, mut clipped, mut empty) = (0, 0, 0);
        for (w, h, c, r) in [(1920, 1080, 8, 8), (1000, 7, 3, 7), (17, 13, 5, 4), (640, 480, 64, 48)] {
            let grid = TileGrid::new(w, h, c, r).unwrap();
            let vp = cam.view_proj(grid.aspect());
            let tiles = PixelTiles::new(&grid);
            for _ in 0..20_000 {
                // Mostly in view, some behind the eye and beyond the sides.
                let p = [(); 3].map(|_| Vec3::new(rnd() * 8.0 - 4.0, rnd() * 8.0 - 4.0, 1.0 - rnd() * 12.0));
                let clip = p.map(|p| vp * p.extend(1.0));
                let v = clip.map(|c| ClipVertex::new(c, &tiles));
                let want = clipped_pixel_box(clip, w, h).map_or(TileBox::EMPTY, |b| grid.tiles_of(&b));
                let got = triangle_tile_box([&v[0], &v[1], &v[2]], || clip, &grid);
                assert_eq!(got.is_empty(), want.is_empty(), "{p:?}");
                if !want.is_empty() {
                    assert_eq!(got, want, "{p:?} on {w}x{h} / {c}x{r}");
                }
                match (v.iter().all(|v| v.fast), want.is_empty()) {
                    (true, _) => fast += 1,
                    (false, false) => clipped += 1,
                    (false, true) => empty += 1,
                }
            }
        }
        assert!(fast > 5000 && clipped > 5000 && empty > 1000, "{fast} fast, {clipped} clipped, {empty} empty");
    }

    #[test]
    fn clipping_a_triangle_through_the_near_plane() {
        let cam = Camera {
            eye: Vec3::ZERO,
            target: -Vec3::Z,
            up: Vec3::Y,
            fovy: 90.0,
            near: 1.0,
            far: 100.0,
            shift: [0.0; 2],
        };
        let vp = cam.view_proj(1.0);
        let tri = [Vec3::new(0.0, 0.0, 0.5), Vec3::new(0.5, 0.0, -2.0), Vec3::new(0.0, 0.5, -2.0)];
        let c = tri.map(|p| vp * p.extend(1.0));
        let b = clipped_pixel_box(c, 100, 100).expect("partly visible");
        // The near-plane cut keeps only the part at depth >= 1: x and y within the far corners' spread.
        assert!(b.xmin >= 49.9 && b.xmax <= 100.0 && b.ymin >= 0.0 && b.ymax <= 50.1, "{b:?}");
        let behind = [Vec3::new(0.0, 0.0, 1.0), Vec3::new(1.0, 0.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
        assert_eq!(clipped_pixel_box(behind.map(|p| vp * p.extend(1.0)), 100, 100), None);
    }
}
