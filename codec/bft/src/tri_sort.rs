//! The independent-triangle baseline of the bandwidth experiment (the paper's "Tri" and
//! "Tiled Tri"): every triangle travels as three float positions, 36 bytes, to every tile
//! its clipped screen box overlaps. Same projection, same boxes as the BFT tile sort, so
//! the two sorts differ only in what they emit.

use glam::Mat4;

use crate::view::{triangle_tile_boxes, TileGrid};

/// Bytes of one independent triangle: three `[f32; 3]` positions.
pub const TRIANGLE_BYTES: usize = 36;

/// Sorts independent triangles into per-tile buffers of `TRIANGLE_BYTES` each.
pub fn sort(positions: &[[f32; 3]], triangles: &[[u32; 3]], view_proj: Mat4, grid: &TileGrid) -> Vec<Vec<u8>> {
    let boxes = triangle_tile_boxes(positions, triangles, view_proj, grid);
    let mut tiles = vec![Vec::new(); grid.tiles()];
    for (t, b) in triangles.iter().zip(&boxes) {
        if b.is_empty() {
            continue;
        }
        let mut bytes = [0u8; TRIANGLE_BYTES];
        for (k, &s) in t.iter().enumerate() {
            for (a, c) in positions[s as usize].iter().enumerate() {
                bytes[k * 12 + a * 4..k * 12 + a * 4 + 4].copy_from_slice(&c.to_le_bytes());
            }
        }
        for r in b.r0..=b.r1 {
            for c in b.c0..=b.c1 {
                tiles[r as usize * grid.cols as usize + c as usize].extend_from_slice(&bytes);
            }
        }
    }
    tiles
}
