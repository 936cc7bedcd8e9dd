//! Tessera's meshes and the files they come from, which every codec builds on: the mesh type
//! with quantization and bounding boxes ([`mesh`]), its loaders (OBJ, PLY, STL and glTF,
//! in core or streamed: [`load`]) and writers ([`save`]), bounded reads ([`input`]), which
//! Tessera model a file is ([`kind`]), compressed sparse rows ([`csr`]), and the camera and
//! tile conventions ([`view`]). No paper of its own: what the three papers' codecs share.

pub mod csr;
pub mod input;
pub mod kind;
pub mod load;
pub mod mesh;
pub mod save;
pub mod view;

pub use load::{load_path, LoadError};
pub use mesh::{Mesh, MeshError, Quantization};
