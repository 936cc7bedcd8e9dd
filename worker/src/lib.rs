//! Tessera's worker side (MPI ranks >= 1): turn a decoded BFT (sub)mesh into the vertex and
//! index buffers the renderer draws ([`RenderMesh`]), render them headless with wgpu, and adapt
//! progressive meshes on the GPU.
//!
//! The GPU modules depend on each other one way, each only on those above it:
//!
//! 1. [`gpu`]: the adapter, device and queue ([`gpu::Gpu`]), error scopes, submission waits and
//!    read-backs, and bind groups built from the binding lists `reflect` reads from each
//!    shader. Nothing of Tessera.
//! 2. [`render`]: the tile renderer on a `Gpu`. It draws a [`RenderMesh`] it uploads, or an
//!    [`render::AdaptedMesh`]: named buffers already on the device.
//! 3. [`pm_adapt`]: the progressive-mesh adaptation on a `Gpu` (Algorithms 1 to 5 of Derzapf
//!    and Guthe). It hands the renderer an `AdaptedMesh` and uses nothing else of it.
//! 4. [`node`]: the worker loop, which drives the three for the messages of the
//!    `tessera-protocol` crate it receives over a [`transport`], and whose errors are a
//!    [`node::WorkerError`].
//!
//! `transport`, [`chunk_cache`] and [`pixels`] (tile pixels coded for the wire) need no
//! GPU; the master and the display ranks use them too.

pub mod chunk_cache;
pub mod gpu;
pub mod node;
pub mod pixels;
pub mod pm_adapt;
mod reflect;
pub mod render;
mod render_mesh;
pub mod transport;
#[cfg(test)]
mod wgsl_contract;

pub use render_mesh::RenderMesh;
