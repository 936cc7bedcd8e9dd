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
//! `protocol`, `transport` and [`chunk_cache`] need no GPU; the master uses them too.

pub mod chunk_cache;
pub mod gpu;
pub mod node;
pub mod pm_adapt;
pub mod protocol;
pub mod render;
pub mod transport;
#[cfg(test)]
mod wgsl_contract;

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
    /// Flat-shaded buffers: three vertices of its own per triangle, each with the
    /// triangle's unit normal (+Z for a degenerate one).
    pub fn flat(triangles: &[[[f32; 3]; 3]]) -> RenderMesh {
        let mut out = RenderMesh {
            positions: Vec::with_capacity(triangles.len() * 3),
            normals: Vec::with_capacity(triangles.len() * 3),
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

    /// Builds buffers from a decoded mesh, with the normals of
    /// [`codec::bft::normals::vertex_normals`], which rank 0 computes the same way.
    pub fn from_decoded(decoded: &Decoded) -> RenderMesh {
        let q = decoded.quantization();
        let positions: Vec<[f32; 3]> = decoded.positions.iter().map(|&p| q.dequantize(p)).collect();
        let normals = vertex_normals(&positions, &decoded.triangles, &decoded.duplicates);
        let indices = decoded.triangles.iter().flatten().copied().collect();
        RenderMesh { positions, normals, indices }
    }

    /// The meshes one after the other, as one (a tile's streams).
    pub fn concat(parts: &[RenderMesh]) -> RenderMesh {
        let mut out = RenderMesh::default();
        for p in parts {
            let base = out.positions.len() as u32;
            out.positions.extend_from_slice(&p.positions);
            out.normals.extend_from_slice(&p.normals);
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
        let rm = RenderMesh::from_decoded(&bft::decode(&enc.bytes).unwrap());
        assert_eq!(rm.triangle_count(), 2);
        for n in &rm.normals {
            assert!((Vec3::from(*n) - Vec3::Z).length() < 1e-6, "{n:?}");
        }
    }
}
