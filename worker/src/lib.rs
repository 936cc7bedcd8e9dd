//! Tessera's worker side (MPI ranks >= 1): turn a decoded BFT (sub)mesh into the vertex and
//! index buffers the renderer draws ([`RenderMesh`]), render them headless with wgpu, and adapt
//! progressive meshes on the GPU.
//!
//! The GPU modules depend on each other one way, each only on those above it:
//!
//! 1. [`gpu`]: the adapter, device and queue ([`gpu::Gpu`]), error scopes, submission waits and
//!    read-backs, and the binding tables every bind group is built from. Nothing of Tessera.
//! 2. [`render`]: the tile renderer on a `Gpu`. It draws a [`RenderMesh`] it uploads, or an
//!    [`render::AdaptedMesh`]: named buffers already on the device.
//! 3. [`pm_adapt`]: the progressive-mesh adaptation on a `Gpu` (Algorithms 1 to 5 of Derzapf
//!    and Guthe). It hands the renderer an `AdaptedMesh` and uses nothing else of it.
//! 4. [`node`]: the worker loop, which drives the three for the [`protocol`] messages it
//!    receives over a [`transport`], and whose errors are a [`node::WorkerError`].
//!
//! `protocol` and `transport` need no GPU; the master uses them too.

pub mod gpu;
pub mod node;
pub mod pm_adapt;
pub mod protocol;
pub mod render;
pub mod transport;
#[cfg(test)]
mod wgsl_contract;

use codec::bft::Decoded;
use glam::Vec3;

/// GPU-ready geometry: float positions, smooth unit normals, and a triangle index list.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RenderMesh {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub indices: Vec<u32>,
}

impl RenderMesh {
    /// Builds buffers from a decoded mesh. Normals are area-weighted averages of the face
    /// normals around each *input* vertex: duplicate slots share their source's normal, so
    /// the seams the encoder cut at non-manifold vertices do not show in the shading.
    pub fn from_decoded(decoded: &Decoded) -> RenderMesh {
        let q = decoded.quantization();
        let positions: Vec<[f32; 3]> = decoded.positions.iter().map(|&p| q.dequantize(p)).collect();
        let mut source: Vec<u32> = (0..positions.len() as u32).collect();
        for &(slot, src) in &decoded.duplicates {
            source[slot as usize] = source[src as usize];
        }
        let mut acc = vec![Vec3::ZERO; positions.len()];
        for t in &decoded.triangles {
            let [a, b, c] = t.map(|s| Vec3::from(positions[s as usize]));
            // The cross product's length is twice the area: larger faces weigh more.
            let n = (b - a).cross(c - a);
            for &s in t {
                acc[source[s as usize] as usize] += n;
            }
        }
        let normals = (0..positions.len())
            .map(|s| acc[source[s] as usize].try_normalize().unwrap_or(Vec3::Z).to_array())
            .collect();
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

    #[test]
    fn duplicate_slots_share_the_normal_of_their_vertex() {
        // Two fans sharing only vertex 0 (a non-manifold vertex): the encoder duplicates it.
        let mesh = Mesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.5], [0.0, -1.0, 0.5]],
            triangles: vec![[0, 1, 2], [0, 3, 4]],
        };
        let enc = bft::encode(&mesh, bft::EncodeOptions::default()).unwrap();
        let dec = bft::decode(&enc.bytes).unwrap();
        assert!(!dec.duplicates.is_empty(), "expected the shared vertex to be duplicated");
        let rm = RenderMesh::from_decoded(&dec);
        for &(slot, src) in &dec.duplicates {
            assert_eq!(rm.normals[slot as usize], rm.normals[src as usize]);
        }
    }
}
