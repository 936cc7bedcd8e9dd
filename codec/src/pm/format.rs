//! The `.dpm` file: a progressive mesh with every split operation compressed on its own
//! (section 4.2), so that any operation decodes from its starting address and a small context
//! the runtime has at hand ([`OpContext`]).
//!
//! ```text
//! offset  size  field
//! 0       8     magic  b"TESSDPM\x1a"
//! 8       2     version (u16 LE), currently 1
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
//!   symbols per (field, byte significance) context ([`super::huffman`]): per table a flag
//!   byte (0: flat, every symbol 8 bits; 1: 256 code lengths follow).
//! * `BASE` (LEB128): per base vertex its FVID gap to the previous one, its quantized position
//!   (3) and octahedral normal (2), and its first operation's address plus one (0: none);
//!   then the base faces as FVID triples.
//! * `OPER`: the operations in the pre-order of the split forest (an operation, the subtree
//!   of `v_l`, the subtree of `v_u`), each a byte-aligned bit stream. Fields, each value coded
//!   as 7-bit groups, least significant first, with a continuation bit, the group's
//!   significance (0, 1, 2+) selecting the table (contexts by byte significance):
//!   1. criteria: `sin(alpha)` in 8 bits (rounded up), the geometric error, the attribute
//!      error and the radius log-coded at 2% (rounded up, `q * 1.02^(k-1)`, 0 for 0), the first
//!      three as the zigzag difference to the parent operation's (section 4.2.3), the radius
//!      as the zigzag difference to this operation's geometric error;
//!   2. which children split further: 0 none, 1 both, 2 `v_l` only, 3 `v_u` only (4.2.1);
//!   3. `v_u - v - 2`, only when `v_l` splits further (otherwise `v_u = v + 1`, 4.2.2);
//!   4. the number of faces, then per face a form (0/1: one corner in `v_l`'s FVID range, one in
//!      `v_u`'s, one outside `v`'s, with orientation; 2: anything else, e.g. degenerate input
//!      faces) and for forms 0/1 the corners as offsets to `v` and `v_u` and the third corner
//!      as the zigzag of its negative offset to `v` or positive offset to the end of `v`'s
//!      range, sorted, the first absolute and the others as differences (4.2.2); form 2 has
//!      three zigzag offsets to `v`;
//!   5. the position delta of `v_u` to `v` (3 zigzag values, quantized over the bounding box)
//!      and the normal delta (2, octahedral). `v_l` keeps `v`'s position and normal (half-edge
//!      collapses), so its delta is always zero and not stored;
//!   6. when both children split further: the address offset of `v_u`'s operation from the end
//!      of this one, as the zigzag difference to `s_avg * (v_u - v - 1)` (4.2.1).
//!
//! Compression follows the four steps of section 4.2: operations with zero offsets give the
//! first tables; the operations are compressed bottom-up (in reverse pre-order), which fixes
//! the offsets; the tables are rebuilt from those symbols and everything is compressed again.
//!
//! Decisions where the paper is silent or that differ from it:
//! * static canonical Huffman codes instead of arithmetic coding (every operation is padded to
//!   a byte; the padding is reported in [`Stats`]);
//! * the third corner's positive offset is taken to the end of `v`'s FVID range (`v_end`, part
//!   of the context: the left child's range ends at `v_u`, the right child's where `v`'s did)
//!   rather than to the next active vertex, which depends on the runtime state;
//! * the geometric and attribute errors are coded separately (they have different units here),
//!   and the radius too;
//! * the input vertex order ([`ProgressiveMesh::fvid_of_input`]) is not stored: the decoded
//!   mesh is numbered by FVID (`fvid_of_input` is the identity);
//! * the `v_l`/`v_u` swap optimisation of section 4.2.4 is not implemented.

use thiserror::Error;

use super::huffman::{BitReader, BitWriter, Table};
use super::{Criteria, ProgressiveMesh, Split, SplitTree, NONE};
use crate::container::{get_varint, put_varint, ContainerError, Layout};

pub const MAGIC: [u8; 8] = *b"TESSDPM\x1a";
pub const VERSION: u16 = 1;
const HEADER_LEN: usize = 4 * 4 + 2 + 4 * 8;
/// The `.dpm` container: sections TABL, BASE, OPER.
const LAYOUT: Layout<3> = Layout {
    magic: MAGIC,
    version: VERSION,
    tags: [*b"TABL", *b"BASE", *b"OPER"],
    names: ["tables section", "base mesh section", "operations section"],
};

/// Everything that can be wrong with `.dpm` bytes (or with a mesh handed to [`encode`]).
#[derive(Debug, Error, PartialEq)]
pub enum DpmError {
    #[error("not a .dpm file (bad magic number)")]
    BadMagic,
    #[error("unsupported .dpm version {0} (this build reads version {VERSION})")]
    UnsupportedVersion(u16),
    #[error("file is truncated: {0}")]
    Truncated(&'static str),
    #[error("checksum mismatch in {0}: the file is corrupt")]
    Checksum(&'static str),
    #[error("{0} trailing bytes after the last section")]
    TrailingBytes(usize),
    #[error("corrupt .dpm data: {0}")]
    Corrupt(String),
    #[error("invalid progressive mesh: {0}")]
    InvalidMesh(String),
    #[error("invalid options: {0}")]
    InvalidOptions(String),
}

fn corrupt(msg: impl Into<String>) -> DpmError {
    DpmError::Corrupt(msg.into())
}

impl From<ContainerError> for DpmError {
    fn from(e: ContainerError) -> DpmError {
        match e {
            ContainerError::BadMagic => DpmError::BadMagic,
            ContainerError::UnsupportedVersion(v) => DpmError::UnsupportedVersion(v),
            ContainerError::Truncated(what) => DpmError::Truncated(what),
            ContainerError::Checksum(what) => DpmError::Checksum(what),
            ContainerError::TrailingBytes(n) => DpmError::TrailingBytes(n),
            ContainerError::WrongSection(name) => corrupt(format!("expected the {name}")),
            ContainerError::Overlong(what) => corrupt(format!("overlong number in {what}")),
        }
    }
}

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

/// The fixed header.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Header {
    /// Finest-level vertices (FVIDs).
    pub vertices: u32,
    pub base_vertices: u32,
    pub base_faces: u32,
    pub splits: u32,
    pub position_bits: u8,
    pub normal_bits: u8,
    pub bbox_min: [f32; 3],
    /// Position quantization step.
    pub step: f32,
    /// Lower bound `q` of the log-coded lengths (geometric error, radius).
    pub length_step: f32,
    /// Lower bound `q` of the log-coded attribute error.
    pub attribute_step: f32,
    /// Average operation size in bytes, for the address offset estimate.
    pub avg_op_bytes: f32,
    /// Total triangles after full refinement.
    pub triangles: u32,
}

impl Header {
    fn to_bytes(self) -> Vec<u8> {
        let mut b = Vec::with_capacity(HEADER_LEN);
        for v in [self.vertices, self.base_vertices, self.base_faces, self.splits] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.push(self.position_bits);
        b.push(self.normal_bits);
        for v in [
            self.bbox_min[0],
            self.bbox_min[1],
            self.bbox_min[2],
            self.step,
            self.length_step,
            self.attribute_step,
            self.avg_op_bytes,
        ] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&self.triangles.to_le_bytes());
        debug_assert_eq!(b.len(), HEADER_LEN);
        b
    }

    fn from_bytes(b: &[u8]) -> Result<Self, DpmError> {
        if b.len() != HEADER_LEN {
            return Err(corrupt(format!("header is {} bytes, expected {HEADER_LEN}", b.len())));
        }
        let u = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap());
        let f = |i: usize| f32::from_le_bytes(b[i..i + 4].try_into().unwrap());
        let h = Header {
            vertices: u(0),
            base_vertices: u(4),
            base_faces: u(8),
            splits: u(12),
            position_bits: b[16],
            normal_bits: b[17],
            bbox_min: [f(18), f(22), f(26)],
            step: f(30),
            length_step: f(34),
            attribute_step: f(38),
            avg_op_bytes: f(42),
            triangles: u(46),
        };
        if !(8..=24).contains(&h.position_bits) || !(4..=16).contains(&h.normal_bits) {
            return Err(corrupt("quantization bits out of range"));
        }
        let pos = |x: f32| x.is_finite() && x > 0.0;
        if !(h.bbox_min.iter().all(|x| x.is_finite())
            && pos(h.step)
            && pos(h.length_step)
            && pos(h.attribute_step)
            && h.avg_op_bytes.is_finite()
            && h.avg_op_bytes >= 0.0)
        {
            return Err(corrupt("bad quantization parameters"));
        }
        if h.base_vertices as u64 + h.splits as u64 != h.vertices as u64 {
            return Err(corrupt("vertex counts do not add up"));
        }
        Ok(h)
    }
}

// ---- quantization -------------------------------------------------------------------------

const MAX_K: u32 = 1 << 20;
const LN_STEP: f64 = 0.019_802_627_296_179_712; // ln 1.02

fn log_enc(e: f32, q: f32) -> u32 {
    if e.is_nan() {
        return MAX_K;
    }
    if e <= 0.0 {
        return 0;
    }
    if e <= q {
        return 1;
    }
    let k = ((e as f64).ln() - (q as f64).ln()) / LN_STEP;
    let mut k = (k.ceil().min(MAX_K as f64) as u32 + 1).min(MAX_K);
    // Never below the true value.
    while k < MAX_K && log_dec(k, q) < e {
        k += 1;
    }
    k
}

fn log_dec(k: u32, q: f32) -> f32 {
    if k == 0 {
        0.0
    } else {
        (q as f64 * (LN_STEP * (k - 1) as f64).exp()) as f32
    }
}

fn sin_enc(s: f32) -> u32 {
    if s.is_nan() {
        return 255;
    }
    (s.clamp(0.0, 1.0) * 255.0).ceil() as u32
}

fn quantize_criteria(c: &Criteria, h: &Header) -> [u32; 4] {
    [
        sin_enc(c.sin_alpha),
        log_enc(c.geometric_error, h.length_step),
        log_enc(c.attribute_error, h.attribute_step),
        log_enc(c.radius, h.length_step),
    ]
}

fn dequantize_criteria(k: [u32; 4], h: &Header) -> Criteria {
    Criteria {
        sin_alpha: k[0] as f32 / 255.0,
        geometric_error: log_dec(k[1], h.length_step),
        attribute_error: log_dec(k[2], h.attribute_step),
        radius: log_dec(k[3], h.length_step),
    }
}

fn max_q(bits: u8) -> u32 {
    (1u32 << bits) - 1
}

fn quantize_position(p: [f32; 3], h: &Header) -> [u32; 3] {
    let m = max_q(h.position_bits) as f32;
    std::array::from_fn(|i| {
        let x = ((p[i] - h.bbox_min[i]) / h.step).round();
        if x.is_nan() {
            0
        } else {
            x.clamp(0.0, m) as u32
        }
    })
}

fn dequantize_position(q: [u32; 3], h: &Header) -> [f32; 3] {
    std::array::from_fn(|i| h.bbox_min[i] + q[i] as f32 * h.step)
}

/// Octahedral normal coding; `[2^bits, 2^bits]` stands for the zero normal.
fn oct_encode(n: [f32; 3], bits: u8) -> [u32; 2] {
    let zero = 1u32 << bits;
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    if !(l1 > 1e-20 && l1.is_finite()) {
        return [zero, zero];
    }
    let (mut x, mut y) = (n[0] / l1, n[1] / l1);
    if n[2] < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * if ox >= 0.0 { 1.0 } else { -1.0 };
        y = (1.0 - ox.abs()) * if oy >= 0.0 { 1.0 } else { -1.0 };
    }
    let m = max_q(bits) as f32;
    [x, y].map(|c| (((c + 1.0) * 0.5 * m).round()).clamp(0.0, m) as u32)
}

fn oct_decode(q: [u32; 2], bits: u8) -> [f32; 3] {
    let zero = 1u32 << bits;
    if q == [zero, zero] {
        return [0.0; 3];
    }
    let m = max_q(bits) as f32;
    let (mut x, mut y) = (q[0] as f32 / m * 2.0 - 1.0, q[1] as f32 / m * 2.0 - 1.0);
    let z = 1.0 - x.abs() - y.abs();
    if z < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * if ox >= 0.0 { 1.0 } else { -1.0 };
        y = (1.0 - ox.abs()) * if oy >= 0.0 { 1.0 } else { -1.0 };
    }
    let l = (x * x + y * y + z * z).sqrt();
    [x / l, y / l, z / l]
}

fn valid_oct(q: [u32; 2], bits: u8) -> bool {
    let zero = 1u32 << bits;
    q == [zero, zero] || (q[0] < zero && q[1] < zero)
}

fn zigzag(v: i64) -> u64 {
    if v >= 0 {
        2 * v as u64
    } else {
        2 * v.unsigned_abs() - 1
    }
}

fn unzigzag(u: u64) -> i64 {
    if u & 1 == 0 {
        (u >> 1) as i64
    } else {
        -(((u + 1) >> 1) as i64)
    }
}

// ---- symbol coding --------------------------------------------------------------------------

/// The fields of an operation; each has three tables (byte significance 0, 1, 2+).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(usize)]
enum Kind {
    Sin,
    GeomError,
    AttrError,
    Radius,
    Children,
    VuOffset,
    FaceCount,
    FaceForm,
    FaceT,
    FaceU,
    FaceOther,
    FaceOtherDelta,
    FaceGeneral,
    Position,
    Normal,
    Pointer,
}

const KINDS: usize = 16;
const SIGNIFICANCES: usize = 3;
const TABLES: usize = KINDS * SIGNIFICANCES;
const CRITERIA_KINDS: [Kind; 4] = [Kind::Sin, Kind::GeomError, Kind::AttrError, Kind::Radius];

/// Where op symbols go: counted (to build tables) or written.
struct OpWriter<'a> {
    tables: Option<&'a [Table]>,
    counts: Option<&'a mut [[u64; 256]]>,
    w: BitWriter,
}

impl OpWriter<'_> {
    fn put(&mut self, kind: Kind, mut v: u64) {
        let mut i = 0;
        loop {
            let more = v >= 0x80;
            let sym = (v & 0x7f) as u8 | if more { 0x80 } else { 0 };
            let ctx = kind as usize * SIGNIFICANCES + i.min(SIGNIFICANCES - 1);
            if let Some(c) = self.counts.as_deref_mut() {
                c[ctx][sym as usize] += 1;
            }
            if let Some(t) = self.tables {
                t[ctx].encode(&mut self.w, sym);
            }
            v >>= 7;
            i += 1;
            if !more {
                break;
            }
        }
    }
}

struct OpReader<'a, 'b> {
    tables: &'a [Table],
    r: BitReader<'a>,
    bits: Option<&'b mut [u64; KINDS]>,
}

impl OpReader<'_, '_> {
    fn get(&mut self, kind: Kind) -> Result<u64, DpmError> {
        let before = self.r.read;
        let mut v = 0u64;
        for i in 0..10 {
            let ctx = kind as usize * SIGNIFICANCES + i.min(SIGNIFICANCES - 1);
            let sym = self.tables[ctx].decode(&mut self.r).ok_or(DpmError::Truncated("an operation"))?;
            v |= ((sym & 0x7f) as u64) << (7 * i);
            if sym & 0x80 == 0 {
                if let Some(b) = self.bits.as_deref_mut() {
                    b[kind as usize] += self.r.read - before;
                }
                if v > u32::MAX as u64 * 2 + 1 {
                    return Err(corrupt("value out of range in an operation"));
                }
                return Ok(v);
            }
        }
        Err(corrupt("overlong value in an operation"))
    }

    fn get_signed(&mut self, kind: Kind) -> Result<i64, DpmError> {
        Ok(unzigzag(self.get(kind)?))
    }
}

// ---- operations -----------------------------------------------------------------------------

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
    /// One past this operation's last byte.
    pub end: usize,
}

/// A face of a split, prepared for coding.
#[derive(Clone, Copy, Debug)]
enum FaceCode {
    /// Corner offsets to `v` and `v_u`, zigzag third-corner offset, reversed orientation.
    Standard {
        t: u32,
        u: u32,
        o: u64,
        rev: bool,
    },
    General([i64; 3]),
}

/// An operation with everything but its address offset.
struct OpData {
    ctx: OpContext,
    v_u: u32,
    crit: [u32; 4],
    children: u32,
    faces: Vec<FaceCode>,
    dpos: [i64; 3],
    dnrm: [i64; 2],
}

/// The prediction of criterion `i`: the parent's value, except for the radius, which is at
/// most both the parent's radius and this operation's geometric error (the error is the
/// region's farthest vertex raised to its neighbours' errors) and is predicted by the
/// smaller of the two.
fn criteria_prediction(parent: &[u32; 4], this: &[u32; 4], i: usize) -> i64 {
    if i == 3 {
        parent[3].min(this[1]) as i64
    } else {
        parent[i] as i64
    }
}

fn children_symbol(left: bool, right: bool) -> u32 {
    match (left, right) {
        (false, false) => 0,
        (true, true) => 1,
        (true, false) => 2,
        (false, true) => 3,
    }
}

fn pointer_estimate(avg: f32, v: u32, v_u: u32) -> i64 {
    (avg as f64 * (v_u as f64 - v as f64 - 1.0)).round() as i64
}

fn write_op(w: &mut OpWriter, d: &OpData, offset: u64, avg: f32) {
    for (i, &kind) in CRITERIA_KINDS.iter().enumerate() {
        w.put(kind, zigzag(criteria_prediction(&d.ctx.parent_criteria, &d.crit, i) - d.crit[i] as i64));
    }
    w.put(Kind::Children, d.children as u64);
    if d.children == 1 || d.children == 2 {
        w.put(Kind::VuOffset, (d.v_u - d.ctx.v - 2) as u64);
    }
    w.put(Kind::FaceCount, d.faces.len() as u64);
    let mut prev_o = None;
    for f in &d.faces {
        match *f {
            FaceCode::Standard { t, u, o, rev } => {
                w.put(Kind::FaceForm, rev as u64);
                w.put(Kind::FaceT, t as u64);
                w.put(Kind::FaceU, u as u64);
                match prev_o {
                    None => w.put(Kind::FaceOther, o),
                    Some(p) => w.put(Kind::FaceOtherDelta, o - p),
                }
                prev_o = Some(o);
            }
            FaceCode::General(c) => {
                w.put(Kind::FaceForm, 2);
                for x in c {
                    w.put(Kind::FaceGeneral, zigzag(x));
                }
            }
        }
    }
    for x in d.dpos {
        w.put(Kind::Position, zigzag(x));
    }
    for x in d.dnrm {
        w.put(Kind::Normal, zigzag(x));
    }
    if d.children == 1 {
        w.put(Kind::Pointer, zigzag(offset as i64 - pointer_estimate(avg, d.ctx.v, d.v_u)));
    }
}

fn read_op(
    h: &Header,
    tables: &[Table],
    ops: &[u8],
    addr: usize,
    ctx: &OpContext,
    bits: Option<&mut [u64; KINDS]>,
) -> Result<DecodedOp, DpmError> {
    if addr >= ops.len() {
        return Err(corrupt("operation address past the end of the operations"));
    }
    let n = h.vertices as i64;
    let (v, v_end) = (ctx.v, ctx.v_end);
    if v >= v_end || v_end as i64 > n {
        return Err(corrupt("bad operation context"));
    }
    let mut r = OpReader { tables, r: BitReader::new(ops, addr), bits };
    let mut crit = [0u32; 4];
    for i in 0..4 {
        let k = criteria_prediction(&ctx.parent_criteria, &crit, i) - r.get_signed(CRITERIA_KINDS[i])?;
        let max = if i == 0 { 255 } else { MAX_K as i64 };
        if !(0..=max).contains(&k) {
            return Err(corrupt("refinement criterion out of range"));
        }
        crit[i] = k as u32;
    }
    let children = r.get(Kind::Children)?;
    let (has_left, has_right) = match children {
        0 => (false, false),
        1 => (true, true),
        2 => (true, false),
        3 => (false, true),
        _ => return Err(corrupt("bad children code")),
    };
    let v_u = if has_left { v as u64 + 2 + r.get(Kind::VuOffset)? } else { v as u64 + 1 };
    if v_u >= v_end as u64 {
        return Err(corrupt("v_u outside the vertex's FVID range"));
    }
    let v_u = v_u as u32;
    // A leaf's range holds exactly one FVID.
    if (has_right && v_end - v_u < 2) || (!has_right && v_end - v_u != 1) {
        return Err(corrupt("split tree inconsistent with the FVID ranges"));
    }
    let nf = r.get(Kind::FaceCount)?;
    if nf > (ops.len() as u64 - addr as u64) * 8 {
        return Err(corrupt("face count larger than the data"));
    }
    let mut faces = Vec::with_capacity(nf as usize);
    let mut prev_o = None;
    for _ in 0..nf {
        let form = r.get(Kind::FaceForm)?;
        match form {
            0 | 1 => {
                let t = v as u64 + r.get(Kind::FaceT)?;
                let u = v_u as u64 + r.get(Kind::FaceU)?;
                let o = match prev_o {
                    None => r.get(Kind::FaceOther)?,
                    Some(p) => p + r.get(Kind::FaceOtherDelta)?,
                };
                prev_o = Some(o);
                let d = unzigzag(o);
                let other = if d < 0 { v as i64 + d } else { v_end as i64 + d };
                if t >= v_u as u64 || u >= v_end as u64 || other < 0 || other >= n {
                    return Err(corrupt("face corner out of range"));
                }
                let (t, u, other) = (t as u32, u as u32, other as u32);
                faces.push(if form == 0 { [t, u, other] } else { [u, t, other] });
            }
            2 => {
                let mut c = [0u32; 3];
                for x in &mut c {
                    let f = v as i64 + r.get_signed(Kind::FaceGeneral)?;
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
    let mut position_u = [0u32; 3];
    for (x, &base) in position_u.iter_mut().zip(&ctx.position) {
        let p = base as i64 + r.get_signed(Kind::Position)?;
        if !(0..=max_q(h.position_bits) as i64).contains(&p) {
            return Err(corrupt("position out of range"));
        }
        *x = p as u32;
    }
    let mut normal_u = [0u32; 2];
    for (x, &base) in normal_u.iter_mut().zip(&ctx.normal) {
        let p = base as i64 + r.get_signed(Kind::Normal)?;
        if !(0..=(1i64 << h.normal_bits)).contains(&p) {
            return Err(corrupt("normal out of range"));
        }
        *x = p as u32;
    }
    if !valid_oct(normal_u, h.normal_bits) {
        return Err(corrupt("normal out of range"));
    }
    let offset = if has_left && has_right {
        let o = pointer_estimate(h.avg_op_bytes, v, v_u) + r.get_signed(Kind::Pointer)?;
        if o < 1 {
            return Err(corrupt("bad operation pointer"));
        }
        Some(o as u64)
    } else {
        None
    };
    let end = r.r.end();
    let left = has_left.then_some(end);
    let right = if has_right {
        let a = end as u64 + offset.unwrap_or(0);
        if a >= ops.len() as u64 {
            return Err(corrupt("operation pointer past the end of the operations"));
        }
        Some(a as usize)
    } else {
        None
    };
    if left.is_some_and(|a| a >= ops.len()) {
        return Err(DpmError::Truncated("the operations"));
    }
    Ok(DecodedOp {
        split: Split { v, v_u, faces },
        criteria_q: crit,
        criteria: dequantize_criteria(crit, h),
        position_u,
        normal_u,
        left,
        right,
        end,
    })
}

fn classify(v: u32, v_u: u32, v_end: u32, f: [u32; 3]) -> FaceCode {
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

// ---- integers in the base mesh section ------------------------------------------------------

fn get_u32(b: &[u8], pos: &mut usize, what: &'static str) -> Result<u32, DpmError> {
    u32::try_from(get_varint(b, pos, what)?).map_err(|_| corrupt(format!("number out of range in {what}")))
}

/// The parsed container: header, tables, the base mesh and the operation bytes.
#[derive(Clone, Debug)]
pub struct Dpm<'a> {
    pub header: Header,
    tables: Vec<Table>,
    /// Base vertex FVIDs, ascending.
    pub base_vertices: Vec<u32>,
    pub base_positions: Vec<[u32; 3]>,
    pub base_normals: Vec<[u32; 2]>,
    /// Per base vertex: the address of its first operation.
    pub roots: Vec<Option<usize>>,
    pub base_faces: Vec<[u32; 3]>,
    pub ops: &'a [u8],
    section_lens: [usize; 3],
}

impl<'a> Dpm<'a> {
    /// Checks the container and reads the tables and the base mesh (not the operations).
    pub fn parse(bytes: &'a [u8]) -> Result<Self, DpmError> {
        let (hb, sections) = LAYOUT.parse(bytes)?;
        let header = Header::from_bytes(hb)?;
        // Tables.
        let tb = sections[0];
        let mut pos = 0;
        let mut tables = Vec::with_capacity(TABLES);
        for _ in 0..TABLES {
            let flag = *tb.get(pos).ok_or(DpmError::Truncated("tables"))?;
            pos += 1;
            let lens: [u8; 256] = match flag {
                0 => [8; 256],
                1 => {
                    let l = tb.get(pos..pos + 256).ok_or(DpmError::Truncated("tables"))?;
                    pos += 256;
                    l.try_into().unwrap()
                }
                _ => return Err(corrupt("bad table flag")),
            };
            tables.push(Table::from_lens(lens).ok_or_else(|| corrupt("invalid code lengths"))?);
        }
        if pos != tb.len() {
            return Err(corrupt("bytes after the tables"));
        }
        // Base mesh.
        let bb = sections[1];
        let ops = sections[2];
        let nb = header.base_vertices as usize;
        if nb > bb.len() / 7 || header.base_faces as usize > bb.len() / 3 || header.splits as usize > ops.len() {
            return Err(corrupt("counts larger than the data"));
        }
        let mut pos = 0;
        let (mut base_vertices, mut base_positions, mut base_normals, mut roots) =
            (Vec::with_capacity(nb), Vec::with_capacity(nb), Vec::with_capacity(nb), Vec::with_capacity(nb));
        let mut next = 0u64;
        for _ in 0..nb {
            let f = next + get_varint(bb, &mut pos, "base vertices")?;
            if f >= header.vertices as u64 {
                return Err(corrupt("base vertex FVID out of range"));
            }
            base_vertices.push(f as u32);
            next = f + 1;
            let mut p = [0u32; 3];
            for x in &mut p {
                *x = get_u32(bb, &mut pos, "base vertices")?;
                if *x > max_q(header.position_bits) {
                    return Err(corrupt("base position out of range"));
                }
            }
            let mut q = [0u32; 2];
            for x in &mut q {
                *x = get_u32(bb, &mut pos, "base vertices")?;
            }
            if !valid_oct(q, header.normal_bits) {
                return Err(corrupt("base normal out of range"));
            }
            base_positions.push(p);
            base_normals.push(q);
            let root = get_varint(bb, &mut pos, "base vertices")?;
            roots.push(match root {
                0 => None,
                a if a - 1 < ops.len() as u64 => Some(a as usize - 1),
                _ => return Err(corrupt("root operation address out of range")),
            });
        }
        if nb > 0 && base_vertices[0] != 0 || (nb == 0 && header.vertices != 0) {
            return Err(corrupt("the first base vertex must have FVID 0"));
        }
        let mut base_faces = Vec::with_capacity(header.base_faces as usize);
        for _ in 0..header.base_faces {
            let mut t = [0u32; 3];
            for x in &mut t {
                *x = get_u32(bb, &mut pos, "base faces")?;
                if *x >= header.vertices {
                    return Err(corrupt("base face FVID out of range"));
                }
            }
            base_faces.push(t);
        }
        if pos != bb.len() {
            return Err(corrupt("bytes after the base mesh"));
        }
        Ok(Dpm {
            header,
            tables,
            base_vertices,
            base_positions,
            base_normals,
            roots,
            base_faces,
            ops,
            section_lens: sections.map(|s| s.len()),
        })
    }

    /// Decodes the single operation at `addr` of the operations section.
    pub fn decode_op(&self, addr: usize, ctx: &OpContext) -> Result<DecodedOp, DpmError> {
        read_op(&self.header, &self.tables, self.ops, addr, ctx, None)
    }

    /// Decodes every operation (pre-order over the forest), optionally counting bits per field.
    fn decode_all(&self, mut bits: Option<&mut [u64; KINDS]>) -> Result<Decoded, DpmError> {
        let h = &self.header;
        let n = h.vertices as usize;
        let mut positions = vec![[0f32; 3]; n];
        let mut normals = vec![[0f32; 3]; n];
        let mut splits = Vec::with_capacity(h.splits as usize);
        let mut criteria = Vec::with_capacity(h.splits as usize);
        let mut addresses = Vec::with_capacity(h.splits as usize);
        let mut contexts = Vec::with_capacity(h.splits as usize);
        let mut stack: Vec<(usize, OpContext)> = vec![];
        for b in 0..self.base_vertices.len() {
            let v = self.base_vertices[b];
            let v_end = self.base_vertices.get(b + 1).copied().unwrap_or(h.vertices);
            positions[v as usize] = dequantize_position(self.base_positions[b], h);
            normals[v as usize] = oct_decode(self.base_normals[b], h.normal_bits);
            let Some(root) = self.roots[b] else {
                if v_end - v != 1 {
                    return Err(corrupt("split tree inconsistent with the FVID ranges"));
                }
                continue;
            };
            stack.push((
                root,
                OpContext {
                    v,
                    v_end,
                    parent_criteria: [0; 4],
                    position: self.base_positions[b],
                    normal: self.base_normals[b],
                },
            ));
            while let Some((addr, ctx)) = stack.pop() {
                if splits.len() >= h.splits as usize {
                    return Err(corrupt("more operations than the header says"));
                }
                let op = read_op(h, &self.tables, self.ops, addr, &ctx, bits.as_deref_mut())?;
                let v_u = op.split.v_u;
                positions[v_u as usize] = dequantize_position(op.position_u, h);
                normals[v_u as usize] = oct_decode(op.normal_u, h.normal_bits);
                if let Some(a) = op.right {
                    stack.push((
                        a,
                        OpContext {
                            v: v_u,
                            v_end: ctx.v_end,
                            parent_criteria: op.criteria_q,
                            position: op.position_u,
                            normal: op.normal_u,
                        },
                    ));
                }
                if let Some(a) = op.left {
                    stack.push((a, OpContext { v_end: v_u, parent_criteria: op.criteria_q, ..ctx }));
                }
                addresses.push(addr);
                contexts.push(ctx);
                criteria.push(op.criteria);
                splits.push(op.split);
            }
        }
        if splits.len() != h.splits as usize {
            return Err(corrupt("fewer operations than the header says"));
        }
        let triangles = self.base_faces.len() as u64 + splits.iter().map(|s| s.faces.len() as u64).sum::<u64>();
        if triangles != h.triangles as u64 {
            return Err(corrupt("triangle count differs from the header"));
        }
        Ok(Decoded {
            pm: ProgressiveMesh {
                base_vertices: self.base_vertices.clone(),
                base_faces: self.base_faces.clone(),
                splits,
                positions,
                fvid_of_input: (0..h.vertices).collect(),
                normals,
                criteria,
            },
            header: *h,
            addresses,
            contexts,
        })
    }
}

/// A decoded `.dpm` file.
#[derive(Clone, Debug)]
pub struct Decoded {
    /// The progressive mesh, splits in the file's (pre-)order, numbered by FVID.
    pub pm: ProgressiveMesh,
    pub header: Header,
    /// Per split: its operation's address in the operations section, and its context.
    pub addresses: Vec<usize>,
    pub contexts: Vec<OpContext>,
}

/// Decodes a `.dpm` file.
pub fn decode(bytes: &[u8]) -> Result<Decoded, DpmError> {
    Dpm::parse(bytes)?.decode_all(None)
}

/// An encoded file and, per split of the input (in its order), the operation's address in the
/// operations section and its context.
#[derive(Clone, Debug)]
pub struct Encoded {
    pub bytes: Vec<u8>,
    pub header: Header,
    pub addresses: Vec<usize>,
    pub contexts: Vec<OpContext>,
}

/// The header's quantization for a mesh.
fn fit_header(pm: &ProgressiveMesh, opts: EncodeOptions) -> Result<Header, DpmError> {
    if !(8..=24).contains(&opts.position_bits) || !(4..=16).contains(&opts.normal_bits) {
        return Err(DpmError::InvalidOptions("position bits must be 8 to 24, normal bits 4 to 16".into()));
    }
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in &pm.positions {
        for i in 0..3 {
            if !p[i].is_finite() {
                return Err(DpmError::InvalidMesh("non-finite position".into()));
            }
            lo[i] = lo[i].min(p[i]);
            hi[i] = hi[i].max(p[i]);
        }
    }
    if pm.positions.is_empty() {
        lo = [0.0; 3];
        hi = [0.0; 3];
    }
    let extent = (0..3).map(|i| hi[i] - lo[i]).fold(0f32, f32::max);
    let mut step = extent / max_q(opts.position_bits) as f32;
    if !(step > 0.0 && step.is_finite()) {
        step = 1.0;
    }
    let n = pm.positions.len();
    Ok(Header {
        vertices: u32::try_from(n).map_err(|_| DpmError::InvalidMesh("too many vertices".into()))?,
        base_vertices: pm.base_vertices.len() as u32,
        base_faces: pm.base_faces.len() as u32,
        splits: pm.splits.len() as u32,
        position_bits: opts.position_bits,
        normal_bits: opts.normal_bits,
        bbox_min: lo,
        step,
        length_step: step * 0.25,
        attribute_step: 1.0 / 4096.0,
        avg_op_bytes: 0.0,
        triangles: (pm.base_faces.len() + pm.splits.iter().map(|s| s.faces.len()).sum::<usize>()) as u32,
    })
}

/// `pm` as the decoder gives it back: positions quantized, normals through the octahedral
/// code, criteria quantized (splits and their order unchanged).
pub fn quantized(pm: &ProgressiveMesh, opts: EncodeOptions) -> Result<ProgressiveMesh, DpmError> {
    let h = fit_header(pm, opts)?;
    let mut q = pm.clone();
    q.positions = pm.positions.iter().map(|&p| dequantize_position(quantize_position(p, &h), &h)).collect();
    q.normals = pm.normals.iter().map(|&n| oct_decode(oct_encode(n, h.normal_bits), h.normal_bits)).collect();
    q.criteria = pm.criteria.iter().map(|c| dequantize_criteria(quantize_criteria(c, &h), &h)).collect();
    Ok(q)
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

    // Pre-order over the forest; per op: split index, right child's op index.
    let mut order: Vec<usize> = Vec::with_capacity(pm.splits.len());
    let mut data: Vec<OpData> = Vec::with_capacity(pm.splits.len());
    let mut right_op: Vec<usize> = Vec::with_capacity(pm.splits.len());
    let mut contexts = vec![OpContext::default(); pm.splits.len()];
    let mut op_of_split = vec![usize::MAX; pm.splits.len()];
    // Stack entries: (split, context, parent op index and side).
    type Pending = (u32, OpContext, Option<(usize, bool)>);
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
        let ctx = OpContext { v, v_end, parent_criteria: [0; 4], position: qpos[v as usize], normal: qnrm[v as usize] };
        stack.push((root, ctx, None));
        while let Some((s, ctx, parent)) = stack.pop() {
            let s = s as usize;
            let split = &pm.splits[s];
            if split.v != ctx.v || split.v_u <= ctx.v || split.v_u >= ctx.v_end || op_of_split[s] != usize::MAX {
                return Err(invalid("split outside its vertex's FVID range"));
            }
            let [l, r] = tree.children[s];
            let (has_l, has_r) = (l != NONE, r != NONE);
            if (!has_l && split.v_u != split.v + 1) || (!has_r && ctx.v_end != split.v_u + 1) {
                return Err(invalid("split tree inconsistent with the FVID ranges"));
            }
            let i = data.len();
            op_of_split[s] = i;
            if let Some((p, true)) = parent {
                right_op[p] = i;
            }
            contexts[s] = ctx;
            let mut faces: Vec<FaceCode> =
                split.faces.iter().map(|&f| classify(split.v, split.v_u, ctx.v_end, f)).collect();
            // Standard faces first, by third-corner offset.
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
                children: children_symbol(has_l, has_r),
                faces,
                dpos: std::array::from_fn(|k| pu[k] as i64 - pv[k] as i64),
                dnrm: std::array::from_fn(|k| nu[k] as i64 - nv[k] as i64),
            });
            order.push(s);
            right_op.push(usize::MAX);
            if has_r {
                let c =
                    OpContext { v: split.v_u, v_end: ctx.v_end, parent_criteria: qcrit[s], position: pu, normal: nu };
                stack.push((r, c, Some((i, true))));
            }
            if has_l {
                let c = OpContext { v_end: split.v_u, parent_criteria: qcrit[s], ..ctx };
                stack.push((l, c, Some((i, false))));
            }
        }
    }
    if data.len() != pm.splits.len() {
        return Err(invalid("splits not reachable from the base vertices"));
    }

    // Step 1-2: tables from the operations with zero offsets.
    let count = |offsets: &[u64], avg: f32| {
        let mut counts = vec![[0u64; 256]; TABLES];
        for (d, &o) in data.iter().zip(offsets) {
            let mut w = OpWriter { tables: None, counts: Some(&mut counts), w: BitWriter::default() };
            write_op(&mut w, d, o, avg);
        }
        counts
    };
    let compress = |tables: &[Table], avg: f32| {
        let mut bytes: Vec<Vec<u8>> = vec![vec![]; data.len()];
        let mut subtree = vec![0u64; data.len()];
        let mut offsets = vec![0u64; data.len()];
        for i in (0..data.len()).rev() {
            let d = &data[i];
            let left = if d.children == 1 || d.children == 2 { subtree[i + 1] } else { 0 };
            let right = if right_op[i] != usize::MAX { subtree[right_op[i]] } else { 0 };
            offsets[i] = left;
            let mut w = OpWriter { tables: Some(tables), counts: None, w: BitWriter::default() };
            write_op(&mut w, d, left, avg);
            bytes[i] = w.w.finish();
            subtree[i] = bytes[i].len() as u64 + left + right;
        }
        (bytes, offsets)
    };
    let tables1: Vec<Table> = count(&vec![0; data.len()], 0.0).iter().map(Table::from_counts).collect();
    // Step 3: bottom-up compression; the average size for the offset estimate comes from it.
    let (bytes1, _) = compress(&tables1, 0.0);
    let avg = bytes1.iter().map(|b| b.len()).sum::<usize>() as f32 / data.len().max(1) as f32;
    let (_, offsets) = compress(&tables1, avg);
    // Step 4: tables from the final symbols, and the final compression.
    let tables: Vec<Table> = count(&offsets, avg).iter().map(Table::from_counts).collect();
    let (op_bytes, _) = compress(&tables, avg);
    h.avg_op_bytes = avg;

    let mut ops = Vec::with_capacity(op_bytes.iter().map(|b| b.len()).sum());
    let mut op_addr = Vec::with_capacity(data.len());
    for b in &op_bytes {
        op_addr.push(ops.len());
        ops.extend_from_slice(b);
    }
    let mut addresses = vec![0usize; pm.splits.len()];
    for (i, &s) in order.iter().enumerate() {
        addresses[s] = op_addr[i];
    }

    // Sections.
    let mut tb = Vec::new();
    for t in &tables {
        if t.lens == [8; 256] {
            tb.push(0);
        } else {
            tb.push(1);
            tb.extend_from_slice(&t.lens);
        }
    }
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
    Ok(Encoded { bytes: out, header: h, addresses, contexts })
}

/// Sizes of a `.dpm` file, with the paper's breakdown of the operations (section 6).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stats {
    pub header: Header,
    pub bytes: usize,
    /// Refinement criteria (sin alpha, errors, radius).
    pub criteria_bytes: f64,
    /// Tree pointers: the children code and the address offsets.
    pub tree_pointer_bytes: f64,
    /// Connectivity: `v_u`'s FVID and the faces.
    pub connectivity_bytes: f64,
    /// Geometry: position and normal deltas.
    pub geometry_bytes: f64,
    /// Byte alignment of the operations.
    pub padding_bytes: f64,
    /// The base mesh section.
    pub base_bytes: usize,
    /// The probability tables section.
    pub table_bytes: usize,
    /// Magic, header, section framing and checksums.
    pub framing_bytes: usize,
}

impl Stats {
    /// Measures a file (decoding every operation).
    pub fn of(bytes: &[u8]) -> Result<Stats, DpmError> {
        let dpm = Dpm::parse(bytes)?;
        let mut bits = [0u64; KINDS];
        dpm.decode_all(Some(&mut bits))?;
        let sum = |ks: &[Kind]| ks.iter().map(|&k| bits[k as usize]).sum::<u64>() as f64 / 8.0;
        let criteria_bytes = sum(&CRITERIA_KINDS);
        let tree_pointer_bytes = sum(&[Kind::Children, Kind::Pointer]);
        let connectivity_bytes = sum(&[
            Kind::VuOffset,
            Kind::FaceCount,
            Kind::FaceForm,
            Kind::FaceT,
            Kind::FaceU,
            Kind::FaceOther,
            Kind::FaceOtherDelta,
            Kind::FaceGeneral,
        ]);
        let geometry_bytes = sum(&[Kind::Position, Kind::Normal]);
        let [tables, base, ops] = dpm.section_lens;
        Ok(Stats {
            header: dpm.header,
            bytes: bytes.len(),
            criteria_bytes,
            tree_pointer_bytes,
            connectivity_bytes,
            geometry_bytes,
            padding_bytes: ops as f64 - criteria_bytes - tree_pointer_bytes - connectivity_bytes - geometry_bytes,
            base_bytes: base,
            table_bytes: tables,
            framing_bytes: bytes.len() - tables - base - ops,
        })
    }

    pub fn bytes_per_vertex(&self) -> f64 {
        self.bytes as f64 / self.header.vertices.max(1) as f64
    }

    /// A part of the breakdown per vertex.
    pub fn per_vertex(&self, bytes: f64) -> f64 {
        bytes / self.header.vertices.max(1) as f64
    }
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
    let tb = [0u8; TABLES];
    let mut bb = vec![];
    put_varint(&mut bb, 0);
    for _ in 0..5 {
        put_varint(&mut bb, 0);
    }
    put_varint(&mut bb, if data.is_empty() { 0 } else { 1 });
    LAYOUT.write(&h.to_bytes(), [&tb, &bb, data])
}
