//! Tessera's worker side (MPI ranks >= 1): turn a decoded BFT (sub)mesh into the vertex and
//! index buffers the renderer draws, and render them headless with wgpu ([`render`]). The GPU
//! progressive-mesh adaptation builds on this crate.

pub mod node;
pub mod pm_gpu;
pub mod protocol;
pub mod render;
pub mod transport;

use codec::bft::normals::vertex_normals;
use codec::bft::Decoded;

/// GPU-ready geometry: float positions, smooth unit normals, and a triangle index list.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RenderMesh {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub indices: Vec<u32>,
}

impl RenderMesh {
    /// Builds buffers from a decoded mesh, with the normals of
    /// [`codec::bft::normals::vertex_normals`], which rank 0 computes the same way.
    pub fn from_decoded(decoded: &Decoded) -> RenderMesh {
        let q = decoded.quantization();
        let positions: Vec<[f32; 3]> = decoded.positions.iter().map(|&p| q.dequantize(p)).collect();
        let normals = vertex_normals(&positions, &decoded.triangles, &decoded.duplicates);
        let indices = decoded.triangles.iter().flatten().copied().collect();
        RenderMesh { positions, normals, indices }
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
        };
        let enc = bft::encode(&mesh, bft::EncodeOptions::default()).unwrap();
        let rm = RenderMesh::from_decoded(&bft::decode(&enc.bytes).unwrap());
        assert_eq!(rm.triangle_count(), 2);
        for n in &rm.normals {
            assert!((Vec3::from(*n) - Vec3::Z).length() < 1e-6, "{n:?}");
        }
    }
}
