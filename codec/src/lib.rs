//! Tessera's codec, everything about meshes and their files that needs no MPI and no GPU, so
//! that it builds and tests fast and its decoders can be fuzzed (`fuzz/`):
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

pub mod bft;
mod container;
mod csr;
pub mod fuzzing;
pub mod huffman;
pub mod input;
pub mod kind;
pub mod load;
pub mod mesh;
pub mod nsp;
pub mod pm;
pub mod rangecoder;
pub mod save;
pub mod tri_sort;
pub mod view;

pub use container::{Format, FormatError};
pub use load::{load_path, LoadError};
pub use mesh::{Mesh, MeshError, Quantization};
