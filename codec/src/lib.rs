//! Tessera's codec, everything about meshes and their files that needs no MPI and no GPU, so
//! that it builds and tests fast and its decoders can be fuzzed (`fuzz/`). It is the face of
//! a crate per paper and the two they build on (`codec/*/`), whose modules it re-exports:
//! - the mesh type, its loaders and writers ([`load`], [`save`]), bounded reads and model-kind
//!   detection ([`input`], [`kind`]), quantization and bounding boxes ([`mesh`]);
//! - entropy coding: the adaptive binary range coder ([`rangecoder`]) and canonical Huffman
//!   codes ([`huffman`]);
//! - the container both file formats share, with its one error type ([`FormatError`]);
//! - BFT mesh coding (Mitra & Chiueh; [`bft`]): encoder, decoder, the `.bft` format, the
//!   compression-domain tile sort with Table 2, and the vertex normals master and workers share;
//! - the camera and tile conventions ([`view`]) and the independent-triangle sort ([`tri_sort`]);
//! - dependency-free progressive meshes (Derzapf & Guthe; [`pm`]): builder, `.dpm` coder and
//!   the CPU reference adaptation that the GPU adaptation is tested against;
//! - the nSP-tree store ([`nsp`]): a lossless out-of-core progressive codec (kd-tree geometry
//!   coding inside an nSP-tree), its `.nsp` format, build, cell decoding and view selection;
//! - what the fuzz targets check ([`fuzzing`]).
//!
//! ```
//! use codec::{bft, Mesh};
//! let mesh = Mesh {
//!     positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]],
//!     triangles: vec![[0, 1, 2], [2, 1, 3]],
//!     ..Default::default()
//! };
//! let encoded = bft::encode(&mesh, bft::EncodeOptions::default()).unwrap();
//! let decoded = bft::decode(&encoded.bytes).unwrap().to_mesh();
//! assert_eq!(decoded.triangles.len(), 2);
//! ```

// The codecs, a crate per paper, and what they build on, re-exported so that the paths
// users and tests write (`codec::bft::encode`, `codec::Mesh`) are the crate's.
pub use tessera_bft as bft;
pub use tessera_bft::tri_sort;
pub use tessera_entropy::{huffman, rangecoder};
pub use tessera_mesh::{input, kind, load, mesh, save, view};
pub use tessera_nsp as nsp;
pub use tessera_pm as pm;

pub mod fuzzing;

pub use tessera_entropy::{Format, FormatError};
pub use tessera_mesh::{load_path, LoadError};
pub use tessera_mesh::{Mesh, MeshError, Quantization};
