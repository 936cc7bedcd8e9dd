//! Tessera's codec: the mesh type and its loaders, quantization, the adaptive range coder,
//! and BFT mesh coding (Mitra & Chiueh). No MPI, no GPU: it builds and tests fast, and the
//! decoder can be fuzzed (`fuzz/`).
//!
//! ```
//! use codec::{bft, Mesh};
//! let mesh = Mesh {
//!     positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]],
//!     triangles: vec![[0, 1, 2], [2, 1, 3]],
//! };
//! let encoded = bft::encode(&mesh, bft::EncodeOptions::default()).unwrap();
//! let decoded = bft::decode(&encoded.bytes).unwrap().to_mesh();
//! assert_eq!(decoded.triangles.len(), 2);
//! ```

pub mod bft;
mod container;
mod csr;
pub mod huffman;
pub mod input;
pub mod load;
pub mod mesh;
pub mod pm;
pub mod rangecoder;
pub mod save;
pub mod tri_sort;
pub mod view;

pub use container::{Format, FormatError};
pub use load::{load_path, LoadError};
pub use mesh::{Mesh, MeshError, Quantization};
