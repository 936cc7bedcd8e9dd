//! Chunked `.bft` files (version 3): a model cut into spatially coherent chunks, each an
//! ordinary `.bft` stream, behind a directory that a reader classifies without touching the
//! chunks' bytes.
//!
//! The BFT paper sorts one command stream per frame, so the master's work and memory grow
//! with the model. Here a frame skips the chunks outside the frustum unread, forwards a chunk
//! that lands wholly in one tile verbatim (its bytes copied, never decoded), and tile-sorts
//! only the chunks that straddle tile borders or frustum planes (`sort.rs`). A file of one
//! chunk is today's model, and today's single-stream files (versions 1 and 2) are still read.
//!
//! # Layout
//!
//! ```text
//! offset  size  field
//! 0       8     magic  b"TESSBFT\x1a" (as versions 1 and 2)
//! 8       2     version (u16 LE) = 3
//! 10      2     header length H (u16 LE)
//! 12      H     header (`ChunkedHeader`, little-endian)
//! 12+H    4     CRC-32 of the header
//!         64*C  directory: one `ChunkEntry` per chunk, C = the header's chunk count
//!         4     CRC-32 of the directory
//! then each chunk, in directory order, back to back:
//!         B     an ordinary `.bft` file (version 2, range-coded) on the model's quantization
//!         D     the chunk's border table (below), ending in its CRC-32
//! ```
//! Nothing follows the last chunk. The directory holds, per chunk, its byte offset and the
//! lengths of its two parts, its triangle and slot counts, its first triangle and first slot
//! in the whole model's numbering (running sums, checked), and its quantized bounding box.
//! There is no checksum over the whole file, so that a reader can open a file larger than
//! memory and read only the chunks a view needs; each chunk's own checksums guard it when it
//! is read.
//!
//! # Numbering and borders
//!
//! Every input triangle is in exactly one chunk. A chunk's slots are numbered after the
//! previous chunk's, so the whole file decodes (`decode_all`) to one slot array and one
//! triangle array, as a single stream would. A vertex used by triangles of several chunks has
//! a slot in each: the **border table** of a chunk lists such slots (and every slot of such a
//! vertex, duplicates inside the chunk included), each with
//! - a link: 0 for the vertex's first slot in the file, else 1 + that first slot, so that
//!   decoding the whole file welds the copies back into one input vertex;
//! - the vertex's normal over the whole model, which no chunk can compute alone.
//!
//! `LEB128 count`, then per entry `LEB128 slot gap` (increasing local slots; the first gap is
//! the slot itself) and `LEB128 link`, then `count` normals as three `f32` LE, then the CRC-32
//! of all that.
//!
//! # Normals
//!
//! A worker computes a stream's normals from its own triangles ([`super::normals`]), and that
//! is the model's normal for a slot whose every triangle is in the stream. A slot on a chunk
//! border has triangles in other chunks, so its normal comes from the border table. The
//! model normal of a vertex is the unit vector of the sum, chunk after chunk in file order,
//! of each chunk's sum of its face normals in stream order ([`super::normals::face_normal_sums`]):
//! for a vertex inside one chunk that is exactly what the worker computes, and every rank
//! uses the same stored value for the others, so a frame does not depend on how the chunks
//! were distributed. (The sums are grouped by chunk, so a chunked file's normals may differ in
//! the last bit from the single-stream file's.)

mod border;
mod encode;
mod error;
mod file;
mod header;
pub mod lod;
mod partition;
pub mod sort;
mod source;
mod spill;

pub use super::format::is_chunked;
pub use border::{oct_decode, oct_encode, Border};
pub use encode::{
    encode_chunked, encode_mesh_chunked, ChunkOptions, ChunkedEncoded, EncodeChunkError, Progress, TriangleSink,
};
pub use file::{wrap_for_fuzzing, ChunkedFile};
pub use header::{ChunkEntry, ChunkedHeader, ENTRY_LEN};
pub use source::{ChunkSource, FileSource};

/// The version of chunked files.
pub const VERSION: u16 = super::format::CHUNKED_VERSION;
/// The version of chunked files with a level-of-detail hierarchy ([`lod`]).
pub const LOD_VERSION: u16 = super::format::LOD_VERSION;
/// The default number of triangles per chunk (see `ChunkOptions::chunk_triangles`).
pub const DEFAULT_CHUNK_TRIANGLES: u32 = 4096;
/// `tessera encode`'s default: a model of at most this many triangles (and at most 4M
/// vertices, one partition bucket) is one stream, and only a larger one is chunked
/// (`ChunkOptions::one_stream_up_to`). Chunks cost bytes (the dragon 1.41x at 4096 triangles
/// a chunk) and buy culling: rank 0 sorts a single stream whole every frame, 43-47 ns a
/// triangle alone (the dragon's 871k in 37.6-40.9 ms) and 138-182 ms for the dragon beside a
/// worker on 2 cores, so at this size 0.18-0.8 s a frame whatever the view shows, where a
/// chunked file sorts what is in view (docs/results.md, "Chunked models and scale").
pub const ONE_STREAM_MAX_TRIANGLES: u64 = 4 << 20;
