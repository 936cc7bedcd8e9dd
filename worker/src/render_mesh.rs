//! [`RenderMesh`]: the geometry a worker uploads for a tile, built from decoded streams.

use codec::bft::normals::vertex_normals;
use codec::bft::Decoded;

/// GPU-ready geometry: float positions, smooth unit normals, optional vertex colours, and a
/// triangle index list.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RenderMesh {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    /// RGBA8 per vertex with alpha 255, or empty (drawn in the renderer's grey). Alpha 0
    /// marks vertices without a colour (a tile whose parts differ).
    pub colors: Vec<[u8; 4]>,
    pub indices: Vec<u32>,
}

impl RenderMesh {
    /// Flat-shaded buffers: three vertices of its own per triangle, each with the
    /// triangle's unit normal (+Z for a degenerate one).
    pub fn flat(triangles: &[[[f32; 3]; 3]]) -> RenderMesh {
        let mut out = RenderMesh {
            positions: Vec::with_capacity(triangles.len() * 3),
            normals: Vec::with_capacity(triangles.len() * 3),
            colors: Vec::new(),
            indices: (0..triangles.len() as u32 * 3).collect(),
        };
        for t in triangles {
            let [a, b, c] = t.map(glam::Vec3::from);
            let n = (b - a).cross(c - a).try_normalize().unwrap_or(glam::Vec3::Z).to_array();
            for p in [a, b, c] {
                out.positions.push(p.to_array());
                out.normals.push(n);
            }
        }
        out
    }

    /// Builds buffers from a decoded mesh (whose triangles it keeps), with the normals of
    /// [`codec::bft::normals::vertex_normals`], which rank 0 computes the same way.
    pub fn from_decoded(decoded: Decoded) -> RenderMesh {
        let q = decoded.quantization();
        let positions: Vec<[f32; 3]> = decoded.positions.iter().map(|&p| q.dequantize(p)).collect();
        let a = &decoded.attributes;
        let normals = if a.normals.is_empty() {
            vertex_normals(&positions, &decoded.triangles, &decoded.duplicates)
        } else {
            (0..positions.len()).map(|s| a.normal(s)).collect()
        };
        // Shading is opaque: a colour's alpha is not drawn.
        let colors = a.colors.iter().map(|c| [c[0], c[1], c[2], 255]).collect();
        // The decoder's triangles become the index list in place: copying them took 0.8-1.2
        // ms of the 24 ms that the dragon's 8x8 tiles took to become meshes on one core (a
        // scratch example, three alternated runs).
        let indices = bytemuck::allocation::cast_vec(decoded.triangles);
        RenderMesh { positions, normals, colors, indices }
    }

    /// Whether the normals are the file's (a stream with normals), which border normals
    /// must not replace.
    pub fn has_file_normals(decoded: &Decoded) -> bool {
        !decoded.attributes.normals.is_empty()
    }

    /// The meshes one after the other, as one (a tile's streams).
    pub fn concat<M: std::borrow::Borrow<RenderMesh>>(parts: &[M]) -> RenderMesh {
        let mut out = RenderMesh::default();
        let colored = parts.iter().any(|p| !p.borrow().colors.is_empty());
        for p in parts {
            let p = p.borrow();
            let base = out.positions.len() as u32;
            out.positions.extend_from_slice(&p.positions);
            out.normals.extend_from_slice(&p.normals);
            if colored {
                match p.colors.is_empty() {
                    true => out.colors.resize(out.positions.len(), [0; 4]),
                    false => out.colors.extend_from_slice(&p.colors),
                }
            }
            out.indices.extend(p.indices.iter().map(|&i| i + base));
        }
        out
    }

    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use codec::{bft, Mesh};
    use glam::Vec3;

    #[test]
    fn flat_square_has_up_normals_and_all_triangles() {
        let mesh = Mesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            ..Default::default()
        };
        let enc = bft::encode(&mesh, bft::EncodeOptions::default()).unwrap();
        let rm = RenderMesh::from_decoded(bft::decode(&enc.bytes).unwrap());
        assert_eq!(rm.triangle_count(), 2);
        for n in &rm.normals {
            assert!((Vec3::from(*n) - Vec3::Z).length() < 1e-6, "{n:?}");
        }
    }
}
