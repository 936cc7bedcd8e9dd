//! The `.dpm` encoder, in the four steps that section 4.2 of the paper gives for it:
//!
//! > 1. Compute uncompressed operations with zero address offsets.
//! > 2. Compute the probability tables.
//! > 3. Compress the operations in reverse order, computing the correct address offsets.
//! > 4. Re-compute the probability tables and re-compress.
//!
//! [`encode`] checks and quantizes the mesh, runs the steps, one function each
//! ([`uncompressed_operations`], [`probability_tables`], [`compress_in_reverse_order`],
//! [`recompute_and_recompress`]), then lays the operations out in pre-order and writes the
//! sections. The paper's reverse order is there so that an operation is compressed after the
//! subtrees it points past; [`compress_bottom_up`] gets the same by compressing the split
//! forest in reverse pre-order, disjoint subtrees in parallel. Steps 3 and 4 also choose the
//! `v_l`/`v_u` swap of section 4.2.4 (see the format's documentation, [`super`]).

use std::borrow::Cow;

use rayon::prelude::*;
use smallvec::SmallVec;

use super::fields::TABLES;
use super::header::{Header, LAYOUT, MAX_NODES, NODE_BYTES};
use super::hierarchy::{self, Hierarchy, OpGeometry};
use super::nodes::{write_node_table, NodeInfo};
use super::op::{classify, write_op, FaceCode, Loc, OpContext, OpData};
use super::quantize::{
    dequantize_criteria, dequantize_position, fit_header, oct_encode, quantize_criteria, quantize_position,
};
use super::symbols::OpWriter;
use super::tables::{every_symbol, write_tables};
use crate::container::put_varint;
use crate::csr::Csr;
use crate::huffman::Table;
use crate::pm::order::{permute_in_place, preorder};
use crate::progressive::{ProgressiveMesh, Split, NONE};
use thiserror::Error;

/// Encoder settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EncodeOptions {
    /// Bits per position coordinate over the bounding box (8 to 24).
    pub position_bits: u8,
    /// Bits per octahedral normal coordinate (4 to 16).
    pub normal_bits: u8,
    /// 0: an in-core file; else the most bytes of a node of the out-of-core hierarchy (at
    /// most [`NODE_BYTES`], the paper's 64 kB; less makes small models take many nodes).
    pub node_bytes: u32,
}

impl Default for EncodeOptions {
    fn default() -> Self {
        EncodeOptions { position_bits: 16, normal_bits: 10, node_bytes: 0 }
    }
}

/// An encoded file and, per split of the input (in its order), the operation's address (in the
/// operations section in core, `node * NODE_BYTES + local` out of core) and its context.
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

/// An encoded file as the parts it is written from (see [`encode_owned`]): a large model's
/// operations are written to the file node by node, never copied into one buffer.
#[derive(Clone, Debug)]
pub struct EncodedFile {
    pub header: Header,
    /// As [`Encoded::symbol_bits`].
    pub symbol_bits: (f64, f64),
    /// The header's bytes, the tables, base mesh and node table sections, and the operations
    /// section in pieces (its nodes out of core).
    sections: (Vec<u8>, [Vec<u8>; 3], Pieces),
}

/// Byte strings kept one after another in one block, each found by its span: an out-of-core
/// file's nodes, coded in any order and written in theirs. A `Vec` per node was the only
/// memory of a spilled build that grew with the model outside its files (the system allocator
/// keeps blocks below the spill threshold: the 102M build's 492 MB of nodes, against 80-104
/// MB of everything else); as one block it goes to files with the build's other arrays.
#[derive(Clone, Debug, Default)]
struct Pieces {
    bytes: Vec<u8>,
    /// Per piece: its start in `bytes` and its length.
    spans: Vec<(usize, usize)>,
}

impl Pieces {
    /// One piece.
    fn one(bytes: Vec<u8>) -> Pieces {
        let spans = vec![(0, bytes.len())];
        Pieces { bytes, spans }
    }

    /// `n` empty pieces.
    fn empty(n: usize) -> Pieces {
        Pieces { bytes: vec![], spans: vec![(0, 0); n] }
    }

    /// Makes piece `i` the bytes `b` (appended to the block).
    fn set(&mut self, i: usize, b: &[u8]) {
        self.spans[i] = (self.bytes.len(), b.len());
        self.bytes.extend_from_slice(b);
    }

    fn get(&self, i: usize) -> &[u8] {
        let (start, len) = self.spans[i];
        &self.bytes[start..start + len]
    }

    fn len(&self) -> usize {
        self.spans.len()
    }

    fn iter(&self) -> impl Iterator<Item = &[u8]> + '_ {
        (0..self.len()).map(|i| self.get(i))
    }
}

impl EncodedFile {
    /// The file's length in bytes.
    pub fn len(&self) -> usize {
        let (h, [tb, bb, nt], oper) = &self.sections;
        LAYOUT.written_len(h, [tb.len(), bb.len(), nt.len(), oper.spans.iter().map(|s| s.1).sum()])
    }

    /// Whether the file is empty (never: it has a header).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Writes the file to `w`, the bytes [`EncodedFile::into_bytes`] returns.
    pub fn write_to(&self, w: &mut dyn std::io::Write) -> std::io::Result<()> {
        let (h, [tb, bb, nt], oper) = &self.sections;
        let pieces: Vec<&[u8]> = oper.iter().collect();
        LAYOUT.write_pieces(w, h, [&[&tb[..]], &[&bb[..]], &[&nt[..]], &pieces])
    }

    /// The file's bytes.
    pub fn into_bytes(self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.len());
        self.write_to(&mut out).expect("writing to a Vec does not fail");
        out
    }
}

/// What keeps a progressive mesh from being encoded.
#[derive(Debug, Error, PartialEq)]
pub enum EncodeError {
    #[error("invalid progressive mesh: {0}")]
    InvalidMesh(String),
    #[error("invalid options: {0}")]
    InvalidOptions(String),
}

fn invalid(msg: &str) -> EncodeError {
    EncodeError::InvalidMesh(msg.into())
}

/// Encodes a progressive mesh from [`super::build`](fn@crate::pm::build) (or any with the same
/// structure: every split reachable from the base vertices, FVID ranges as in section 3.2).
pub fn encode(pm: &ProgressiveMesh, opts: EncodeOptions) -> Result<Encoded, EncodeError> {
    encode_with_progress(pm, opts, &mut |_| {})
}

/// As [`encode`], naming each step to `step` as it starts (for a progress display: a model of
/// a hundred million triangles takes minutes).
pub fn encode_with_progress(
    pm: &ProgressiveMesh,
    opts: EncodeOptions,
    step: &mut dyn FnMut(&str),
) -> Result<Encoded, EncodeError> {
    let (file, addresses, contexts) = encode_mesh(Cow::Borrowed(pm), opts, true, step)?;
    let (header, symbol_bits) = (file.header, file.symbol_bits);
    Ok(Encoded { bytes: file.into_bytes(), header, addresses, contexts, symbol_bits })
}

/// As [`encode_with_progress`], taking the progressive mesh so that what the encoder has
/// quantized or copied into its own order (positions, normals, criteria, splits: about 85
/// bytes an operation) is freed as soon as it is, without [`Encoded::addresses`] and
/// [`Encoded::contexts`] (52 bytes an operation more), and returning the file as its parts,
/// written with [`EncodedFile::write_to`] (an out-of-core file's nodes are never copied into
/// one buffer, which took twice the file's size): what `tessera pm build` needs on large
/// models. The bytes are the same.
pub fn encode_owned(
    pm: ProgressiveMesh,
    opts: EncodeOptions,
    step: &mut dyn FnMut(&str),
) -> Result<EncodedFile, EncodeError> {
    Ok(encode_mesh(Cow::Owned(pm), opts, false, step)?.0)
}

/// [`encode_with_progress`] and [`encode_owned`]; `per_split`: whether to return the
/// addresses and contexts.
fn encode_mesh(
    mut pm: Cow<ProgressiveMesh>,
    opts: EncodeOptions,
    per_split: bool,
    step: &mut dyn FnMut(&str),
) -> Result<(EncodedFile, Vec<usize>, Vec<OpContext>), EncodeError> {
    let step = &mut |s: &str| {
        crate::pm::trace(s);
        step(s)
    };
    let mut h = fit_header(&pm, opts)?;
    check_mesh(&pm)?;
    step("preparing the operations");
    let qpos: Vec<[u32; 3]> = pm.positions.par_iter().map(|&p| quantize_position(p, &h)).collect();
    let qnrm: Vec<[u32; 2]> = pm.normals.par_iter().map(|&v| oct_encode(v, h.normal_bits)).collect();
    let qcrit: Vec<[u32; 4]> = pm.criteria.par_iter().map(|c| quantize_criteria(c, &h)).collect();
    // Only the splits and the base mesh are read from here on, and after the operations are
    // made, the base mesh alone: what was quantized goes before the tree is made.
    if let Cow::Owned(pm) = &mut pm {
        (pm.positions, pm.normals, pm.criteria, pm.fvid_of_input) = Default::default();
    }
    let (ops, first_guess) = uncompressed_operations(&mut pm, &qpos, &qnrm, qcrit, h.normal_bits)?;
    step("first tables");
    let (first_tables, _) = probability_tables(&ops, &first_guess);
    step("coding bottom-up with estimated tables");
    let offsets = compress_in_reverse_order(&ops, &first_tables);
    step("coding again with the counted tables");
    // Out of core the operations are coded again node by node: of this coding only the
    // lengths are read.
    let last = recompute_and_recompress(&ops, &offsets, opts.node_bytes == 0);
    h.avg_op_size = offsets.avg;
    drop(offsets);

    let symbol_bits = last.symbol_bits;
    // Per operation its address (see `Encoded::addresses`): in core below 2^31, out of core
    // `node * NODE_BYTES + local` in 32 bits.
    let (oper, op_addr, tables, node_table): (Pieces, Vec<u32>, _, _) = if opts.node_bytes == 0 {
        let (oper, op_addr) = lay_out(&ops, &last.bytes, &last.choices.swaps);
        // Offsets into the section and their residuals stay within 32 bits as zigzag values.
        if oper.len() >= 1 << 31 {
            return Err(invalid("the operations take 2 GiB or more; split the model into chunks"));
        }
        (Pieces::one(oper), op_addr, last.tables, vec![])
    } else if ops.len() == 0 {
        // Nothing to page: a mesh without operations is an in-core file.
        (Pieces::default(), vec![], last.tables, vec![])
    } else {
        // The out-of-core layout codes the operations again: of the in-core coding it needs
        // only the tables and the sizes.
        let Recompressed { tables, bytes: OpBytes { len: sizes, .. }, choices, .. } = last;
        drop(choices);
        let ooc = out_of_core(&ops, &sizes, &tables, &h, opts.node_bytes, step)?;
        h.nodes = ooc.infos.len() as u32;
        (ooc.nodes, ooc.addr, ooc.tables, write_node_table(&ooc.infos))
    };
    let tb = write_tables(&tables);
    let root_addr: Vec<Option<u64>> =
        ops.root_ops.iter().map(|&r| (r != usize::MAX).then(|| u64::from(op_addr[r]))).collect();
    let bb = base_section(&pm, &qpos, &qnrm, &root_addr);
    let (mut addresses, mut contexts) = (vec![], vec![]);
    if per_split {
        addresses = vec![0usize; ops.len()];
        contexts = vec![OpContext::default(); ops.len()];
        for (i, &s) in ops.order.iter().enumerate() {
            addresses[s as usize] = op_addr[i] as usize;
            contexts[s as usize] = ops.context(i);
        }
    }
    let file = EncodedFile { header: h, symbol_bits, sections: (h.to_bytes(), [tb, bb, node_table], oper) };
    Ok((file, addresses, contexts))
}

/// The checks of `pm`'s structure that need no traversal (the traversal of step 1 checks the
/// split tree against the FVID ranges).
fn check_mesh(pm: &ProgressiveMesh) -> Result<(), EncodeError> {
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
    Ok(())
}

/// The operations of step 1, in pre-order of the split forest (an operation, then `v_l`'s
/// subtree, then `v_u`'s), and the split forest over them.
///
/// The splits and their criteria are moved into the operations' order, in place (which is
/// the order the passes read them in: read through the splits' refinement order, the encoder
/// spent a fifth of its time waiting for memory; copied, the faces beside the splits were the
/// encoder's peak). An operation's [`OpData`] is made again from it each time it is coded
/// ([`Operations::op`]): kept, it was three quarters of the encoder's memory. Making it costs
/// time (on the dragon, compressing took 2.4-2.5 s against 2.0 s when it was kept).
struct Operations<'a> {
    qpos: &'a [[u32; 3]],
    qnrm: &'a [[u32; 2]],
    /// Per operation: its split's index in the progressive mesh.
    order: Vec<u32>,
    /// Per operation: its split (`v`, `v_u`, faces), the progressive mesh's own, moved into
    /// this order in place (a copy of the faces beside them was the encoder's peak).
    splits: Vec<Split>,
    /// Per operation: one past the last FVID its vertex stands for.
    v_end: Vec<u32>,
    /// Per operation: its split's quantized criteria (moved into this order in place).
    crit: Vec<[u32; 4]>,
    /// Per operation: its parent operation (`NONE` for a root).
    parent: Vec<u32>,
    /// Per operation: the operations of `v_l` and `v_u` (`NONE` where that child is a leaf;
    /// read as `usize` through [`Operations::children`]). 32-bit, as the layout's ids are.
    child_ops: Vec<[u32; 2]>,
    /// Per base vertex: its first operation (`usize::MAX`: none).
    root_ops: Vec<usize>,
    normal_bits: u8,
}

impl Operations<'_> {
    fn len(&self) -> usize {
        self.order.len()
    }

    /// Operation `i`'s children's operations, `usize::MAX` where that child is a leaf.
    fn children(&self, i: usize) -> [usize; 2] {
        self.child_ops[i].map(|c| if c == NONE { usize::MAX } else { c as usize })
    }

    /// Operation `i`'s faces.
    fn faces(&self, i: usize) -> &[[u32; 3]] {
        &self.splits[i].faces
    }

    /// Operation `i`'s split vertex.
    fn v(&self, i: usize) -> u32 {
        self.splits[i].v
    }

    /// Operation `i`'s context.
    fn context(&self, i: usize) -> OpContext {
        let v = self.v(i);
        let p = self.parent[i];
        OpContext {
            v,
            v_end: self.v_end[i],
            parent_criteria: if p == NONE { [0; 4] } else { self.crit[p as usize] },
            position: self.qpos[v as usize],
            normal: self.qnrm[v as usize],
        }
    }

    /// Operation `i`: its context, its quantized criteria, its faces classified and sorted by
    /// third-corner offset (4.2.2), its position and normal deltas.
    fn op(&self, i: usize) -> OpData {
        let ctx = self.context(i);
        let (v, v_u) = (ctx.v, self.splits[i].v_u);
        let mut faces: SmallVec<[FaceCode; 2]> =
            self.faces(i).iter().map(|&f| classify(v, v_u, ctx.v_end, f)).collect();
        faces.sort_by_key(|f| match *f {
            FaceCode::Standard { o, .. } => (0, o),
            FaceCode::General(_) => (1, 0),
        });
        let (pv, pu) = (self.qpos[v as usize], self.qpos[v_u as usize]);
        let (nv, nu) = (self.qnrm[v as usize], self.qnrm[v_u as usize]);
        let [l, r] = self.children(i);
        OpData {
            ctx,
            v_u,
            crit: self.crit[i],
            has_left: l != usize::MAX,
            has_right: r != usize::MAX,
            faces,
            dpos: std::array::from_fn(|k| pu[k] as i32 - pv[k] as i32),
            dnrm: std::array::from_fn(|k| nu[k] as i32 - nv[k] as i32),
        }
    }
}

/// How the operations are stored besides their data, what an operation's bytes depend on: per
/// operation whether `v_u`'s operation is stored first (the swap, where both children split),
/// the address offset of the child stored second (the size of the subtree stored first), and
/// the average operation size `s_avg` the offsets are estimated from (section 4.2.1; 16.16
/// fixed point).
struct Choices {
    swaps: Vec<bool>,
    offsets: Vec<u64>,
    avg: u32,
}

/// Step 1 of section 4.2: "Compute uncompressed operations with zero address offsets."
///
/// Walks the split forest from the base vertices in pre-order, checking every split against
/// its vertex's FVID range, and makes each split an [`OpData`]: its context, its quantized
/// criteria, its faces classified and sorted by third-corner offset (4.2.2), its position and
/// normal deltas. The choices go with zero offsets and a first guess at the swaps, the smaller
/// subtree first: from tables built without swaps, the swapped children code would be too
/// long for any swap to pay.
///
/// The pre-order is a sort ([`preorder`]); the splits are moved into it first and the walk
/// reads them in it, one after the other, keeping a stack of the FVID ranges still to split
/// (following the tree's children from the roots read the splits at random: a spilled
/// build's pages read back again and again).
fn uncompressed_operations<'a>(
    pm: &mut Cow<ProgressiveMesh>,
    qpos: &'a [[u32; 3]],
    qnrm: &'a [[u32; 2]],
    mut qcrit: Vec<[u32; 4]>,
    normal_bits: u8,
) -> Result<(Operations<'a>, Choices), EncodeError> {
    let n = qpos.len();
    let m = pm.splits.len();
    crate::pm::trace("sorting the splits into pre-order");
    let order = preorder(&pm.splits);
    // The splits and their criteria, moved into the operations' order (taken from an owned
    // progressive mesh, copied from a borrowed one).
    let mut splits = match pm {
        Cow::Owned(pm) => std::mem::take(&mut pm.splits),
        Cow::Borrowed(pm) => pm.splits.clone(),
    };
    crate::pm::trace("moving the splits into pre-order");
    permute_in_place(&mut splits, &mut qcrit, &order);
    crate::pm::trace("walking the split tree");
    // Per op: its range end, parent op, children's op indices.
    let mut v_ends: Vec<u32> = Vec::with_capacity(m);
    let mut parents: Vec<u32> = Vec::with_capacity(m);
    let mut child_ops: Vec<[u32; 2]> = Vec::with_capacity(m);
    let mut root_ops = vec![usize::MAX; pm.base_vertices.len()];
    // Ranges of more than one FVID still to split, the last pushed split next: (their first
    // FVID, their end, the parent op and side).
    type Pending = (u32, u32, Option<(usize, usize)>);
    let mut stack: Vec<Pending> = vec![];
    for (b, &v) in pm.base_vertices.iter().enumerate() {
        let v_end = pm.base_vertices.get(b + 1).copied().unwrap_or(n as u32);
        if v_end <= v {
            return Err(invalid("base vertices not in ascending FVID order"));
        }
        if v_end - v == 1 {
            continue;
        }
        root_ops[b] = v_ends.len();
        stack.push((v, v_end, None));
        while let Some((v, v_end, parent)) = stack.pop() {
            let i = v_ends.len();
            let Some(split) = splits.get(i).filter(|s| s.v == v) else {
                return Err(invalid(if parent.is_none() {
                    "FVID range of an unsplit base vertex"
                } else {
                    "split tree inconsistent with the FVID ranges"
                }));
            };
            if split.v_u <= v || split.v_u >= v_end {
                return Err(invalid("split outside its vertex's FVID range"));
            }
            if let Some((p, side)) = parent {
                // A vertex splits after the split that made it (its left siblings' order is
                // the sort's).
                if side == 1 && order[p] > order[i] {
                    return Err(invalid("a split before the split that makes its vertex"));
                }
                child_ops[p][side] = i as u32;
            }
            v_ends.push(v_end);
            parents.push(parent.map_or(NONE, |(p, _)| p as u32));
            child_ops.push([NONE; 2]);
            if v_end - split.v_u > 1 {
                stack.push((split.v_u, v_end, Some((i, 1))));
            }
            if split.v_u - v > 1 {
                stack.push((v, split.v_u, Some((i, 0))));
            }
        }
    }
    if v_ends.len() != m {
        return Err(invalid("splits not reachable from the base vertices"));
    }

    let smaller_first: Vec<bool> = splits.iter().zip(&v_ends).map(|(s, &v_end)| v_end - s.v_u < s.v_u - s.v).collect();
    let zero_offsets = Choices { swaps: smaller_first, offsets: vec![0; m], avg: 0 };
    let ops = Operations {
        qpos,
        qnrm,
        order,
        splits,
        v_end: v_ends,
        crit: qcrit,
        parent: parents,
        child_ops,
        root_ops,
        normal_bits,
    };
    Ok((ops, zero_offsets))
}

/// Step 2 of section 4.2: "Compute the probability tables."
///
/// The symbols of every operation coded with `choices` are counted per table, and every table
/// is a Huffman code over those counts in which every symbol has a code ([`every_symbol`]), so
/// that the tables still code the symbols of the next compression, whose offsets and swaps
/// differ. Returns the tables and the counts.
fn probability_tables(ops: &Operations, choices: &Choices) -> (Vec<Table>, Vec<[u64; 256]>) {
    let counts = count_symbols(ops, choices);
    (counts.iter().map(every_symbol).collect(), counts)
}

/// Step 3 of section 4.2: "Compress the operations in reverse order, computing the correct
/// address offsets."
///
/// Two bottom-up compressions with step 2's tables: the first without an offset estimate gives
/// the average operation size `s_avg` (section 4.2.1), the second, with the estimate, gives
/// the offsets and the swaps that step 4 counts.
fn compress_in_reverse_order(ops: &Operations, tables: &[Table]) -> Choices {
    // Of these compressions only the length and the choices are read: their bytes are not kept.
    let len = compress_bottom_up(ops, tables, 0, false).0.total;
    // 16.16 fixed point, rounded.
    let total = len << 16;
    let n = ops.len().max(1) as u64;
    let avg = ((total + n / 2) / n).min(u32::MAX as u64) as u32;
    compress_bottom_up(ops, tables, avg, false).1
}

/// Every operation's bytes in one buffer, in the order they were coded (a heap block per
/// operation cost more memory than the bytes: the builder's memory must follow what it keeps),
/// or, where the bytes are not kept, only their lengths.
struct OpBytes {
    data: Vec<u8>,
    start: Vec<u64>,
    len: Vec<u32>,
    total: u64,
    keep: bool,
}

impl OpBytes {
    fn new(m: usize, keep: bool) -> Self {
        Self { data: vec![], start: if keep { vec![0; m] } else { vec![] }, len: vec![0; m], total: 0, keep }
    }

    fn put(&mut self, i: usize, b: &[u8]) {
        self.len[i] = b.len() as u32;
        self.total += b.len() as u64;
        if self.keep {
            self.start[i] = self.data.len() as u64;
            self.data.extend_from_slice(b);
        }
    }

    fn get(&self, i: usize) -> &[u8] {
        let s = self.start[i] as usize;
        &self.data[s..s + self.len[i] as usize]
    }
}

/// What the encoder writes: the file's tables, each operation's bytes and how it was stored.
struct Recompressed {
    tables: Vec<Table>,
    bytes: OpBytes,
    choices: Choices,
    /// [`Encoded::symbol_bits`].
    symbol_bits: (f64, f64),
}

/// Step 4 of section 4.2: "Re-compute the probability tables and re-compress."
///
/// The tables are counted from the operations as step 3 stored them (its offsets and swaps),
/// and the final compression chooses the swaps again with those tables (every symbol has a
/// code, so a changed choice still codes); the offset estimate keeps step 3's `s_avg`.
fn recompute_and_recompress(ops: &Operations, step3: &Choices, keep_bytes: bool) -> Recompressed {
    let (tables, counts) = probability_tables(ops, step3);
    let symbol_bits = symbol_bits(&counts, &tables);
    let (bytes, choices) = compress_bottom_up(ops, &tables, step3.avg, keep_bytes);
    Recompressed { tables, bytes, choices, symbol_bits }
}

/// The symbol counts per table of every operation coded with `choices`, in parallel chunks,
/// each with its own counts, summed at the end.
fn count_symbols(ops: &Operations, choices: &Choices) -> Vec<[u64; 256]> {
    let Choices { swaps, offsets, avg } = choices;
    const CHUNK: usize = 1 << 14;
    (0..ops.len().div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut counts = vec![[0u64; 256]; TABLES];
            for i in c * CHUNK..((c + 1) * CHUNK).min(ops.len()) {
                let mut w = OpWriter::counting(&mut counts);
                write_op(&mut w, &ops.op(i), swaps[i], offsets[i], *avg, ops.normal_bits, None);
            }
            counts
        })
        .reduce(
            || vec![[0u64; 256]; TABLES],
            |mut a, b| {
                add_counts(&mut a, &b);
                a
            },
        )
}

/// Adds the symbol counts per table `b` to `a`.
fn add_counts(a: &mut [[u64; 256]], b: &[[u64; 256]]) {
    for (x, y) in a.iter_mut().zip(b) {
        for (p, q) in x.iter_mut().zip(y) {
            *p += q;
        }
    }
}

/// The bits of the counted symbols with `tables`, and their entropy.
fn symbol_bits(counts: &[[u64; 256]], tables: &[Table]) -> (f64, f64) {
    let mut symbol_bits = (0.0f64, 0.0f64);
    for (c, t) in counts.iter().zip(tables) {
        let total = c.iter().sum::<u64>() as f64;
        for (&k, &len) in c.iter().zip(&t.lens) {
            if k > 0 {
                symbol_bits.0 += k as f64 * len as f64;
                symbol_bits.1 += k as f64 * (total / k as f64).log2();
            }
        }
    }
    symbol_bits
}

/// One bottom-up compression with `tables` and the offset estimate from `avg`: children before
/// parents, so the sizes of both subtrees are known when an operation is coded. Per operation
/// its bytes (their lengths only unless `keep_bytes`), swap and offset. Every operation whose
/// children both split is coded both ways, and keeps the shorter (section 4.2.4; ties by bits,
/// then unswapped).
///
/// The operations are coded in reverse pre-order, children before their parents: disjoint
/// subtrees of at most a few thousand operations in parallel (each a range of the pre-order,
/// read backwards), then the operations above them. Coding a height of the forest at a time
/// in parallel (what this did before) went over the whole arrays once per height: the same
/// bytes, but where the arrays are pages the kernel may drop (`pm build --spill-dir`) the
/// 13.9M build's compression took 79 s instead of 17 in a 700 MB cgroup.
fn compress_bottom_up(ops: &Operations, tables: &[Table], avg: u32, keep_bytes: bool) -> (OpBytes, Choices) {
    let m = ops.len();
    let mut bytes = OpBytes::new(m, keep_bytes);
    let mut subtree = vec![0u64; m];
    let mut swaps = vec![false; m];
    let mut offsets = vec![0u64; m];
    // An operation's bytes, swap, offset and subtree bytes, from its children's subtree bytes.
    let code_op = |i: usize, sub: &dyn Fn(usize) -> u64| -> (Vec<u8>, bool, u64, u64) {
        let d = ops.op(i);
        let [l, r] = ops.children(i);
        let code = |swap: bool, offset: u64| {
            let mut w = OpWriter::coding(tables);
            write_op(&mut w, &d, swap, offset, avg, ops.normal_bits, None);
            w.finish()
        };
        let (b, swap, offset) = if d.has_left && d.has_right {
            let (plain, plain_bits) = code(false, sub(l));
            let (other, other_bits) = code(true, sub(r));
            if (other.len(), other_bits) < (plain.len(), plain_bits) {
                (other, true, sub(r))
            } else {
                (plain, false, sub(l))
            }
        } else {
            (code(false, 0).0, false, 0)
        };
        let child = |c: usize| if c == usize::MAX { 0 } else { sub(c) };
        let total = b.len() as u64 + child(l) + child(r);
        (b, swap, offset, total)
    };
    // Operations per subtree; a subtree is the pre-order range from its root on.
    let mut count = vec![1u32; m];
    for i in (0..m).rev() {
        for c in ops.children(i) {
            if c != usize::MAX {
                count[i] += count[c];
            }
        }
    }
    let (tasks, top) = subtrees_of_at_most(&count, (m / (rayon::current_num_threads() * 16)).clamp(1 << 10, 1 << 14));
    drop(count);
    // In batches, so the coded bytes in flight stay few.
    for batch in tasks.chunks(rayon::current_num_threads() * 8) {
        // Per subtree its operations' bytes (last to first) and per operation its length,
        // swap, offset and subtree bytes.
        type Subtree = (Vec<u8>, Vec<(u32, bool, u64, u64)>);
        let coded: Vec<Subtree> = batch
            .par_iter()
            .map(|range| {
                let mut data = Vec::new();
                let mut per_op = vec![(0u32, false, 0u64, 0u64); range.len()];
                for i in range.clone().rev() {
                    let (b, swap, offset, total) = code_op(i, &|c| per_op[c - range.start].3);
                    data.extend_from_slice(&b);
                    per_op[i - range.start] = (b.len() as u32, swap, offset, total);
                }
                (data, per_op)
            })
            .collect();
        for (range, (data, per_op)) in batch.iter().zip(coded) {
            // `data` holds the range's operations last to first.
            let mut at = 0usize;
            for (k, i) in range.clone().enumerate().rev() {
                let (len, swap, offset, total) = per_op[k];
                bytes.put(i, &data[at..at + len as usize]);
                at += len as usize;
                subtree[i] = total;
                swaps[i] = swap;
                offsets[i] = offset;
            }
        }
    }
    for &i in top.iter().rev() {
        let (b, swap, offset, total) = code_op(i, &|c| subtree[c]);
        subtree[i] = total;
        bytes.put(i, &b);
        swaps[i] = swap;
        offsets[i] = offset;
    }
    (bytes, Choices { swaps, offsets, avg })
}

/// Of a forest in pre-order with `size[i]` elements in the subtree of `i` (the range from `i`
/// on): the disjoint subtrees of at most `grain` elements whose parents' are larger, as
/// ranges in pre-order, and the elements above them, ascending.
fn subtrees_of_at_most(size: &[u32], grain: usize) -> (Vec<std::ops::Range<usize>>, Vec<usize>) {
    let (mut tasks, mut top) = (Vec::new(), Vec::new());
    let mut i = 0;
    while i < size.len() {
        if size[i] as usize <= grain {
            tasks.push(i..i + size[i] as usize);
            i += size[i] as usize;
        } else {
            top.push(i);
            i += 1;
        }
    }
    (tasks, top)
}

/// An out-of-core layout: the tables, per node its bytes and what the node table keeps of it,
/// per operation its address (`node * NODE_BYTES + local`).
struct OutOfCore {
    tables: Vec<Table>,
    nodes: Pieces,
    infos: Vec<NodeInfo>,
    addr: Vec<u32>,
}

/// How an operation of an out-of-core file is coded: its swap, the in-node offset of the child
/// stored second, where its children are.
#[derive(Clone, Copy, Debug, Default)]
struct OocCoding {
    swap: bool,
    /// Within a node: below [`NODE_BYTES`].
    offset: u32,
    locs: [Loc; 2],
}

/// The out-of-core layout (sections 4.1 and 4.2): the hierarchy built over the in-core coded
/// sizes `incore_sizes` (the pointers out of a node estimated from their count, see
/// `hierarchy.rs`), the operations coded node by
/// node, children's nodes first, with the in-core tables, the tables counted again from that
/// coding and the operations coded again. As in the paper, where a node comes out larger than
/// `node_bytes` (in the final coding), the hierarchy is built again with a smaller size limit
/// ("we iteratively reduce the maximum node size when building the hierarchy and store the
/// model as soon as all nodes are small enough after compression").
fn out_of_core(
    ops: &Operations,
    incore_sizes: &[u32],
    incore_tables: &[Table],
    h: &Header,
    node_bytes: u32,
    step: &mut dyn FnMut(&str),
) -> Result<OutOfCore, EncodeError> {
    if node_bytes as usize > NODE_BYTES || node_bytes < 256 {
        return Err(EncodeError::InvalidOptions(format!("node size {node_bytes} bytes outside 256 to {NODE_BYTES}")));
    }
    let geometry = Geometry { ops, sizes: incore_sizes, h };
    let roots: Vec<usize> = ops.root_ops.iter().copied().filter(|&r| r != usize::MAX).collect();
    let mut s_max = node_bytes as u64 * 15 / 16;
    loop {
        step(&format!("grouping the operations into nodes of at most {s_max} bytes"));
        let hier = hierarchy::build(&geometry, &roots, s_max)
            .ok_or_else(|| invalid(&format!("an operation is larger than a node of {node_bytes} bytes")))?;
        if hier.parents.len() > MAX_NODES as usize {
            return Err(invalid(&format!(
                "more than {MAX_NODES} nodes of {node_bytes} bytes; use larger nodes or split the model into chunks"
            )));
        }
        let mut tables = incore_tables.to_vec();
        let (mut largest, mut total) = (0, 0);
        for round in 0..2 {
            step(&format!("coding {} nodes, {} tables", hier.parents.len(), ["in-core", "counted"][round]));
            let (nodes, addr, counts) = code_nodes(ops, &hier, &tables, h.avg_op_size, round == 0, total);
            largest = nodes.spans.iter().map(|s| s.1).max().unwrap_or(0);
            total = nodes.spans.iter().map(|s| s.1).sum();
            // Only the final coding has to fit `node_bytes`: the first, with the in-core
            // tables, only counts the symbols (its nodes come out a few percent larger), as
            // long as its addresses are whole (a node within `NODE_BYTES`).
            if largest > [NODE_BYTES, node_bytes as usize][round] {
                break;
            }
            if round == 0 {
                tables = counts.iter().map(every_symbol).collect();
            } else {
                let infos = node_infos(ops, h, &hier, &nodes);
                return Ok(OutOfCore { tables, nodes, infos, addr });
            }
        }
        let shrunk = (s_max as f64 * node_bytes as f64 / largest as f64 * 0.98) as u64;
        s_max = shrunk.min(s_max - 1);
        if s_max < 64 {
            return Err(invalid("the out-of-core hierarchy does not fit its nodes"));
        }
    }
}

/// The hierarchy's view of the operations (see [`OpGeometry`]): their children, the in-core
/// coded sizes `sizes`, and their errors and centres as they
/// decode.
struct Geometry<'a> {
    ops: &'a Operations<'a>,
    sizes: &'a [u32],
    h: &'a Header,
}

impl OpGeometry for Geometry<'_> {
    fn len(&self) -> usize {
        self.ops.len()
    }

    fn children(&self, i: usize) -> [u32; 2] {
        self.ops.child_ops[i]
    }

    fn size(&self, i: usize) -> u32 {
        self.sizes[i]
    }

    fn error(&self, i: usize) -> f32 {
        dequantize_criteria(self.ops.crit[i], self.h).geometric_error
    }

    fn center(&self, i: usize) -> [f32; 3] {
        dequantize_position(self.ops.qpos[self.ops.v(i) as usize], self.h)
    }
}

/// A node's bytes, and per operation in it its index and address.
type CodedNode = (Vec<u8>, Vec<(u32, u32)>);

/// Codes every operation of an out-of-core file (see [`out_of_core`]), a node's children
/// before it, so that a child's address is known when its parent operation is coded. Returns
/// per node its bytes (with `count`, only their lengths: that round's nodes are not written),
/// per operation its address and, with `count`, the symbols of the
/// operations as coded counted per table (else none): what the next round's tables are made
/// from, counted node by node rather than from a per-operation record of the choices (24
/// bytes an operation). `reserve`: the bytes to make room for at once (the round before's
/// total: growing the block by doubling copied it, and could take twice its bytes).
///
/// Nodes are numbered in pre-order, so a node's subtree of the hierarchy is the range of
/// node ids from it on: disjoint subtrees of at most 64 nodes are coded in parallel, each
/// last node to first, then the nodes above them. Coding a depth of the hierarchy at a time
/// (what this did before) went over the whole arrays once per depth: the same bytes, but where
/// the arrays are pages the kernel may drop (`pm build --spill-dir`) the 102M build read them
/// back at 740 MB/s for minutes in a 3.5 GB cgroup.
fn code_nodes(
    ops: &Operations,
    hier: &Hierarchy,
    tables: &[Table],
    avg: u32,
    count: bool,
    reserve: usize,
) -> (Pieces, Vec<u32>, Vec<[u64; 256]>) {
    let m = ops.len();
    let nodes_count = hier.parents.len();
    let members = Csr::build(nodes_count, || hier.node_of.iter().enumerate().map(|(i, &n)| (n, i as u32)));
    let mut size = vec![1u32; nodes_count];
    for n in (0..nodes_count).rev() {
        if let Some(p) = hier.parents[n] {
            debug_assert!((p as usize) < n);
            size[p as usize] += size[n];
        }
    }
    let threads = rayon::current_num_threads();
    let (tasks, top) = subtrees_of_at_most(&size, (nodes_count / (threads * 16)).clamp(1, 64));
    drop(size);
    let code = |n: usize, addr: &dyn Fn(usize) -> u32, counting: Option<&mut [[u64; 256]]>| {
        code_node(ops, hier, members.get(n), n as u32, addr, &Symbols { tables, avg }, counting)
    };
    let mut addr = vec![NONE; m];
    let tables_counted = if count { TABLES } else { 0 };
    let mut counts = vec![[0u64; 256]; tables_counted];
    let mut nodes = Pieces::empty(nodes_count);
    if !count {
        nodes.bytes.reserve_exact(reserve);
    }
    let put = |nodes: &mut Pieces, n: usize, bytes: &[u8]| {
        if count {
            nodes.spans[n] = (0, bytes.len());
        } else {
            nodes.set(n, bytes);
        }
    };
    // In batches, so that the nodes coded in flight stay few; the symbols counted per
    // thread's share of a batch (a table of counts per node in flight took more memory than
    // the dragon's operations).
    for batch in tasks.chunks(threads * 4) {
        let (coded, batch_counts) = batch
            .par_iter()
            .fold(
                || (Vec::new(), vec![[0u64; 256]; tables_counted]),
                |(mut coded, mut c), range| {
                    // The addresses this subtree placed, which its nodes' parents read.
                    let mut placed: rustc_hash::FxHashMap<u32, u32> = Default::default();
                    for n in range.clone().rev() {
                        let counting = count.then_some(&mut c[..]);
                        let lookup = |i: usize| placed.get(&(i as u32)).copied().unwrap_or(NONE);
                        let node: CodedNode = code(n, &lookup, counting);
                        placed.extend(node.1.iter().copied());
                        coded.push((n, node));
                    }
                    (coded, c)
                },
            )
            .reduce(
                || (Vec::new(), vec![[0u64; 256]; tables_counted]),
                |(mut a, mut ca), (b, cb)| {
                    a.extend(b);
                    add_counts(&mut ca, &cb);
                    (a, ca)
                },
            );
        add_counts(&mut counts, &batch_counts);
        for (n, (bytes, placed)) in coded {
            for (i, a) in placed {
                addr[i as usize] = a;
            }
            put(&mut nodes, n, &bytes);
        }
    }
    for &n in top.iter().rev() {
        let (bytes, placed) = code(n, &|i| addr[i], count.then_some(&mut counts[..]));
        for (i, a) in placed {
            addr[i as usize] = a;
        }
        put(&mut nodes, n, &bytes);
    }
    (nodes, addr, counts)
}

/// How a node's operations are coded: the symbol tables, and the average operation size
/// `s_avg` the offsets are estimated from (section 4.2.1).
#[derive(Clone, Copy)]
struct Symbols<'a> {
    tables: &'a [Table],
    avg: u32,
}

/// Codes the operations `list` (ascending, pre-order) of node `n`, children before parents,
/// each with the shorter of its swaps (as [`compress_bottom_up`]), and lays them out: per
/// operation subtree entering the node, in pre-order, each operation followed by the child it
/// stores first where that is in the node. Returns the node's bytes and per operation its
/// address; adds the symbols of the operations as coded to `counts` where given.
fn code_node(
    ops: &Operations,
    hier: &Hierarchy,
    list: &[u32],
    n: u32,
    addr: &dyn Fn(usize) -> u32,
    symbols: &Symbols,
    mut counts: Option<&mut [[u64; 256]]>,
) -> CodedNode {
    let Symbols { tables, avg } = *symbols;
    let parent_op = &ops.parent;
    let idx = |i: usize| list.binary_search(&(i as u32)).ok();
    let mut inner = vec![0u64; list.len()];
    let mut bytes: Vec<Vec<u8>> = vec![vec![]; list.len()];
    let mut coding = vec![OocCoding::default(); list.len()];
    for (k, &i) in list.iter().enumerate().rev() {
        let i = i as usize;
        let d = ops.op(i);
        let [l, r] = ops.children(i);
        // A child's location and the bytes of its subtree's part in this node.
        let loc = |c: usize| -> (Loc, u64) {
            if hier.node_of[c] == n {
                (Loc::default(), inner[idx(c).expect("in the node")])
            } else {
                let a = addr(c);
                debug_assert!(hier.node_of[c] > n && a != NONE);
                (Loc { delta: hier.node_of[c] - n, local: a % NODE_BYTES as u32 }, 0)
            }
        };
        let code = |swap: bool| {
            let (first, second) = if swap { (r, l) } else { (l, r) };
            let mut locs = [Loc::default(); 2];
            let mut sizes = [0u64; 2];
            for (k, c) in [first, second].into_iter().filter(|&c| c != usize::MAX).enumerate() {
                (locs[k], sizes[k]) = loc(c);
            }
            let offset = if first != usize::MAX && second != usize::MAX && locs[0].delta == 0 { sizes[0] } else { 0 };
            let mut w = OpWriter::coding(tables);
            write_op(&mut w, &d, swap, offset, avg, ops.normal_bits, Some(locs));
            let (b, bits) = w.finish();
            (b, bits, OocCoding { swap, offset: offset as u32, locs })
        };
        let (b, _, c) = if d.has_left && d.has_right {
            let plain = code(false);
            let other = code(true);
            if (other.0.len(), other.1) < (plain.0.len(), plain.1) {
                other
            } else {
                plain
            }
        } else {
            code(false)
        };
        if let Some(counts) = counts.as_deref_mut() {
            let mut w = OpWriter::counting(counts);
            write_op(&mut w, &d, c.swap, u64::from(c.offset), avg, ops.normal_bits, Some(c.locs));
        }
        let sub = |c: usize| if c == usize::MAX { 0 } else { loc(c).1 };
        inner[k] = b.len() as u64 + sub(l) + sub(r);
        bytes[k] = b;
        coding[k] = c;
    }
    // The node's bytes: each operation's once (`inner` counts a subtree's at every ancestor).
    let mut out = Vec::with_capacity(bytes.iter().map(Vec::len).sum());
    let mut placed = Vec::with_capacity(list.len());
    let mut stack = vec![];
    for (k, &i) in list.iter().enumerate() {
        let p = parent_op[i as usize];
        if p != NONE && hier.node_of[p as usize] == n {
            continue;
        }
        stack.push(k);
        while let Some(k) = stack.pop() {
            let i = list[k] as usize;
            // Wrapping: the counting coding may make a node larger than `NODE_BYTES`, and is
            // then thrown away (see `out_of_core`).
            placed.push((i as u32, (n * NODE_BYTES as u32).wrapping_add(out.len() as u32)));
            out.extend_from_slice(&bytes[k]);
            let [l, r] = ops.children(i);
            let (first, second) = if coding[k].swap { (r, l) } else { (l, r) };
            for c in [second, first] {
                if c != usize::MAX && hier.node_of[c] == n {
                    stack.push(idx(c).unwrap());
                }
            }
        }
    }
    (out, placed)
}

/// What the node table keeps of every node: its length and checksum, its parent, the box of
/// its operations' bounding spheres (widened by a few ulps so that `f32` rounding cannot put
/// a sphere outside it) and its greatest errors, as the operations decode.
fn node_infos(ops: &Operations, h: &Header, hier: &Hierarchy, nodes: &Pieces) -> Vec<NodeInfo> {
    let mut infos: Vec<NodeInfo> = nodes
        .iter()
        .zip(&hier.parents)
        .map(|(b, &parent)| NodeInfo {
            offset: 0,
            len: b.len() as u32,
            parent,
            bbox_min: [f32::INFINITY; 3],
            bbox_max: [f32::NEG_INFINITY; 3],
            geometric_error: 0.0,
            attribute_error: 0.0,
            crc: crc32fast::hash(b),
        })
        .collect();
    let mut offset = 0;
    for n in &mut infos {
        n.offset = offset;
        offset += n.len as u64;
    }
    let widen = |x: f32, up: bool| {
        let e = x.abs() * 4.0 * f32::EPSILON + f32::MIN_POSITIVE;
        if up {
            x + e
        } else {
            x - e
        }
    };
    for (i, &node) in hier.node_of.iter().enumerate() {
        let n = &mut infos[node as usize];
        let c = dequantize_criteria(ops.crit[i], h);
        let center = dequantize_position(ops.qpos[ops.v(i) as usize], h);
        for (k, x) in center.into_iter().enumerate() {
            n.bbox_min[k] = n.bbox_min[k].min(widen(x - c.radius, false));
            n.bbox_max[k] = n.bbox_max[k].max(widen(x + c.radius, true));
        }
        n.geometric_error = n.geometric_error.max(c.geometric_error);
        n.attribute_error = n.attribute_error.max(c.attribute_error);
    }
    infos
}

/// The operations section: pre-order, each operation followed by the subtree it stores first.
/// Returns the section and per operation its address.
fn lay_out(ops: &Operations, op_bytes: &OpBytes, swaps: &[bool]) -> (Vec<u8>, Vec<u32>) {
    let m = op_bytes.len.len();
    let mut oper = Vec::with_capacity(op_bytes.data.len());
    // Addresses past 2^31 make the section too long (the caller's error), so 32 bits hold them.
    let mut op_addr = vec![0u32; m];
    let mut layout: Vec<usize> = vec![];
    for &root in ops.root_ops.iter().filter(|&&r| r != usize::MAX) {
        layout.push(root);
        while let Some(i) = layout.pop() {
            op_addr[i] = oper.len() as u32;
            oper.extend_from_slice(op_bytes.get(i));
            let [l, r] = ops.children(i);
            let (first, second) = if swaps[i] { (r, l) } else { (l, r) };
            for c in [second, first] {
                if c != usize::MAX {
                    layout.push(c);
                }
            }
        }
    }
    (oper, op_addr)
}

/// The base mesh section (LEB128): per base vertex its FVID gap to the previous one, its
/// quantized position and normal, and its first operation's address (`root_addr`) plus one (0:
/// none); then the base faces.
fn base_section(pm: &ProgressiveMesh, qpos: &[[u32; 3]], qnrm: &[[u32; 2]], root_addr: &[Option<u64>]) -> Vec<u8> {
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
        put_varint(&mut bb, root_addr[b].map_or(0, |a| a + 1));
    }
    for t in &pm.base_faces {
        for &x in t {
            put_varint(&mut bb, x as u64);
        }
    }
    bb
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
        avg_op_size: 4 << 16,
        triangles: data.first().copied().unwrap_or(0) as u32,
        max_faces: 64,
        nodes: 0,
    };
    let tb = vec![0u8; TABLES.div_ceil(8)];
    let mut bb = vec![];
    put_varint(&mut bb, 0);
    for _ in 0..5 {
        put_varint(&mut bb, 0);
    }
    put_varint(&mut bb, if data.is_empty() { 0 } else { 1 });
    LAYOUT.write(&h.to_bytes(), [&tb, &bb, &[], data])
}
