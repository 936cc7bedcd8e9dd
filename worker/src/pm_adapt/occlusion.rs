//! Occlusion culling one frame late (the paper's section 5.7 culls occluded nodes with the
//! depth of the frame before): a depth pyramid of the last frame's drawing, built here on the
//! host from the depth buffer the renderer read back, and tested against every refining
//! vertex's bounding sphere in the state update (`occluded` in `worker/src/pm_adapt/shaders/state.wgsl`). A
//! vertex whose sphere was hidden does not split, and a creator whose sphere was hidden lets
//! its vertices collapse, so hidden parts coarsen to what the frame before showed of them.
//! Spheres, not nodes: every vertex's sphere bounds all it refines into, so the test is the
//! node test at the finest grain and works for in-core files too.

use glam::{Mat4, Vec3, Vec4};

/// The side in pixels of the pyramid's finest cells.
pub const CELL: u32 = 4;

/// A max-depth pyramid of one rectangle of a frame, with the view-projection it was drawn
/// with: level 0 has a cell per `CELL` x `CELL` pixels, each level above halves both sides
/// (rounding up) down to one cell; a cell holds the farthest depth of its pixels (1 where
/// nothing was drawn). Laid out as `occ` of `state.wgsl` reads it.
#[derive(Clone, Debug)]
pub struct Occluder {
    pub(super) view_proj: Mat4,
    pub(super) frame: (u32, u32),
    pub(super) rect: [u32; 4],
    pub(super) words: Vec<u32>,
}

impl Occluder {
    /// The pyramid of `depth`, the depth buffer's values over `rect` of a `frame`-sized frame
    /// drawn with `view_proj`, row by row (`(x1 - x0) * (y1 - y0)` values).
    pub fn new(view_proj: Mat4, frame: (u32, u32), rect: [u32; 4], depth: &[f32]) -> Occluder {
        let (rw, rh) = ((rect[2] - rect[0]) as usize, (rect[3] - rect[1]) as usize);
        assert_eq!(depth.len(), rw * rh, "depth values for the rectangle");
        let cell = CELL as usize;
        let mut levels: Vec<(usize, usize, Vec<f32>)> = Vec::new();
        let (w, h) = (rw.div_ceil(cell).max(1), rh.div_ceil(cell).max(1));
        let mut base = vec![0f32; w * h];
        for (y, row) in depth.chunks_exact(rw.max(1)).enumerate() {
            let cells = &mut base[(y / cell) * w..(y / cell + 1) * w];
            for (x, &d) in row.iter().enumerate() {
                let c = &mut cells[x / cell];
                *c = c.max(d);
            }
        }
        levels.push((w, h, base));
        while levels.last().is_some_and(|&(w, h, _)| w > 1 || h > 1) {
            let (w, h, below) = levels.last().expect("non-empty");
            let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
            let mut up = vec![0f32; nw * nh];
            for y in 0..*h {
                for x in 0..*w {
                    let c = &mut up[(y / 2) * nw + x / 2];
                    *c = c.max(below[y * w + x]);
                }
            }
            levels.push((nw, nh, up));
        }
        let mut words = vec![levels.len() as u32];
        let mut at = 1 + 3 * levels.len();
        for (w, h, cells) in &levels {
            words.extend([*w as u32, *h as u32, at as u32]);
            at += cells.len();
        }
        for (_, _, cells) in &levels {
            words.extend(cells.iter().map(|d| d.to_bits()));
        }
        Occluder { view_proj, frame, rect, words }
    }
}

impl Occluder {
    /// The occlusion fields of the stages' `Params`: the view-projection, the rectangle (x0,
    /// y0, x1, y1), and the frame's width and height, the finest cell's side, 1 (on).
    pub(super) fn params(&self) -> ([[f32; 4]; 4], [f32; 4], [f32; 4]) {
        let size = [self.frame.0 as f32, self.frame.1 as f32, CELL as f32, 1.0];
        (self.view_proj.to_cols_array_2d(), self.rect.map(|v| v as f32), size)
    }

    /// Whether the box `lo..hi` was hidden in the pyramid's frame: the test `state.wgsl`'s
    /// `occluded` makes of a sphere's box, here of a node's box (out of core, hidden nodes
    /// are not required: [`codec::pm::NodeCache::schedule_culled`]).
    pub fn hides(&self, lo: Vec3, hi: Vec3) -> bool {
        let (mut min, mut max, mut zmin) = (glam::Vec2::splat(f32::MAX), glam::Vec2::splat(f32::MIN), f32::MAX);
        for k in 0..8 {
            let c = Vec3::new(
                if k & 1 != 0 { hi.x } else { lo.x },
                if k & 2 != 0 { hi.y } else { lo.y },
                if k & 4 != 0 { hi.z } else { lo.z },
            );
            let q = self.view_proj * Vec4::from((c, 1.0));
            if q.w <= 0.0 {
                return false;
            }
            min = min.min(q.truncate().truncate() / q.w);
            max = max.max(q.truncate().truncate() / q.w);
            zmin = zmin.min(q.z / q.w);
        }
        if zmin <= 0.0 {
            return false;
        }
        let (w, h) = (self.frame.0 as f32, self.frame.1 as f32);
        let (x0, x1) = ((min.x + 1.0) * 0.5 * w, (max.x + 1.0) * 0.5 * w);
        let (y0, y1) = ((1.0 - max.y) * 0.5 * h, (1.0 - min.y) * 0.5 * h);
        let [rx0, ry0, rx1, ry1] = self.rect.map(|v| v as f32);
        if x0 < rx0 || y0 < ry0 || x1 > rx1 || y1 > ry1 {
            return false;
        }
        let levels = self.words[0] as usize;
        let (mut level, mut side) = (0, CELL as f32);
        while level + 1 < levels && (x1 - x0).max(y1 - y0) > side {
            level += 1;
            side *= 2.0;
        }
        let [lw, lh, at] = [1, 2, 3].map(|i| self.words[i + 3 * level] as usize);
        let cell = |v: f32, lo: f32, n: usize| (((v - lo) / side) as usize).min(n - 1);
        let mut far = 0f32;
        for cy in cell(y0, ry0, lh)..=cell(y1, ry0, lh) {
            for cx in cell(x0, rx0, lw)..=cell(x1, rx0, lw) {
                far = far.max(f32::from_bits(self.words[at + cy * lw + cx]));
            }
        }
        zmin > far
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wall at depth 0.5 over the left half of a 64x32 frame: a box behind it is hidden, one
    /// in front of it, beside it or reaching past the pyramid's rectangle is not; the levels
    /// halve down to one cell.
    #[test]
    fn boxes_behind_the_drawn_depth_are_hidden() {
        let cam = codec::view::Camera {
            eye: Vec3::new(0.0, 0.0, 4.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fovy: 60.0,
            near: 1.0,
            far: 10.0,
            shift: [0.0; 2],
        };
        let (w, h) = (64u32, 32u32);
        let vp = cam.view_proj(w as f32 / h as f32);
        let depth: Vec<f32> = (0..w * h).map(|i| if i % w < w / 2 { 0.5 } else { 1.0 }).collect();
        let o = Occluder::new(vp, (w, h), [0, 0, w, h], &depth);
        // Levels of 16x8, 8x4, 4x2, 2x1 and 1x1 cells; the finest start after the table.
        assert_eq!(o.words[0], 5);
        assert_eq!(&o.words[1..4], &[16, 8, 16]);
        // The depth of a point at distance d along the view axis.
        let z = |d: f32| {
            let q = vp * Vec4::new(0.0, 0.0, 4.0 - d, 1.0);
            q.z / q.w
        };
        let (near_d, far_d) = ((1..100).map(|k| k as f32 * 0.09 + 1.0).find(|&d| z(d) > 0.5).unwrap(), 9.0);
        let small =
            |x: f32, d: f32| (Vec3::new(x - 0.05, -0.05, 4.0 - d - 0.05), Vec3::new(x + 0.05, 0.05, 4.0 - d + 0.05));
        let (lo, hi) = small(-0.5, far_d);
        assert!(o.hides(lo, hi), "behind the wall");
        let (lo, hi) = small(-0.5, near_d - 0.5);
        assert!(!o.hides(lo, hi), "in front of the wall");
        let (lo, hi) = small(0.5, far_d);
        assert!(!o.hides(lo, hi), "beside the wall");
        assert!(!o.hides(Vec3::new(-50.0, -0.1, -5.1), Vec3::new(-0.2, 0.1, -4.9)), "past the frame");
        assert!(!o.hides(Vec3::new(-0.1, -0.1, 3.0), Vec3::new(0.1, 0.1, 5.0)), "around the eye");
    }
}
