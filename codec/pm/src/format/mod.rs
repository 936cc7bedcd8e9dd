//! The `.dpm` file: a progressive mesh with every split operation compressed on its own
//! (section 4.2), so that any operation decodes from its starting address and a small context
//! the runtime has at hand ([`OpContext`]).
//!
//! ```text
//! offset  size  field
//! 0       8     magic  b"TESSDPM\x1a"
//! 8       2     version (u16 LE), currently 5 (2, whose operations decoded with floating-point
//!               steps, 3, without a node table, and 4, whose out-of-core pointers were coded
//!               as below without the pairs, are refused with a note to rebuild)
//! 10      2     header length H (u16 LE)
//! 12      H     header (little-endian, see `Header`)
//! 12+H    4     CRC-32 of the header bytes
//! then four sections, in this order: TABL, BASE, NODE, OPER, each
//!         4     tag (ASCII)
//!         4     payload length N (u32 LE)
//!         N     payload
//!         4     CRC-32 of the payload
//! ```
//!
//! * `TABL`: the shared probability tables, one static canonical Huffman code over byte
//!   symbols per context ([`crate::huffman`]), as one bit stream: per table a bit (0: flat,
//!   every symbol 8 bits; 1: the 256 code lengths follow, each the Elias gamma code of one plus
//!   the zigzag difference to the previous length, starting from 8, and after a length equal to
//!   the previous one the gamma code of one plus the number of further lengths that repeat it;
//!   version 3's runs took the bunny's tables from 4.8 to 3.2 kB).
//! * `BASE` (LEB128): per base vertex its FVID gap to the previous one, its quantized position
//!   (3) and octahedral normal (2), and its first operation's address plus one (0: none);
//!   then the base faces as FVID triples.
//! * `NODE`: empty in core; out of core the node table (`nodes.rs`).
//! * `OPER`: in core, the operations in pre-order of the split forest (an operation, the
//!   subtree of the child it stores first, the subtree of the other), each a byte-aligned bit
//!   stream. Out of core, the nodes one after the other, each the same pre-order over the
//!   operation subtrees that enter it (below).
//!
//! **Out of core (sections 4.1, 4.2.1, 5.7).** `tessera pm build --node-kb K` groups the
//! operations into a hierarchy of nodes of at most K kB (`hierarchy.rs`: inner nodes hold the
//! coarse operations) and the header counts the nodes. An operation's address is then
//! `node * 2^16 + local` (the paper's `o_ooc`), 32 bits, and every child that splits is coded by
//! its node's distance from this one (0: the same node; the children's nodes come later in
//! the node table's pre-order) and, in another node, its local address; in the same node the
//! child stored first follows directly and the second is coded as in core, its estimate the
//! pointer's when the first is in the node, else 0. Where both children enter the same other
//! node (version 5), the second's local address is not coded whole: there `v_l`'s part comes
//! directly before `v_u`'s (the node holds the subtrees entering it in pre-order, and no
//! descendant of `v_l` can enter it from elsewhere), so the distance between them is coded as
//! a pointer past `v_l`'s subtree, `s_avg` times its FVID count less one its estimate (the
//! in-core pointer's field and classes), added to the first's local address, or subtracted
//! when swapped. Measured: the bunny's layout from 1.032 to 0.867 bytes per operation over the
//! in-core file, the dragon's from 0.551 to 0.486 (a third of the pointers into other nodes
//! come in such pairs). A reader reads everything before the operations ([`NodeFile`]) and
//! then the nodes it needs, each checked by its own checksum. In 64 kB nodes the layout cost
//! 1.18 bytes per operation on the bunny (11 nodes) and 1.39 on the dragon (127 nodes) with
//! the paper's two children per node; see `hierarchy.rs` for what lowered it (the paper:
//! about 1; `cargo test -p tessera-codec --release --test pm_ooc -- --ignored --nocapture`),
//! mostly the local addresses of the pointers into other nodes.
//!
//! Every value is coded in a *context*: its field and a class computed from what the decoder
//! already has (the operation's context and the fields before it), each with its own tables.
//! A value becomes symbols in one of two ways: *groups*, 7 bits at a time, least significant
//! first, with a continuation bit, the group's byte significance (0, 1, 2+) selecting one of
//! three tables (the paper's contexts by byte significance); or *buckets*, one symbol for the
//! value below 16 and otherwise for its bit length and the 3 bits below the leading one,
//! followed by the other low bits uncoded (for wide values whose low bits are noise). With
//! `n = v_end - v`, the number of FVIDs `v` stands for, an operation holds, in this order:
//!
//! 1. criteria (section 4.2.3): `sin(alpha)` in 8 bits (rounded up), the geometric error and
//!    the attribute error log-coded at 2% (rounded up, `q * 2^((k-1)/35)`, 0 for 0), each as the
//!    zigzag difference to the parent operation's; `sin(alpha)` in 4 classes by the parent's
//!    value (groups);
//! 2. the head symbol, in 4 classes by `n` (2, 3, 4, more; groups):
//!    `c + 5 * (min(faces, 3) + 4 * (pattern + 3 * r))`, where `c` is the children code (0 none
//!    splits further, 1 both with `v_l`'s operation stored first, 2 `v_l` only, 3 `v_u` only, 4
//!    both with `v_u`'s stored first: the swap), `pattern` 0 or 1 when the first two faces are
//!    standard (below) and of opposite orientation, or there is one standard face, giving the
//!    first face's orientation, else 2, and `r` whether the radius differs from its prediction;
//! 3. when `r`: the radius, log-coded, as the zigzag difference to the smaller of the parent's
//!    radius and this geometric error, less one (groups);
//! 4. when both children split and `n > 4`: the split point, as the FVID count of the child
//!    stored first, less 2, in 6 classes by the bit length of `n` (groups; 4.2.1 and 4.2.2).
//!    Otherwise it is implied: `v_u = v + 1` when `v_l` is a leaf, `v_end - 1` when `v_u` is;
//! 5. the faces (4.2.2): when more than 2, their number less 3 (groups); then per face its form
//!    unless the pattern gives it (0/1: a standard face, with one corner in `v_l`'s FVID range,
//!    one in `v_u`'s and one outside `v`'s, and its orientation; 2: anything else, e.g.
//!    degenerate input faces). A standard face codes the offset of its corner to `v`, unless
//!    `v_l`'s range is one FVID, and of its corner to `v_u`, unless `v_u`'s range is one FVID
//!    (groups, in 7 classes: for the first face by the range's bit length, for the others by
//!    the previous face's offset, 0, 1 or more), and its third corner as the zigzag of its
//!    negative offset to `v` or positive offset to `v_end`; the faces are sorted by that, the
//!    first coded whole and the others as differences (buckets, 3 classes by the bit length of
//!    `n`). Form 2 has three zigzag offsets to `v` (groups);
//! 6. the position delta of `v_u` to `v` (quantized over the bounding box; buckets): the two
//!    axes least aligned with `v`'s normal first, in classes by the magnitude of the radius,
//!    then the third as the difference to its tangent-plane prediction
//!    `round(-(n_a d_a + n_b d_b) / n_c)` (in integers, below), in classes by the bit length of
//!    `|d_a| + |d_b|`;
//!    `v_l` keeps `v`'s position and normal (half-edge collapses), so its delta is always zero
//!    and not stored;
//! 7. the normal delta (2, octahedral), in classes by the magnitude of the attribute error
//!    (buckets): the error bounds the normal's change;
//! 8. when both children split: the address offset of the child stored second from the end of
//!    this operation, as the zigzag difference to `s_avg * (m - 1)`, `m` the FVID count of the
//!    child stored first (4.2.1; `s_avg` in 16.16 fixed point, the product rounded to a byte),
//!    in 6 classes by the bit length of `m` (groups).
//!
//! **Integer-exact decoding (version 3).** Decoding an operation takes integer steps only, so a
//! GPU decodes it bit for bit as the CPU does (`worker/src/pm_adapt/shaders/decode.wgsl`, tested against
//! [`Dpm::decode_op`]): every coded value fits in 32 bits (decoders refuse wider ones; the
//! encoder refuses 2^31 vertices or a 2 GiB operations section, which keep them there); the
//! log codes step by `2^(1/35)`, so a code `k` decodes as the entry `(k-1) % 35` of a per-file
//! table of 35 `f32` values ([`log_table`], correctly rounded products of the lower bound and
//! the format's constants) with `(k-1) / 35` added to its exponent bits ([`log_value`]); the
//! tangent-plane prediction takes the octahedral code as an integer vector along the normal
//! (no normalisation, which a GPU may round differently), shifted to 11 bits of magnitude, and
//! predicts nothing where a tangential delta is 2^18 steps or more, so its products fit in 32
//! bits; the pointer estimate multiplies integers (32-bit halves on a GPU). Version 2 used
//! `exp`, a normalised `f64` normal and an `f32` average; the integer steps did not change
//! the sizes (bunny 393,776 to 393,768 bytes, dragon 4,288,305 to 4,288,300). With the
//! nesting radii of the builder (`pm::build`) and the runs in the tables, version 3 takes
//! 392,134 bytes for the bunny (11.26 bytes per vertex) and 4,286,343 for the dragon (9.79).
//!
//! Compression follows the four steps of section 4.2 (`encode.rs`, one function per step):
//! operations with zero offsets give the first tables; the operations are compressed bottom-up
//! (children before parents, as the paper's reverse order), which fixes the offsets; the
//! tables are rebuilt from those symbols and everything is compressed again.
//!
//! **The `v_l`/`v_u` swap (section 4.2.4).** In the paper swapping `v_t` and `v_u` of a split
//! renumbers the FVIDs of both subtrees and costs nothing to signal. Here a vertex has the
//! position and normal of its FVID's finest vertex (the left child keeps `v`'s, half-edge
//! collapses, see [`super`]), so handing `v`'s FVID to the other child would move the coarse
//! vertex, altering the mesh; and the FVIDs are the decoded mesh's numbering. The swap is
//! therefore a per-operation coding choice that leaves the FVIDs alone: where both children
//! split further, the children code (4 instead of 1) says that `v_u`'s operation is stored
//! directly after this one and `v_l`'s is reached through the pointer, and the split point is
//! coded as the size of `v_u`'s range. Either way the pointer skips the subtree stored first,
//! and its estimate errs less over a smaller subtree; the split point is cheaper from the
//! smaller side. As in the paper the encoder decides by coded size: in each bottom-up
//! compression an operation whose children both split is coded both ways with that pass's
//! tables and keeps the shorter (ties: fewer bits, then unswapped). The first tables come from
//! the guess "smaller subtree first"; from tables built without swaps the swapped children
//! code would be too long for any swap to pay. On the bunny about half of those operations
//! swap, saving 0.03 bytes per vertex (0.02 on the dragon, measured against always storing
//! `v_l`'s operation first). The paper's swap also changes the FVIDs, and with them the face
//! corner offsets of the operation and its neighbours; here those stay as built.
//!
//! Decisions where the paper is silent or that differ from it:
//! * static canonical Huffman codes instead of arithmetic coding (every operation is padded to
//!   a byte; the padding is reported in [`DpmStats`]). Measured (`tessera pm build` prints it,
//!   from [`Encoded::symbol_bits`]): the entropy-coded symbols take 8.14 bytes per vertex on the
//!   bunny with these codes against 7.94 at their entropy, 7.69 against 7.57 on the dragon; an
//!   arithmetic coder could save at most those 0.20 and 0.12 bytes, and must then terminate
//!   every operation (some bits beyond the entropy, then the same byte padding), which takes
//!   most of it back, while Huffman decoding is a table lookup per symbol. A Huffman symbol costs at least a bit, so
//!   fields that are nearly always the same value are packed into one head symbol, and values
//!   the FVID ranges imply (children of ranges of 2 or 3 FVIDs, corners in a range of one, the
//!   split point of a range of 4) are not coded at all, nor is the second face's orientation
//!   when it is the opposite of the first's (the head's pattern);
//! * contexts beyond byte significance, from what the decoder knows when it reads a value (the
//!   classes above), and the tangent-plane prediction of the position (section 4.2.4 only
//!   predicts from `v`; the normal of `v` is in the context), in integers (above);
//! * the third corner's positive offset is taken to the end of `v`'s FVID range (`v_end`, part
//!   of the context: the left child's range ends at `v_u`, the right child's where `v`'s did)
//!   rather than to the next active vertex, which depends on the runtime state;
//! * the geometric and attribute errors are coded separately (they have different units here),
//!   and the radius too;
//! * the input vertex order
//!   ([`ProgressiveMesh::fvid_of_input`](super::ProgressiveMesh::fvid_of_input)) is not
//!   stored: the decoded mesh is numbered by FVID (`fvid_of_input` is the identity).
//!
//! Every context, prediction and implied value above was kept because it made the Stanford
//! bunny (`stanford/bunny_zipper_c3d.obj.gz`, 34,834 vertices) smaller, tables included; the
//! file went from 13.11 to 11.30 bytes per vertex with version 2 (the dragon from 11.58 to
//! 9.80). Contexts that did not pay for their tables on the bunny were left out: classes by
//! `n` for the geometric and attribute errors, by the parent's magnitude for them, by the first
//! tangential coordinate for the second, a normal delta predicted along the motion.
//!
//! # The code
//!
//! One concern per file: `header.rs` the container and the header; `quantize.rs` the
//! quantizers of positions, normals and criteria; `fields.rs` the fields of an operation with
//! their contexts and predictions; `symbols.rs` how values become Huffman-coded symbols;
//! `tables.rs` the shared tables (`TABL`); `op.rs` one operation, written and read; `decode.rs`
//! the decoder; `encode.rs` the encoder; `stats.rs` the size breakdown ([`DpmStats`]).

mod decode;
mod encode;
mod fields;
mod header;
mod hierarchy;
mod node_file;
mod nodes;
mod op;
mod quantize;
mod stats;
mod symbols;
mod tables;

pub use decode::{decode, Decoded, Dpm};
pub use encode::{
    encode, encode_owned, encode_with_progress, wrap_for_fuzzing, EncodeError, EncodeOptions, Encoded, EncodedFile,
};
pub use fields::{TABLES, TABLE_BASE};
pub use header::{DpmError, Header, MAGIC, MAX_NODES, MAX_OP_FACES, NODE_BYTES, VERSION};
pub use node_file::NodeFile;
pub use nodes::NodeInfo;
pub use op::{DecodedOp, OpContext};
pub use quantize::{log_table, log_value, quantized, LOG_STEPS, MAX_K};
pub use stats::DpmStats;
