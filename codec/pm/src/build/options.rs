//! What every step of the builder shares: the options, the statistics, the error, and the
//! sizes that shape the work (hubs, chunks).

use thiserror::Error;

use crate::mesh::MeshError;
use crate::pm::format::MAX_OP_FACES;

/// A vertex with more live faces than this becomes a hub (see the module docs).
pub const HUB_FACES: usize = 512;

/// What [`build_with_stats`](super::build_with_stats) did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BuildStats {
    pub collapses: usize,
    /// Vertices that became hubs (see the module docs); none on ordinary meshes.
    pub hubs: usize,
    /// Steps of the simplification's inner loops: face-list entries read and heap entries
    /// pushed or popped. Linear in the face count whatever the valence (a test bounds it).
    pub work: u64,
    /// Chunks simplified (see [`BuildOptions::chunk_faces`]); 1 for a whole-model build.
    pub chunks: usize,
}

/// Why a progressive mesh cannot be built.
#[derive(Debug, Error, PartialEq)]
pub enum PmError {
    #[error("invalid input mesh: {0}")]
    Mesh(#[from] MeshError),
    /// A collapse would remove more faces than one operation of a `.dpm` file adds
    /// ([`MAX_OP_FACES`]): the faces of the edge between input vertices `a` and `b`
    /// (counted from 0).
    #[error(
        "vertices {a} and {b} share {faces} faces; a .dpm operation adds at most {MAX_OP_FACES} \
         (the collapse of their edge would remove them all)"
    )]
    OpFaces { a: u32, b: u32, faces: usize },
}

/// Chunk size of [`BuildOptions::default`]: models of more faces are simplified in chunks.
/// Measured on the dragon (871k faces, 2 cores, one run after the other): 64k-face chunks
/// simplify it 2.3x faster than one whole-model simplifier (3.5 s against 8.1 s, smaller
/// working sets and two chunks at a time) into 9.80 bytes/vertex against 9.79, adapting to
/// 0.2% more triangles for the same view; 16k-face chunks were about as fast (3.2 s) and cost
/// 0.4%, 128k-face chunks were slower (4.4 s).
pub const CHUNK_FACES: usize = 1 << 16;

/// How [`build_with_options`](super::build_with_options) works.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BuildOptions {
    /// A model of more faces than this is simplified in spatial chunks of at most this many
    /// faces (see the module docs), so the simplifier's memory follows the chunk, not
    /// the model; `0` never chunks.
    pub chunk_faces: usize,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self { chunk_faces: CHUNK_FACES }
    }
}
