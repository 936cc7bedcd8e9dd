//! The per-operation coder: one split operation, coded on its own into a byte-aligned bit
//! stream and decoded from its address and an [`OpContext`] alone (section 4.2), its fields in
//! the order the format's documentation ([`super`]) lists them. [`write_op`] and [`read_op`]
//! mirror each other field by field; every value the reader gets is checked against the
//! FVID ranges, the grids and the operations section before it is used.

use std::sync::Arc;

use smallvec::SmallVec;

use super::fields::{
    corner_class, criteria_prediction, head_class, magnitude_class, pointer_estimate, position_frame, region_class,
    sin_class, split_class, tangent_class, tangent_prediction, ATTR, FACE_COUNT, FACE_FORM, FACE_GENERAL, FACE_OTHER,
    FACE_OTHER_DELTA, FACE_T, FACE_U, GEOM, HEAD, KINDS, LOCAL, NODE_DELTA, NORMAL, POINTER, POS_NORMAL, POS_TANGENT,
    RADIUS, SIN, SPLIT,
};
use super::header::max_q;
use super::header::{corrupt, Header, NODE_BYTES};
use super::quantize::{dequantize_criteria, valid_oct, MAX_K};
use super::symbols::{unzigzag, zigzag, OpReader, OpWriter};
use super::DpmError;
use crate::huffman::Table;
use crate::progressive::{Criteria, Split};

/// What a single operation needs besides its bytes: all of it the runtime has when it is about
/// to perform the split (the vertex, the end of its FVID range, its parent's criteria and its
/// quantized attributes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OpContext {
    /// FVID of the vertex that splits.
    pub v: u32,
    /// One past the last FVID `v` stands for.
    pub v_end: u32,
    /// The quantized criteria of the parent operation (zeros for a root).
    pub parent_criteria: [u32; 4],
    /// `v`'s quantized position and octahedral normal.
    pub position: [u32; 3],
    pub normal: [u32; 2],
}

/// One decoded operation.
#[derive(Clone, Debug, PartialEq)]
pub struct DecodedOp {
    pub split: Split,
    pub criteria_q: [u32; 4],
    pub criteria: Criteria,
    /// `v_u`'s quantized position and normal.
    pub position_u: [u32; 3],
    pub normal_u: [u32; 2],
    /// Addresses of the operations of `v_l` and `v_u`, where they split further.
    pub left: Option<usize>,
    pub right: Option<usize>,
    /// Whether `v_u`'s operation is stored first, directly after this one (the swap of
    /// section 4.2.4; only where both children split further).
    pub swapped: bool,
    /// One past this operation's last byte.
    pub end: usize,
}

/// A face of a split, prepared for coding.
#[derive(Clone, Copy, Debug)]
pub(super) enum FaceCode {
    /// Corner offsets to `v` and `v_u`, zigzag third-corner offset, reversed orientation.
    Standard {
        t: u32,
        u: u32,
        o: u64,
        rev: bool,
    },
    General([i64; 3]),
}

/// An operation with everything but its address offset and its swap.
pub(super) struct OpData {
    pub(super) ctx: OpContext,
    pub(super) v_u: u32,
    pub(super) crit: [u32; 4],
    pub(super) has_left: bool,
    pub(super) has_right: bool,
    /// Standard faces first, by third-corner offset. Inline up to the two faces of a manifold
    /// split, so making an operation's data (each time the encoder codes it) allocates
    /// nothing in the common case.
    pub(super) faces: SmallVec<[FaceCode; 2]>,
    /// Deltas of quantized positions (at most 24 bits) and normals (at most 16 bits).
    pub(super) dpos: [i32; 3],
    pub(super) dnrm: [i32; 2],
}

/// Where a child's operation is stored in an out-of-core file: its node's distance from this
/// operation's node (0: the same node; a node's descendants in the hierarchy come after it)
/// and, in another node, its local address there.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Loc {
    pub(super) delta: u32,
    pub(super) local: u32,
}

/// The children code of the head symbol: 0 none splits further, 1 both (`v_l`'s operation
/// first), 2 `v_l` only, 3 `v_u` only, 4 both, swapped (`v_u`'s operation first).
fn children_code(left: bool, right: bool, swapped: bool) -> u32 {
    match (left, right) {
        (false, false) => 0,
        (true, true) => 1 + 3 * swapped as u32,
        (true, false) => 2,
        (false, true) => 3,
    }
}

/// The orientation pattern of the head symbol: 0 or 1 when the first two faces are standard
/// and of opposite orientation (or there is one standard face), the first face's orientation;
/// 2 when every face's form is coded.
fn face_pattern(faces: &[FaceCode]) -> u32 {
    match faces {
        [] => 0,
        [FaceCode::Standard { rev, .. }] => *rev as u32,
        [FaceCode::Standard { rev: a, .. }, FaceCode::Standard { rev: b, .. }, ..] if a != b => *a as u32,
        _ => 2,
    }
}

/// Writes an operation; `swapped` stores `v_u`'s subtree first, `offset` is the size in bytes
/// of the subtree stored first (both only where both children split further; out of core, of
/// its part in this node). Out of core, `ooc` says where the children stored first and second
/// are (the first of the children that split, then the second).
pub(super) fn write_op(
    w: &mut OpWriter,
    d: &OpData,
    swapped: bool,
    offset: u64,
    avg: u32,
    normal_bits: u8,
    ooc: Option<[Loc; 2]>,
) {
    let (v, v_u, v_end) = (d.ctx.v, d.v_u, d.ctx.v_end);
    let mut residual = [0i64; 4];
    for (i, r) in residual.iter_mut().enumerate() {
        *r = criteria_prediction(&d.ctx.parent_criteria, &d.crit, i) - d.crit[i] as i64;
    }
    w.put_signed(SIN, sin_class(&d.ctx.parent_criteria), residual[0]);
    w.put_signed(GEOM, 0, residual[1]);
    w.put_signed(ATTR, 0, residual[2]);
    let swapped = swapped && d.has_left && d.has_right;
    let nf = d.faces.len();
    let pattern = face_pattern(&d.faces);
    let head = children_code(d.has_left, d.has_right, swapped)
        + 5 * (nf.min(3) as u32 + 4 * (pattern + 3 * (residual[3] != 0) as u32));
    w.put(HEAD, head_class(v, v_end), head as u64);
    if residual[3] != 0 {
        w.put(RADIUS, 0, zigzag(residual[3]) - 1);
    }
    let first_size = if swapped { v_end - v_u } else { v_u - v };
    // Both children split, so each has at least 2 FVIDs; a range of 4 leaves no choice.
    if d.has_left && d.has_right && v_end - v > 4 {
        w.put(SPLIT, split_class(v_end - v), (first_size - 2) as u64);
    }
    if nf >= 3 {
        w.put(FACE_COUNT, 0, (nf - 3) as u64);
    }
    let mut prev: Option<(u64, u64, u64)> = None;
    for (i, f) in d.faces.iter().enumerate() {
        let implied = pattern < 2 && i < 2;
        match *f {
            FaceCode::Standard { t, u, o, rev } => {
                if !implied {
                    w.put(FACE_FORM, 0, rev as u64);
                }
                let (t, u) = (t as u64, u as u64);
                if v_u - v > 1 {
                    w.put(FACE_T, corner_class(prev.map(|p| p.0), v_u - v), t);
                }
                if v_end - v_u > 1 {
                    w.put(FACE_U, corner_class(prev.map(|p| p.1), v_end - v_u), u);
                }
                match prev {
                    None => w.put(FACE_OTHER, region_class(v, v_end), o),
                    Some((_, _, po)) => w.put(FACE_OTHER_DELTA, region_class(v, v_end), o - po),
                }
                prev = Some((t, u, o));
            }
            FaceCode::General(c) => {
                w.put(FACE_FORM, 0, 2);
                for x in c {
                    w.put_signed(FACE_GENERAL, 0, x);
                }
            }
        }
    }
    let (axes, n) = position_frame(d.ctx.normal, normal_bits);
    let [d0, d1, d2] = axes.map(|a| i64::from(d.dpos[a]));
    let class = magnitude_class(d.crit[3]);
    w.put_signed(POS_TANGENT, class, d0);
    w.put_signed(POS_TANGENT, class, d1);
    w.put_signed(POS_NORMAL, tangent_class(d0, d1), d2 - tangent_prediction(n, d0, d1));
    let class = magnitude_class(d.crit[2]);
    for x in d.dnrm {
        w.put_signed(NORMAL, class, i64::from(x));
    }
    let both = d.has_left && d.has_right;
    match ooc {
        None if both => {
            w.put_signed(POINTER, split_class(first_size + 2), offset as i64 - pointer_estimate(avg, first_size))
        }
        None => {}
        Some(locs) => {
            let splitting = d.has_left as usize + d.has_right as usize;
            for (k, loc) in locs.iter().enumerate().take(splitting) {
                w.put(NODE_DELTA, k, loc.delta as u64);
                if loc.delta != 0 && k == 1 && locs[0].delta == loc.delta {
                    // Both children enter the same other node, where `v_l`'s part comes
                    // directly before `v_u`'s: the distance between them, as an in-node
                    // pointer past `v_l`'s subtree.
                    let (first, second) = (i64::from(locs[0].local), i64::from(loc.local));
                    let part = if swapped { first - second } else { second - first };
                    debug_assert!(part >= 1, "v_l's part in the node precedes v_u's");
                    w.put_signed(POINTER, split_class(v_u - v + 2), part - pointer_estimate(avg, v_u - v));
                } else if loc.delta != 0 {
                    w.put(LOCAL, 0, loc.local as u64);
                } else if k == 1 {
                    let estimate = if locs[0].delta == 0 { pointer_estimate(avg, first_size) } else { 0 };
                    w.put_signed(POINTER, split_class(first_size + 2), offset as i64 - estimate);
                }
            }
        }
    }
}

/// Reads the operation at byte `addr` of `ops`, in context `ctx`, optionally adding the bits
/// of every field to its kind. The inverse of [`write_op`]. In core `ops` is the operations
/// section and `node` `None`; out of core `ops` is the bytes of node `node` and `addr` the
/// local address there, and the children's addresses come back as `node * NODE_BYTES + local`.
pub(super) fn read_op(
    h: &Header,
    tables: &[Arc<Table>],
    ops: &[u8],
    addr: usize,
    node: Option<u32>,
    ctx: &OpContext,
    bits: Option<&mut [u64; KINDS]>,
) -> Result<DecodedOp, DpmError> {
    if addr >= ops.len() {
        return Err(corrupt("operation address past the end of the operations"));
    }
    let n = h.vertices as i64;
    let (v, v_end) = (ctx.v, ctx.v_end);
    if v >= v_end
        || v_end as i64 > n
        || !valid_oct(ctx.normal, h.normal_bits)
        || ctx.position.iter().any(|&p| p > max_q(h.position_bits))
    {
        return Err(corrupt("bad operation context"));
    }
    let mut r = OpReader::new(tables, ops, addr, bits);
    let mut crit = [0u32; 4];
    let residual =
        [r.get_signed(SIN, sin_class(&ctx.parent_criteria))?, r.get_signed(GEOM, 0)?, r.get_signed(ATTR, 0)?];
    let head = r.get(HEAD, head_class(v, v_end))?;
    let (code, nfc, pattern, rz) = (head % 5, head / 5 % 4, head / 20 % 3, head / 60);
    if rz > 1 {
        return Err(corrupt("bad operation head"));
    }
    let radius_residual = if rz == 1 { unzigzag(r.get(RADIUS, 0)? + 1) } else { 0 };
    for (i, res) in residual.into_iter().chain([radius_residual]).enumerate() {
        let k = criteria_prediction(&ctx.parent_criteria, &crit, i) - res;
        let max = if i == 0 { 255 } else { MAX_K as i64 };
        if !(0..=max).contains(&k) {
            return Err(corrupt("refinement criterion out of range"));
        }
        crit[i] = k as u32;
    }
    let (has_left, has_right, swapped) = match code {
        0 => (false, false, false),
        1 => (true, true, false),
        2 => (true, false, false),
        3 => (false, true, false),
        _ => (true, true, true),
    };
    let size = (v_end - v) as u64;
    let (v_u, first_size) = match (has_left, has_right) {
        (true, true) => {
            let s = if size > 4 { r.get(SPLIT, split_class(v_end - v))? + 2 } else { 2 };
            if s + 2 > size {
                return Err(corrupt("v_u outside the vertex's FVID range"));
            }
            (if swapped { v_end as u64 - s } else { v as u64 + s }, s as u32)
        }
        (true, false) => (v_end as u64 - 1, 0),
        (false, _) => (v as u64 + 1, 0),
    };
    let v_u = v_u as u32;
    // A leaf's range holds exactly one FVID.
    if v_u <= v
        || v_u >= v_end
        || (has_left && v_u - v < 2)
        || (!has_left && v_u - v != 1)
        || (has_right && v_end - v_u < 2)
        || (!has_right && v_end - v_u != 1)
    {
        return Err(corrupt("split tree inconsistent with the FVID ranges"));
    }
    let nf = if nfc == 3 { 3 + r.get(FACE_COUNT, 0)? } else { nfc };
    if nf > (ops.len() as u64 - addr as u64) * 8 || nf > h.max_faces as u64 {
        return Err(corrupt("face count larger than the data or the header's maximum"));
    }
    if (nf == 0 && pattern != 0) || pattern > 2 {
        return Err(corrupt("bad operation head"));
    }
    let mut faces = crate::pm::SplitFaces::with_capacity(nf as usize);
    let mut prev: Option<(u64, u64, u64)> = None;
    for i in 0..nf {
        let form = match (pattern, i) {
            (0 | 1, 0) => pattern,
            (0 | 1, 1) => 1 - pattern,
            _ => r.get(FACE_FORM, 0)?,
        };
        match form {
            0 | 1 => {
                let t = if v_u - v > 1 { r.get(FACE_T, corner_class(prev.map(|p| p.0), v_u - v))? } else { 0 };
                let u = if v_end - v_u > 1 { r.get(FACE_U, corner_class(prev.map(|p| p.1), v_end - v_u))? } else { 0 };
                let o = match prev {
                    None => r.get(FACE_OTHER, region_class(v, v_end))?,
                    Some((_, _, po)) => po + r.get(FACE_OTHER_DELTA, region_class(v, v_end))?,
                };
                prev = Some((t, u, o));
                let d = unzigzag(o);
                let other = if d < 0 { v as i64 + d } else { v_end as i64 + d };
                let (t, u) = (v as u64 + t, v_u as u64 + u);
                if t >= v_u as u64 || u >= v_end as u64 || other < 0 || other >= n {
                    return Err(corrupt("face corner out of range"));
                }
                let (t, u, other) = (t as u32, u as u32, other as u32);
                faces.push(if form == 0 { [t, u, other] } else { [u, t, other] });
            }
            2 => {
                let mut c = [0u32; 3];
                for x in &mut c {
                    let f = v as i64 + r.get_signed(FACE_GENERAL, 0)?;
                    if f < 0 || f >= n {
                        return Err(corrupt("face corner out of range"));
                    }
                    *x = f as u32;
                }
                faces.push(c);
            }
            _ => return Err(corrupt("bad face form")),
        }
    }
    let (axes, nrm) = position_frame(ctx.normal, h.normal_bits);
    let class = magnitude_class(crit[3]);
    let d0 = r.get_signed(POS_TANGENT, class)?;
    let d1 = r.get_signed(POS_TANGENT, class)?;
    let d2 = tangent_prediction(nrm, d0, d1) + r.get_signed(POS_NORMAL, tangent_class(d0, d1))?;
    let mut position_u = [0u32; 3];
    for (a, d) in axes.into_iter().zip([d0, d1, d2]) {
        let p = ctx.position[a] as i64 + d;
        if !(0..=max_q(h.position_bits) as i64).contains(&p) {
            return Err(corrupt("position out of range"));
        }
        position_u[a] = p as u32;
    }
    let mut normal_u = [0u32; 2];
    let class = magnitude_class(crit[2]);
    for (x, &base) in normal_u.iter_mut().zip(&ctx.normal) {
        let p = base as i64 + r.get_signed(NORMAL, class)?;
        if !(0..=(1i64 << h.normal_bits)).contains(&p) {
            return Err(corrupt("normal out of range"));
        }
        *x = p as u32;
    }
    if !valid_oct(normal_u, h.normal_bits) {
        return Err(corrupt("normal out of range"));
    }
    let both = has_left && has_right;
    // The addresses of the children stored first and second (of those that split).
    let (first, second) = match node {
        None => {
            let offset = if both {
                let residual = r.get_signed(POINTER, split_class(first_size + 2))?;
                let o = pointer_estimate(h.avg_op_size, first_size).saturating_add(residual);
                if o < 1 {
                    return Err(corrupt("bad operation pointer"));
                }
                o as u64
            } else {
                0
            };
            let end = r.end();
            if (has_left || has_right) && end >= ops.len() {
                return Err(DpmError::Truncated("the operations"));
            }
            let second = end as u64 + offset;
            if both && second >= ops.len() as u64 {
                return Err(corrupt("operation pointer past the end of the operations"));
            }
            (end, second as usize)
        }
        Some(n) => {
            /// A child's operation: at an offset from this operation's end in this node, or
            /// at an address in another node.
            enum At {
                Here(u64),
                There(usize),
            }
            let mut read_child = |k: usize, first: Option<&At>| -> Result<At, DpmError> {
                let delta = r.get(NODE_DELTA, k)?;
                if delta != 0 {
                    let target = n as u64 + delta;
                    let local = match first {
                        // Both in one other node: `v_l`'s part there directly before `v_u`'s.
                        Some(&At::There(a)) if (a / NODE_BYTES) as u64 == target => {
                            let l_size = v_u - v;
                            let residual = r.get_signed(POINTER, split_class(l_size + 2))?;
                            let part = pointer_estimate(h.avg_op_size, l_size).saturating_add(residual);
                            let first_local = (a % NODE_BYTES) as i64;
                            let local = if swapped { first_local - part } else { first_local.saturating_add(part) };
                            if part < 1 || local < 0 {
                                return Err(corrupt("bad operation pointer"));
                            }
                            local as u64
                        }
                        _ => r.get(LOCAL, 0)?,
                    };
                    if target >= h.nodes as u64 || local >= NODE_BYTES as u64 {
                        return Err(corrupt("operation pointer past the last node"));
                    }
                    return Ok(At::There((target * NODE_BYTES as u64 + local) as usize));
                }
                // In this node: the first directly after this operation, the second past the
                // first's subtree (its part in this node).
                if k == 0 {
                    return Ok(At::Here(0));
                }
                let first_here = matches!(first, Some(At::Here(_)));
                let estimate = if first_here { pointer_estimate(h.avg_op_size, first_size) } else { 0 };
                let o = estimate.saturating_add(r.get_signed(POINTER, split_class(first_size + 2))?);
                if o < 0 || (first_here && o < 1) {
                    return Err(corrupt("bad operation pointer"));
                }
                Ok(At::Here(o as u64))
            };
            let splitting = has_left as usize + has_right as usize;
            let first = if splitting > 0 { Some(read_child(0, None)?) } else { None };
            let second = if splitting > 1 { Some(read_child(1, first.as_ref())?) } else { None };
            // The offsets in this node are from this operation's end, known only now.
            let end = r.end() as u64;
            let resolve = |a: Option<At>, k: usize| -> Result<usize, DpmError> {
                match a {
                    None => Ok(0),
                    Some(At::There(x)) => Ok(x),
                    Some(At::Here(o)) if end + o < ops.len() as u64 => Ok(n as usize * NODE_BYTES + (end + o) as usize),
                    Some(At::Here(_)) if k == 0 => Err(DpmError::Truncated("the operations")),
                    Some(At::Here(_)) => Err(corrupt("operation pointer past the end of its node")),
                }
            };
            (resolve(first, 0)?, resolve(second, 1)?)
        }
    };
    let end = r.end();
    let (left, right) = match (has_left, has_right, swapped) {
        (true, true, false) => (Some(first), Some(second)),
        (true, true, true) => (Some(second), Some(first)),
        (true, false, _) => (Some(first), None),
        (false, true, _) => (None, Some(first)),
        (false, false, _) => (None, None),
    };
    Ok(DecodedOp {
        split: Split { v, v_u, faces },
        criteria_q: crit,
        criteria: dequantize_criteria(crit, h),
        position_u,
        normal_u,
        left,
        right,
        swapped,
        end,
    })
}

/// The coding form of face `f` of the split of `v` into `v_l` (FVIDs `v..v_u`) and `v_u`
/// (`v_u..v_end`): standard when it has one corner in each child's range and one outside `v`'s,
/// else general.
pub(super) fn classify(v: u32, v_u: u32, v_end: u32, f: [u32; 3]) -> FaceCode {
    let class = |c: u32| {
        if c >= v && c < v_u {
            0
        } else if c >= v_u && c < v_end {
            1
        } else {
            2
        }
    };
    let cl = f.map(class);
    let find = |k| (0..3).find(|&i| cl[i] == k);
    if let (Some(i), Some(j), Some(k)) = (find(0), find(1), find(2)) {
        let o = f[k];
        let d = if o < v { o as i64 - v as i64 } else { (o - v_end) as i64 };
        return FaceCode::Standard { t: f[i] - v, u: f[j] - v_u, o: zigzag(d), rev: j != (i + 1) % 3 };
    }
    FaceCode::General(f.map(|c| c as i64 - v as i64))
}
