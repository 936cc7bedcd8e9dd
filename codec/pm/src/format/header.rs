//! The `.dpm` container and its fixed header: the magic number, the version, the layout of
//! the three checksummed sections ([`crate::container`] checks them), the header's fields byte
//! by byte. What can be wrong with the bytes is a [`DpmError`], the container error type
//! `.bft` files share ([`FormatError`]).

use crate::container::Layout;
pub use crate::container::{Format, FormatError};

pub const MAGIC: [u8; 8] = crate::kind::DPM_MAGIC;
pub const VERSION: u16 = 5;
/// The last version whose operations decode with floating-point steps (`exp`, an `f64`
/// prediction): refused with a message that says how to get a current file.
pub const FLOAT_VERSION: u16 = 2;
/// The last version without a node table (`NODE`) or a node count in the header: its
/// operations decode as version 4's and 5's in-core ones, but its container differs; refused with a
/// message that says how to get a current file.
pub const NODELESS_VERSION: u16 = 3;
/// The last version that coded a second child in the same other node as the first by its
/// whole local address: its out-of-core files decode differently; refused with a message that
/// says how to get a current file.
pub const PAIRLESS_VERSION: u16 = 4;
const HEADER_LEN: usize = 4 * 4 + 2 + 4 * 10;
/// The `.dpm` container: sections TABL, BASE, NODE, OPER (the operations last, so that an
/// out-of-core reader reads everything before them and then the nodes it needs).
pub(super) const LAYOUT: Layout<4> = Layout {
    format: Format::Dpm,
    magic: MAGIC,
    version: VERSION,
    reads: &[VERSION],
    tags: [*b"TABL", *b"BASE", *b"NODE", *b"OPER"],
    names: ["tables section", "base mesh section", "node table", "operations section"],
};

/// The most bytes of operations in one node of an out-of-core file: an operation's address is
/// `node * NODE_BYTES + local` (section 4.2.1's `2^16`), 32 bits in all.
pub const NODE_BYTES: usize = 1 << 16;
/// The most nodes of an out-of-core file (address `u32::MAX` means "none").
pub const MAX_NODES: u32 = (1 << 16) - 1;

/// Everything that can be wrong with `.dpm` bytes: the container error type both formats
/// share. (What keeps a mesh from being encoded is an [`EncodeError`](super::EncodeError).)
pub type DpmError = FormatError;

pub(super) fn corrupt(msg: impl Into<String>) -> DpmError {
    FormatError::Corrupt(Format::Dpm, msg.into())
}

/// Reads a LEB128 integer of a `.dpm` section.
pub(super) fn get_varint(b: &[u8], pos: &mut usize, what: &'static str) -> Result<u64, DpmError> {
    crate::container::get_varint(Format::Dpm, b, pos, what)
}

/// The fixed header, little-endian, `HEADER_LEN` (58) bytes:
///
/// ```text
/// offset  size  field
/// 0       4     vertices (u32)
/// 4       4     base_vertices (u32)
/// 8       4     base_faces (u32)
/// 12      4     splits (u32)
/// 16      1     position_bits (8 to 24)
/// 17      1     normal_bits (4 to 16)
/// 18      12    bbox_min (3 f32)
/// 30      4     step (f32)
/// 34      4     length_step (f32)
/// 38      4     attribute_step (f32)
/// 42      4     avg_op_size (u32, 16.16 fixed point)
/// 46      4     triangles (u32)
/// 50      4     max_faces (u32, at most 65535)
/// 54      4     nodes (u32; 0: in core, else the nodes of the out-of-core hierarchy)
/// ```
///
/// Reading it rejects bit counts out of range, non-finite floats, steps that are not positive,
/// lower bounds of the log codes that are not normal `f32`s below 2^64 (their codes decode by
/// exponent arithmetic), and vertex counts that do not add up (`base_vertices + splits =
/// vertices`, below 2^31), and more than [`MAX_OP_FACES`] faces per operation.
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
    /// Average operation size in 1/65536 bytes (16.16 fixed point), for the address offset
    /// estimate: an integer, so every decoder computes the same estimate.
    pub avg_op_size: u32,
    /// Total triangles after full refinement.
    pub triangles: u32,
    /// The most faces one operation adds: decoders refuse operations with more, which bounds
    /// the work of a corrupt one (a GPU thread's loop, the faces allocated).
    pub max_faces: u32,
    /// The nodes of the out-of-core hierarchy (section 4.1), at most [`MAX_NODES`]; 0 for an
    /// in-core file, whose operation addresses are byte offsets into the operations section.
    pub nodes: u32,
}

/// The most faces an operation may add (the header's `max_faces` at most).
pub const MAX_OP_FACES: u32 = 65535;

impl Header {
    pub(super) fn to_bytes(self) -> Vec<u8> {
        let mut b = Vec::with_capacity(HEADER_LEN);
        for v in [self.vertices, self.base_vertices, self.base_faces, self.splits] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.push(self.position_bits);
        b.push(self.normal_bits);
        for v in
            [self.bbox_min[0], self.bbox_min[1], self.bbox_min[2], self.step, self.length_step, self.attribute_step]
        {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&self.avg_op_size.to_le_bytes());
        b.extend_from_slice(&self.triangles.to_le_bytes());
        b.extend_from_slice(&self.max_faces.to_le_bytes());
        b.extend_from_slice(&self.nodes.to_le_bytes());
        debug_assert_eq!(b.len(), HEADER_LEN);
        b
    }

    pub(super) fn from_bytes(b: &[u8]) -> Result<Self, DpmError> {
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
            avg_op_size: u(42),
            triangles: u(46),
            max_faces: u(50),
            nodes: u(54),
        };
        if !(8..=24).contains(&h.position_bits) || !(4..=16).contains(&h.normal_bits) {
            return Err(corrupt("quantization bits out of range"));
        }
        let log_bound = |x: f32| x.is_normal() && x > 0.0 && x < 1.8e19;
        if !(h.step.is_finite() && h.step > 0.0) {
            return Err(corrupt(format!("header field step: {} is not a finite number above zero", h.step)));
        }
        for (field, v) in [("length_step", h.length_step), ("attribute_step", h.attribute_step)] {
            if !log_bound(v) {
                return Err(corrupt(format!("header field {field}: {v} is not a normal f32 between 0 and 2^64")));
            }
        }
        // Every point of the quantization grid fits f32, computed as dequantization computes
        // it, so that no decoded position (nor a box or camera made from them) is infinite.
        let levels = max_q(h.position_bits);
        for (a, axis) in ["x", "y", "z"].into_iter().enumerate() {
            let min = h.bbox_min[a];
            if !min.is_finite() {
                return Err(corrupt(format!("header field bbox_min: {min} on {axis} does not fit f32")));
            }
            if !(min + levels as f32 * h.step).is_finite() {
                return Err(corrupt(format!(
                    "header field step: {min} + {} x {levels} on {axis} does not fit f32",
                    h.step
                )));
            }
        }
        if h.base_vertices as u64 + h.splits as u64 != h.vertices as u64 || h.vertices >= 1 << 31 {
            return Err(corrupt("vertex counts do not add up"));
        }
        if h.max_faces > MAX_OP_FACES {
            return Err(corrupt("more faces per operation than the format allows"));
        }
        if h.nodes > MAX_NODES {
            return Err(corrupt("more nodes than the format allows"));
        }
        Ok(h)
    }
}

/// The largest code of a `bits`-bit coordinate.
pub(super) fn max_q(bits: u8) -> u32 {
    (1u32 << bits) - 1
}
