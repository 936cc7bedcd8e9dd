//! Breadth-First Traversal (BFT) mesh coding.
//!
//! This work is based on: T. Mitra and T. Chiueh, "A Breadth-First Approach to Efficient
//! Mesh Traversal", Graphics Hardware 1998, and "Compression-Domain Parallel Rendering"
//! (`shared/papers/bft-compression-domain-sort-first.txt`, section 2, Figure 2, and the
//! modification rules of Tables 1 and 2, which fixed the semantics below).
//!
//! # The frontier
//!
//! The frontier is a queue `Q` of vertex *slots* (decoded vertex indices), read as a
//! circular sequence: every pair `(Q[i], Q[i+1])`, and `(Q[last], Q[0])`, is a frontier edge.
//! The **current edge** is always `(l, r) = (Q[0], Q[1])`: `l` is the left vertex, `r` the
//! right vertex. The triangle found across the current edge is `(l, r, x)` in that
//! (counter-clockwise) order; `x` is the third vertex. The encoder looks for an unvisited
//! triangle that contains the directed edge `l -> r`.
//!
//! | command  | third vertex `x`              | triangle    | frontier after                         |
//! |----------|-------------------------------|-------------|----------------------------------------|
//! | `NEW`    | a new slot                    | `(l, r, x)` | pop `l`; push `l`; push `x`            |
//! | `RF<k>`  | `Q[2 + k]`                    | `(l, r, x)` | pop `l`; push `l`; push `x`            |
//! | `LF<k>`  | `Q[last - k]`                 | `(l, r, x)` | pop `l`; push `l`; push `x`            |
//! | `RF0`    | `Q[2]`                        | `(l, r, x)` | remove `r` (`l` stays current)         |
//! | `LF0`    | `Q[last]`                     | `(l, r, x)` | pop `l`                                |
//! | `NULL`   | -                             | -           | pop `l`; push `l` (skip the edge)      |
//! | `DL`     | -                             | -           | pop `l` (delete left)                  |
//! | `DR`     | -                             | -           | remove `r` (delete right)              |
//! | `ADD`    | a new slot, or `Q[last - k]`  | -           | push `x`                               |
//! | `SEED`   | three new slots `s, s+1, s+2` | `(s, s+2, s+1)` | clear; push `s`, `s+1`, `s+2`      |
//! | `CLEAR`  | -                             | -           | clear                                  |
//!
//! `NEW`, `RF<k>` and `LF<k>` change the frontier alike: the current edge `l -> r` becomes
//! `l -> x -> r` with the two new edges queued at the back, which is what makes the
//! traversal breadth-first. When `x` is already on the frontier (`RF<k>`, `LF<k>` with
//! `k >= 0`), `x` then appears twice: the frontier touches itself and is read as two loops
//! joined at `x`, each processed in turn as the queue rotates. `RF0`/`LF0` are the distinct
//! closing commands that remove the vertex whose fan the triangle completes; a generic
//! `RF<0>` (which keeps `r`) only ever appears in tile submeshes, where the vertices between
//! `r` and `x` were clipped away.
//!
//! These semantics are exactly the ones under which every row of Table 2 preserves the
//! paper's two synchronization invariants (a tile's frontier is the original frontier with
//! the vertices clipped for that tile removed, and its current edge is the closest unclipped
//! successor of the original one). For example, `NEW` with `l` kept and `x` clipped must
//! become `NULL`, which holds only if `NEW` re-queues `l`, and `RF0` with `r` clipped and
//! `l` kept emits nothing, which holds only if `RF0` leaves `l` current.
//!
//! The offsets count frontier entries, so they can be rewritten per tile from counters of
//! unclipped pushes (section 3.1.3) without scanning the frontier.
//!
//! # Topology the paper leaves open
//!
//! * **Components.** `SEED` starts a component: it clears the frontier and codes a triangle
//!   with three new slots. The encoder seeds again when no frontier vertex has an unvisited
//!   triangle left.
//! * **Boundaries and holes.** A current edge without an unvisited triangle is a null edge:
//!   the encoder deletes `l` (`DL`) or `r` (`DR`) when all of that vertex's triangles are
//!   visited, and otherwise skips the edge (`NULL`) to come back to it a round later.
//! * **Non-manifold input, flipped orientation.** If the third vertex was seen before but is
//!   no longer on the frontier, the encoder gives it a fresh slot that *duplicates* the old
//!   one (a `NEW` whose position is copied); the duplicate table maps it back, so decoding
//!   is exact on vertex indices. If a full rotation of the frontier finds no triangle while
//!   vertices still have unvisited ones (their fans are not reachable across frontier edges),
//!   the encoder reseeds.
//! * **Degenerate triangles** with a repeated index cannot be enumerated across an edge;
//!   they are stored as *loose* triangles (three slot indices each), after the traversal.
//!   Zero-area triangles with distinct indices and duplicate triangles are ordinary input.
//! * **Unused vertices** are not coded (as in Draco); [`EncodeStats::unused_vertices`] counts
//!   them.
//!
//! # Coding
//!
//! Commands, offsets and positions are coded with the adaptive binary range coder of
//! [`crate::rangecoder`], in two streams: connectivity and geometry. Command contexts are the
//! previous command's class and how many triangles `l` and `r` already have (their
//! visited degree), all known to the decoder before it reads the command, and all computable
//! again per tile, so a tile stream is produced by re-coding rewritten commands, not by
//! running the traversal again. Positions are quantized over the bounding box and predicted
//! by the parallelogram rule across the current edge (`l + r - apex`, with the apex of the
//! triangle that created the edge, kept per frontier entry); residuals are coded by their
//! bit length, sign and mantissa.
//!
//! A stream may instead be prefix-coded ([`Coding::Prefix`], `prefix.rs`): the same symbols,
//! with static Huffman tables built for the stream and stored at its head, and a command's
//! table chosen by the previous command alone. Without the frontier's degrees in its context
//! a decoder reads each command before it carries out the one before, and keeps no degrees.
//! The first prefix coding ([`Coding::PrefixByDegree`], header byte 41 = 1) chose the table
//! by the previous command's class and `l`'s degree; it still reads. The tile sort writes its
//! tiles prefix-coded when asked, because it codes every tile anew each frame; `tessera
//! encode` writes range-coded files unless asked for prefix-coded ones
//! ([`EncodeOptions::coding`]).

// The paths the modules were written with when they were one crate (`crate::mesh`,
// `crate::bft::...`), kept for the crate's own files.
pub(crate) use crate as bft;
#[allow(unused_imports)]
pub(crate) use tessera_entropy::{container, huffman, rangecoder, Format, FormatError};
#[allow(unused_imports)]
pub(crate) use tessera_mesh::{csr, input, kind, load, mesh, view, LoadError, Mesh, MeshError, Quantization};

pub mod attributes;
pub mod chunked;
mod command;
mod decode;
mod encode;
mod file;
mod format;
mod frontier;
mod model;
pub mod normals;
mod prefix;
pub mod tile_sort;
mod tile_writer;
pub mod tri_sort;

pub use command::Command;
pub use decode::{decode_ops, Decoded, Op};
pub use encode::{encode, encode_with_progress, EncodeOptions, EncodeStats, Encoded};
pub use file::{decode, decode_file};
pub use format::{wrap_for_fuzzing, AttributeFlags, BftError, Coding, Header, Stats, MAGIC, READS, VERSION};
