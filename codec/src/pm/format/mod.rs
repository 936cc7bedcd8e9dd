//! The `.dpm` file: a progressive mesh with every split operation compressed on its own
//! (section 4.2), so that any operation decodes from its starting address and a small context
//! the runtime has at hand ([`OpContext`]).
//!
//! ```text
//! offset  size  field
//! 0       8     magic  b"TESSDPM\x1a"
//! 8       2     version (u16 LE), currently 2
//! 10      2     header length H (u16 LE)
//! 12      H     header (little-endian, see `Header`)
//! 12+H    4     CRC-32 of the header bytes
//! then three sections, in this order: TABL, BASE, OPER, each
//!         4     tag (ASCII)
//!         4     payload length N (u32 LE)
//!         N     payload
//!         4     CRC-32 of the payload
//! ```
//!
//! * `TABL`: the shared probability tables, one static canonical Huffman code over byte
//!   symbols per context ([`crate::huffman`]), as one bit stream: per table a bit (0: flat,
//!   every symbol 8 bits; 1: the 256 code lengths follow, each the Elias gamma code of one plus
//!   the zigzag difference to the previous length, starting from 8).
//! * `BASE` (LEB128): per base vertex its FVID gap to the previous one, its quantized position
//!   (3) and octahedral normal (2), and its first operation's address plus one (0: none);
//!   then the base faces as FVID triples.
//! * `OPER`: the operations in pre-order of the split forest (an operation, the subtree of the
//!   child it stores first, the subtree of the other), each a byte-aligned bit stream.
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
//!    the attribute error log-coded at 2% (rounded up, `q * 1.02^(k-1)`, 0 for 0), each as the
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
//!    `round(-(n_a d_a + n_b d_b) / n_c)`, in classes by the bit length of `|d_a| + |d_b|`;
//!    `v_l` keeps `v`'s position and normal (half-edge collapses), so its delta is always zero
//!    and not stored;
//! 7. the normal delta (2, octahedral), in classes by the magnitude of the attribute error
//!    (buckets): the error bounds the normal's change;
//! 8. when both children split: the address offset of the child stored second from the end of
//!    this operation, as the zigzag difference to `s_avg * (m - 1)`, `m` the FVID count of the
//!    child stored first (4.2.1), in 6 classes by the bit length of `m` (groups).
//!
//! Compression follows the four steps of section 4.2: operations with zero offsets give the
//! first tables; the operations are compressed bottom-up (in reverse pre-order), which fixes
//! the offsets; the tables are rebuilt from those symbols and everything is compressed again.
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
//!   predicts from `v`; the normal of `v` is in the context). The prediction uses basic `f64`
//!   arithmetic on the decoded normal (IEEE 754 rounds those exactly), so encoder and decoder
//!   agree on every platform;
//! * the third corner's positive offset is taken to the end of `v`'s FVID range (`v_end`, part
//!   of the context: the left child's range ends at `v_u`, the right child's where `v`'s did)
//!   rather than to the next active vertex, which depends on the runtime state;
//! * the geometric and attribute errors are coded separately (they have different units here),
//!   and the radius too;
//! * the input vertex order ([`ProgressiveMesh::fvid_of_input`]) is not stored: the decoded
//!   mesh is numbered by FVID (`fvid_of_input` is the identity).
//!
//! Every context, prediction and implied value above was kept because it made the Stanford
//! bunny (`stanford/bunny_zipper_c3d.obj.gz`, 34,834 vertices) smaller, tables included; the
//! file went from 13.11 to 11.30 bytes per vertex with version 2 (the dragon from 11.58 to
//! 9.80). Contexts that did not pay for their tables on the bunny were left out: classes by
//! `n` for the geometric and attribute errors, by the parent's magnitude for them, by the first
//! tangential coordinate for the second, a normal delta predicted along the motion.

mod decode;
mod fields;
mod header;
mod op;
mod quantize;
mod stats;
mod symbols;
mod tables;

pub use decode::{decode, Decoded, Dpm};
pub use header::{DpmError, Header, MAGIC, VERSION};
pub use op::{DecodedOp, OpContext};
pub use quantize::quantized;
pub use stats::DpmStats;

use rayon::prelude::*;

use super::{ProgressiveMesh, SplitTree, NONE};
use crate::container::put_varint;
use crate::huffman::Table;
use fields::*;
use header::LAYOUT;
use op::{classify, write_op, FaceCode, OpData};
use quantize::{fit_header, oct_encode, quantize_criteria, quantize_position};
use symbols::OpWriter;
use tables::{every_symbol, write_tables};

/// Encoder settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EncodeOptions {
    /// Bits per position coordinate over the bounding box (8 to 24).
    pub position_bits: u8,
    /// Bits per octahedral normal coordinate (4 to 16).
    pub normal_bits: u8,
}

impl Default for EncodeOptions {
    fn default() -> Self {
        EncodeOptions { position_bits: 16, normal_bits: 10 }
    }
}

/// An encoded file and, per split of the input (in its order), the operation's address in the
/// operations section and its context.
#[derive(Clone, Debug)]
pub struct Encoded {
    pub bytes: Vec<u8>,
    pub header: Header,
    pub addresses: Vec<usize>,
    pub contexts: Vec<OpContext>,
    /// The Huffman-coded symbols of the tables' counts (before the final choice of swaps):
    /// their bits with the file's codes, and their entropy, the bits an ideal arithmetic
    /// coder with the same static tables would spend on them (before its per-operation
    /// termination). The gap is what arithmetic coding could save.
    pub symbol_bits: (f64, f64),
}

fn invalid(msg: &str) -> DpmError {
    DpmError::InvalidMesh(msg.into())
}

/// Encodes a progressive mesh from [`super::build`](fn@super::build) (or any with the same
/// structure: every split reachable from the base vertices, FVID ranges as in section 3.2).
pub fn encode(pm: &ProgressiveMesh, opts: EncodeOptions) -> Result<Encoded, DpmError> {
    let mut h = fit_header(pm, opts)?;
    let n = pm.positions.len();
    if pm.normals.len() != n || pm.criteria.len() != pm.splits.len() {
        return Err(invalid("normals or criteria do not match the vertices or splits"));
    }
    if pm.base_vertices.len() + pm.splits.len() != n {
        return Err(invalid("base vertices and splits do not add up to the vertices"));
    }
    if pm.base_vertices.windows(2).any(|w| w[0] >= w[1]) || pm.base_vertices.first().is_some_and(|&v| v != 0) {
        return Err(invalid("base vertices must ascend from FVID 0"));
    }
    if pm.splits.iter().any(|s| s.v as usize >= n || s.v_u as usize >= n) {
        return Err(invalid("split FVID out of range"));
    }
    let in_range = |t: &[u32; 3]| t.iter().all(|&f| (f as usize) < n);
    if !pm.base_faces.iter().all(in_range) || !pm.splits.iter().all(|s| s.faces.iter().all(in_range)) {
        return Err(invalid("face FVID out of range"));
    }
    let qpos: Vec<[u32; 3]> = pm.positions.iter().map(|&p| quantize_position(p, &h)).collect();
    let qnrm: Vec<[u32; 2]> = pm.normals.iter().map(|&v| oct_encode(v, h.normal_bits)).collect();
    let qcrit: Vec<[u32; 4]> = pm.criteria.iter().map(|c| quantize_criteria(c, &h)).collect();
    let tree = SplitTree::new(pm);

    // Pre-order over the forest (v_l first); per op: split index, children's op indices.
    let mut order: Vec<usize> = Vec::with_capacity(pm.splits.len());
    let mut data: Vec<OpData> = Vec::with_capacity(pm.splits.len());
    let mut child_ops: Vec<[usize; 2]> = Vec::with_capacity(pm.splits.len());
    let mut contexts = vec![OpContext::default(); pm.splits.len()];
    let mut op_of_split = vec![usize::MAX; pm.splits.len()];
    let mut root_ops = vec![usize::MAX; pm.base_vertices.len()];
    // Stack entries: (split, context, parent op index and side).
    type Pending = (u32, OpContext, Option<(usize, usize)>);
    let mut stack: Vec<Pending> = vec![];
    for (b, &v) in pm.base_vertices.iter().enumerate() {
        let v_end = pm.base_vertices.get(b + 1).copied().unwrap_or(n as u32);
        let root = tree.roots[b];
        if root == NONE {
            if v_end - v != 1 {
                return Err(invalid("FVID range of an unsplit base vertex"));
            }
            continue;
        }
        root_ops[b] = data.len();
        let ctx = OpContext { v, v_end, parent_criteria: [0; 4], position: qpos[v as usize], normal: qnrm[v as usize] };
        stack.push((root, ctx, None));
        while let Some((s, ctx, parent)) = stack.pop() {
            let s = s as usize;
            let split = &pm.splits[s];
            if split.v != ctx.v || split.v_u <= ctx.v || split.v_u >= ctx.v_end || op_of_split[s] != usize::MAX {
                return Err(invalid("split outside its vertex's FVID range"));
            }
            let [l, r] = tree.children[s];
            let (has_left, has_right) = (l != NONE, r != NONE);
            if (!has_left && split.v_u != split.v + 1) || (!has_right && ctx.v_end != split.v_u + 1) {
                return Err(invalid("split tree inconsistent with the FVID ranges"));
            }
            let i = data.len();
            op_of_split[s] = i;
            if let Some((p, side)) = parent {
                child_ops[p][side] = i;
            }
            contexts[s] = ctx;
            let mut faces: Vec<FaceCode> =
                split.faces.iter().map(|&f| classify(split.v, split.v_u, ctx.v_end, f)).collect();
            faces.sort_by_key(|f| match *f {
                FaceCode::Standard { o, .. } => (0, o),
                FaceCode::General(_) => (1, 0),
            });
            let (pv, pu) = (qpos[split.v as usize], qpos[split.v_u as usize]);
            let (nv, nu) = (qnrm[split.v as usize], qnrm[split.v_u as usize]);
            data.push(OpData {
                ctx,
                v_u: split.v_u,
                crit: qcrit[s],
                has_left,
                has_right,
                faces,
                dpos: std::array::from_fn(|k| pu[k] as i64 - pv[k] as i64),
                dnrm: std::array::from_fn(|k| nu[k] as i64 - nv[k] as i64),
            });
            order.push(s);
            child_ops.push([usize::MAX; 2]);
            if has_right {
                let c =
                    OpContext { v: split.v_u, v_end: ctx.v_end, parent_criteria: qcrit[s], position: pu, normal: nu };
                stack.push((r, c, Some((i, 1))));
            }
            if has_left {
                let c = OpContext { v_end: split.v_u, parent_criteria: qcrit[s], ..ctx };
                stack.push((l, c, Some((i, 0))));
            }
        }
    }
    if data.len() != pm.splits.len() {
        return Err(invalid("splits not reachable from the base vertices"));
    }

    let nb = h.normal_bits;
    // Symbol counts for given swaps and offsets.
    // In parallel chunks, each with its own counts, summed at the end.
    let count = |swaps: &[bool], offsets: &[u64], avg: f32| {
        const CHUNK: usize = 1 << 14;
        data.par_chunks(CHUNK)
            .enumerate()
            .map(|(c, chunk)| {
                let mut counts = vec![[0u64; 256]; TABLES];
                for (k, d) in chunk.iter().enumerate() {
                    let i = c * CHUNK + k;
                    let mut w = OpWriter::counting(&mut counts);
                    write_op(&mut w, d, swaps[i], offsets[i], avg, nb);
                }
                counts
            })
            .reduce(
                || vec![[0u64; 256]; TABLES],
                |mut a, b| {
                    for (x, y) in a.iter_mut().zip(&b) {
                        for (p, q) in x.iter_mut().zip(y) {
                            *p += q;
                        }
                    }
                    a
                },
            )
    };
    // Operations by height in the split forest (0: both children leaves): an operation's
    // children are all of lower height, so each height is coded in parallel once the lower
    // ones are done (pre-order puts children after their parent).
    let mut height = vec![0u32; data.len()];
    for i in (0..data.len()).rev() {
        let h = child_ops[i].iter().filter(|&&c| c != usize::MAX).map(|&c| height[c] + 1).max().unwrap_or(0);
        height[i] = h;
    }
    let mut levels: Vec<Vec<usize>> = vec![vec![]; height.iter().max().map_or(0, |&h| h as usize + 1)];
    for (i, &h) in height.iter().enumerate() {
        levels[h as usize].push(i);
    }
    // Bottom-up compression (children before parents, so the sizes of both subtrees are known):
    // per op its bytes, swap and offset. Every operation whose children both split is coded
    // both ways, and keeps the shorter (section 4.2.4; ties by bits, then unswapped).
    let compress = |tables: &[Table], avg: f32| {
        let m = data.len();
        let mut bytes: Vec<Vec<u8>> = vec![vec![]; m];
        let mut subtree = vec![0u64; m];
        let mut swaps = vec![false; m];
        let mut offsets = vec![0u64; m];
        for level in &levels {
            let coded: Vec<(Vec<u8>, bool, u64)> = level
                .par_iter()
                .map(|&i| {
                    let d = &data[i];
                    let [l, r] = child_ops[i];
                    let code = |swap: bool, offset: u64| {
                        let mut w = OpWriter::coding(tables);
                        write_op(&mut w, d, swap, offset, avg, nb);
                        w.finish()
                    };
                    if d.has_left && d.has_right {
                        let (plain, plain_bits) = code(false, subtree[l]);
                        let (other, other_bits) = code(true, subtree[r]);
                        if (other.len(), other_bits) < (plain.len(), plain_bits) {
                            (other, true, subtree[r])
                        } else {
                            (plain, false, subtree[l])
                        }
                    } else {
                        (code(false, 0).0, false, 0)
                    }
                })
                .collect();
            for (&i, (b, swap, offset)) in level.iter().zip(coded) {
                let [l, r] = child_ops[i];
                let sub = |c: usize| if c == usize::MAX { 0 } else { subtree[c] };
                subtree[i] = b.len() as u64 + sub(l) + sub(r);
                bytes[i] = b;
                swaps[i] = swap;
                offsets[i] = offset;
            }
        }
        (bytes, swaps, offsets)
    };
    let m = data.len();
    // Steps 1-2 of section 4.2: tables from the operations with zero offsets, the smaller
    // subtree first (a first guess at the swaps: tables from unswapped operations would make
    // the swapped children code too long for any swap to pay).
    let smaller_first: Vec<bool> = data.iter().map(|d| d.ctx.v_end - d.v_u < d.v_u - d.ctx.v).collect();
    let tables1: Vec<Table> = count(&smaller_first, &vec![0; m], 0.0).iter().map(every_symbol).collect();
    // Step 3: bottom-up compression, choosing the swaps; the average size for the offset
    // estimate comes from it.
    let (bytes1, _, _) = compress(&tables1, 0.0);
    let avg = bytes1.iter().map(|b| b.len()).sum::<usize>() as f32 / m.max(1) as f32;
    let (_, swaps, offsets) = compress(&tables1, avg);
    // Step 4: tables from those symbols, and the final compression (choosing the swaps again
    // with the final tables; every symbol has a code, so a changed choice still codes).
    let final_counts = count(&swaps, &offsets, avg);
    let tables: Vec<Table> = final_counts.iter().map(every_symbol).collect();
    let mut symbol_bits = (0.0f64, 0.0f64);
    for (c, t) in final_counts.iter().zip(&tables) {
        let total = c.iter().sum::<u64>() as f64;
        for (&k, &len) in c.iter().zip(&t.lens) {
            if k > 0 {
                symbol_bits.0 += k as f64 * len as f64;
                symbol_bits.1 += k as f64 * (total / k as f64).log2();
            }
        }
    }
    let (op_bytes, swaps, _) = compress(&tables, avg);
    h.avg_op_bytes = avg;

    // Layout: pre-order, each operation followed by the subtree it stores first.
    let mut ops = Vec::with_capacity(op_bytes.iter().map(|b| b.len()).sum());
    let mut op_addr = vec![0usize; m];
    let mut layout: Vec<usize> = vec![];
    for &root in root_ops.iter().filter(|&&r| r != usize::MAX) {
        layout.push(root);
        while let Some(i) = layout.pop() {
            op_addr[i] = ops.len();
            ops.extend_from_slice(&op_bytes[i]);
            let [l, r] = child_ops[i];
            let (first, second) = if swaps[i] { (r, l) } else { (l, r) };
            for c in [second, first] {
                if c != usize::MAX {
                    layout.push(c);
                }
            }
        }
    }
    let mut addresses = vec![0usize; pm.splits.len()];
    for (i, &s) in order.iter().enumerate() {
        addresses[s] = op_addr[i];
    }

    // Sections.
    let tb = write_tables(&tables);
    let mut bb = Vec::new();
    let mut next = 0u64;
    for (b, &v) in pm.base_vertices.iter().enumerate() {
        put_varint(&mut bb, v as u64 - next);
        next = v as u64 + 1;
        for x in qpos[v as usize] {
            put_varint(&mut bb, x as u64);
        }
        for x in qnrm[v as usize] {
            put_varint(&mut bb, x as u64);
        }
        let root = tree.roots[b];
        put_varint(&mut bb, if root == NONE { 0 } else { addresses[root as usize] as u64 + 1 });
    }
    for t in &pm.base_faces {
        for &x in t {
            put_varint(&mut bb, x as u64);
        }
    }
    let out = LAYOUT.write(&h.to_bytes(), [&tb, &bb, &ops]);
    Ok(Encoded { bytes: out, header: h, addresses, contexts, symbol_bits })
}

/// Wraps arbitrary bytes as the operations section of a valid container (for fuzzing the
/// operation decoder behind the checksums): flat tables, one base vertex whose first operation
/// is at address 0, and counts taken from the data's length.
pub fn wrap_for_fuzzing(data: &[u8]) -> Vec<u8> {
    let splits = (data.len() as u32).min(64);
    let h = Header {
        vertices: splits + 1,
        base_vertices: 1,
        base_faces: 0,
        splits,
        position_bits: 16,
        normal_bits: 10,
        bbox_min: [0.0; 3],
        step: 1.0,
        length_step: 0.25,
        attribute_step: 1.0 / 4096.0,
        avg_op_bytes: 4.0,
        triangles: data.first().copied().unwrap_or(0) as u32,
    };
    let tb = vec![0u8; TABLES.div_ceil(8)];
    let mut bb = vec![];
    put_varint(&mut bb, 0);
    for _ in 0..5 {
        put_varint(&mut bb, 0);
    }
    put_varint(&mut bb, if data.is_empty() { 0 } else { 1 });
    LAYOUT.write(&h.to_bytes(), [&tb, &bb, data])
}
