//! Smooth vertex normals, the one definition that rank 0 and the workers share.
//!
//! A worker shades a tile with normals it computes from the tile's own triangles
//! ([`vertex_normals`]). For most vertices that is the whole mesh's normal, bit for bit: a
//! tile keeps its triangles in the model's stream order, so a vertex whose every triangle lies
//! in the tile accumulates the same face normals in the same order. The others, the border
//! slots ([`BorderNormals::for_tile`]), would be shaded differently on either side of a tile
//! border, so rank 0 sends their whole-mesh normals with the tile; the test of which slots
//! those are ([`Boxes::whole_fan_in`]) sits with the tile sort's boxes. Duplicate slots (the
//! encoder's cuts at non-manifold vertices) are always border slots: a tile may hold one
//! copy of a vertex without the other.

use glam::Vec3;
use rayon::prelude::*;

use super::tile_sort::{Boxes, Tile, TileModel};
use super::Decoded;
use crate::view::TileGrid;

/// Area-weighted averages of the face normals around each *input* vertex, one per slot:
/// duplicate slots (`(slot, source)` pairs) share their source's normal, so the seams the
/// encoder cut at non-manifold vertices do not show in the shading. A vertex without
/// triangles, or whose faces cancel, gets +Z.
pub fn vertex_normals(positions: &[[f32; 3]], triangles: &[[u32; 3]], duplicates: &[(u32, u32)]) -> Vec<[f32; 3]> {
    let (source, acc) = face_normal_sums(positions, triangles, duplicates);
    (0..positions.len()).map(|s| unit(acc[source[s] as usize])).collect()
}

/// The sums [`vertex_normals`] normalizes: per slot, the slot's source (itself, or the slot
/// it duplicates), and at each source the face normals of its triangles added in triangle
/// order. A chunked file's border normals add these sums chunk after chunk
/// (`bft::chunked`).
pub fn face_normal_sums(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    duplicates: &[(u32, u32)],
) -> (Vec<u32>, Vec<Vec3>) {
    let mut source: Vec<u32> = (0..positions.len() as u32).collect();
    for &(slot, src) in duplicates {
        source[slot as usize] = source[src as usize];
    }
    let mut acc = vec![Vec3::ZERO; positions.len()];
    add_face_normals(positions, triangles, |s| source[s as usize], &mut acc);
    (source, acc)
}

/// Adds each triangle's face normal, in triangle order, at `at(v)` of `acc` for each of its
/// vertices `v` (positions indexed by `v`).
pub fn add_face_normals<'a>(
    positions: &[[f32; 3]],
    triangles: impl IntoIterator<Item = &'a [u32; 3]>,
    at: impl Fn(u32) -> u32,
    acc: &mut [Vec3],
) {
    for t in triangles {
        let [a, b, c] = t.map(|s| Vec3::from(positions[s as usize]));
        // The cross product's length is twice the area: larger faces weigh more.
        let n = (b - a).cross(c - a);
        for &s in t {
            acc[at(s) as usize] += n;
        }
    }
}

/// A sum of face normals as a unit normal: +Z where the faces cancel or there are none.
pub fn unit(sum: Vec3) -> [f32; 3] {
    sum.try_normalize().unwrap_or(Vec3::Z).to_array()
}

/// The whole mesh's vertex normals, and which slots are duplicates (or have them), whose
/// normals a tile never computes alone.
pub struct BorderNormals {
    normals: Vec<[f32; 3]>,
    duplicated: Vec<bool>,
}

impl BorderNormals {
    pub fn of(decoded: &Decoded) -> BorderNormals {
        let q = decoded.quantization();
        let positions: Vec<[f32; 3]> = decoded.positions.iter().map(|&p| q.dequantize(p)).collect();
        let mut duplicated = vec![false; positions.len()];
        for &(slot, src) in &decoded.duplicates {
            duplicated[slot as usize] = true;
            duplicated[src as usize] = true;
        }
        BorderNormals { normals: vertex_normals(&positions, &decoded.triangles, &decoded.duplicates), duplicated }
    }

    /// Replaces the normals of `slots` by the given ones and makes them border slots of every
    /// tile: a chunk's slots whose vertex other chunks share get the whole model's normal,
    /// which the chunk alone cannot compute (`bft::chunked`).
    pub fn set_border(&mut self, slots: impl IntoIterator<Item = (u32, [f32; 3])>) {
        for (slot, n) in slots {
            self.normals[slot as usize] = n;
            self.duplicated[slot as usize] = true;
        }
    }

    /// The bytes its tables take on the heap.
    pub fn heap_bytes(&self) -> usize {
        std::mem::size_of_val(&self.normals[..]) + self.duplicated.len()
    }

    /// The whole mesh's normal of `slot`.
    pub fn normal(&self, slot: u32) -> [f32; 3] {
        self.normals[slot as usize]
    }

    /// The normals `tile` needs from the whole mesh, as `(tile slot, normal)`: those of the
    /// slots that are duplicated or have a triangle outside the tile.
    /// A model with the file's normals needs none: its tiles carry them.
    pub fn for_tile(&self, model: &TileModel, boxes: &Boxes, tile: &Tile, grid: &TileGrid) -> Vec<(u32, [f32; 3])> {
        if !model.decoded.attributes.normals.is_empty() {
            return Vec::new();
        }
        let (c, r) = ((tile.index % grid.cols as usize) as u16, (tile.index / grid.cols as usize) as u16);
        tile.slots
            .iter()
            .enumerate()
            .filter(|(_, &s)| self.duplicated[s as usize] || !boxes.whole_fan_in(model, s, c, r))
            .map(|(i, &s)| (i as u32, self.normals[s as usize]))
            .collect()
    }

    /// [`Self::for_tile`] for every tile, in parallel.
    pub fn for_tiles(
        &self,
        model: &TileModel,
        boxes: &Boxes,
        tiles: &[Tile],
        grid: &TileGrid,
    ) -> Vec<Vec<(u32, [f32; 3])>> {
        tiles.par_iter().map(|tile| self.for_tile(model, boxes, tile, grid)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bft::tile_sort::{boxes_into, Sorter};
    use crate::bft::{decode, encode, Coding, EncodeOptions};
    use crate::view::Camera;
    use crate::Mesh;

    fn dequantized(d: &Decoded) -> Vec<[f32; 3]> {
        let q = d.quantization();
        d.positions.iter().map(|&p| q.dequantize(p)).collect()
    }

    /// A grid of quads on a bumpy surface, so that normals differ from vertex to vertex.
    fn bumpy(n: u32) -> Mesh {
        let mut positions = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
                positions.push([x, y, 0.1 * (7.0 * x).sin() * (5.0 * y).cos()]);
            }
        }
        let mut triangles = Vec::new();
        let v = |i: u32, j: u32| j * (n + 1) + i;
        for j in 0..n {
            for i in 0..n {
                triangles.push([v(i, j), v(i + 1, j), v(i + 1, j + 1)]);
                triangles.push([v(i, j), v(i + 1, j + 1), v(i, j + 1)]);
            }
        }
        Mesh::new(positions, triangles)
    }

    /// A worker's normals for a tile, with the border normals the master sends, equal the
    /// whole mesh's normals bit for bit on every slot of every tile.
    #[test]
    fn tile_normals_with_border_normals_equal_the_whole_meshs() {
        let enc = encode(&bumpy(24), EncodeOptions::default()).unwrap();
        let model = TileModel::from_bytes(&enc.bytes).unwrap();
        let full = BorderNormals::of(&model.decoded);
        let grid = TileGrid::new(320, 240, 4, 3).unwrap();
        let cam = Camera::framing(model.decoded.header.bbox_min, model.decoded.header.bbox_max, grid.aspect());
        let mut boxes = Boxes::default();
        boxes_into(&model, cam.view_proj(grid.aspect()), &grid, &mut boxes);
        let tiles = Sorter::new(Coding::Range).sort(&model, &boxes, &grid).unwrap();
        assert!(tiles.len() > 4, "the view should cover several tiles");
        let borders = full.for_tiles(&model, &boxes, &tiles, &grid);
        let mut inner = 0;
        for (tile, border) in tiles.iter().zip(&borders) {
            let d = decode(&tile.bytes).unwrap();
            let mut normals = vertex_normals(&dequantized(&d), &d.triangles, &d.duplicates);
            inner += normals.len() - border.len();
            for &(i, n) in border {
                normals[i as usize] = n;
            }
            for (i, &s) in tile.slots.iter().enumerate() {
                assert_eq!(
                    normals[i].map(f32::to_bits),
                    full.normal(s).map(f32::to_bits),
                    "tile {} slot {s}",
                    tile.index
                );
            }
        }
        assert!(inner > 0, "some slots must need no border normal");
    }

    #[test]
    fn duplicate_slots_share_the_normal_of_their_vertex() {
        // Two fans sharing only vertex 0 (a non-manifold vertex): the encoder duplicates it.
        let mesh = Mesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.5], [0.0, -1.0, 0.5]],
            triangles: vec![[0, 1, 2], [0, 3, 4]],
            ..Default::default()
        };
        let dec = decode(&encode(&mesh, EncodeOptions::default()).unwrap().bytes).unwrap();
        assert!(!dec.duplicates.is_empty(), "expected the shared vertex to be duplicated");
        let normals = vertex_normals(&dequantized(&dec), &dec.triangles, &dec.duplicates);
        for &(slot, src) in &dec.duplicates {
            assert_eq!(normals[slot as usize], normals[src as usize]);
        }
    }
}
