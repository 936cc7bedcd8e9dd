//! The independent-triangle baseline of the bandwidth experiment (the paper's "Tri" and
//! "Tiled Tri"): every triangle travels as three float positions, 36 bytes, to every tile
//! its clipped screen box overlaps. Same projection, same boxes as the BFT tile sort, so
//! the two sorts differ only in what they emit.

use glam::Mat4;

use crate::view::{triangle_tile_boxes_into, ClipVertex, TileBox, TileGrid};

/// Bytes of one independent triangle: three `[f32; 3]` positions.
pub const TRIANGLE_BYTES: usize = 36;

/// The buffers of [`sort_into`], which a frame loop keeps as it keeps the BFT sort's.
#[derive(Default)]
pub struct TriBuffers {
    clip: Vec<ClipVertex>,
    boxes: Vec<TileBox>,
    /// Per tile, its triangles' bytes.
    pub tiles: Vec<Vec<u8>>,
}

/// Sorts independent triangles into per-tile buffers of `TRIANGLE_BYTES` each.
pub fn sort(positions: &[[f32; 3]], triangles: &[[u32; 3]], view_proj: Mat4, grid: &TileGrid) -> Vec<Vec<u8>> {
    let mut b = TriBuffers::default();
    sort_into(positions, triangles, view_proj, grid, &mut b);
    b.tiles
}

/// [`sort`] into the buffers of an earlier frame: fresh ones cost the dragon's Tri sort
/// their page faults every frame, and made its time 11.5-13 ms in one process and 19-20 ms
/// in another, against the BFT sort that keeps its own.
pub fn sort_into(positions: &[[f32; 3]], triangles: &[[u32; 3]], view_proj: Mat4, grid: &TileGrid, b: &mut TriBuffers) {
    triangle_tile_boxes_into(positions, triangles, view_proj, grid, &mut b.clip, &mut b.boxes);
    b.tiles.resize_with(grid.tiles(), Vec::new);
    b.tiles.iter_mut().for_each(Vec::clear);
    for (t, bx) in triangles.iter().zip(&b.boxes) {
        if bx.is_empty() {
            continue;
        }
        let mut bytes = [0u8; TRIANGLE_BYTES];
        for (k, &s) in t.iter().enumerate() {
            for (a, c) in positions[s as usize].iter().enumerate() {
                bytes[k * 12 + a * 4..k * 12 + a * 4 + 4].copy_from_slice(&c.to_le_bytes());
            }
        }
        for r in bx.r0..=bx.r1 {
            for c in bx.c0..=bx.c1 {
                b.tiles[r as usize * grid.cols as usize + c as usize].extend_from_slice(&bytes);
            }
        }
    }
}
