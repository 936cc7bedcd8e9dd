//! Occlusion culling one frame late (the paper's section 5.7 culls occluded nodes with the
//! depth of the frame before): a depth pyramid of the last frame's drawing, built here on the
//! host from the depth buffer the renderer read back, and tested against every refining
//! vertex's bounding sphere in the state update (`occluded` in `shaders/pm/state.wgsl`). A
//! vertex whose sphere was hidden does not split, and a creator whose sphere was hidden lets
//! its vertices collapse, so hidden parts coarsen to what the frame before showed of them.
//! Spheres, not nodes: every vertex's sphere bounds all it refines into, so the test is the
//! node test at the finest grain and works for in-core files too.

use glam::Mat4;

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
