//! A chunk's border table, and the octahedral normals it stores.

use super::error::chunk_err;
use super::header::ChunkEntry;
use crate::container::{get_varint, put_varint, Format, FormatError};

/// A unit normal as two 16-bit octahedral coordinates (Meyer et al., "On floating-point
/// normal vectors", 2010): under 1e-4 radians of error, and 4 bytes where three `f32` take 12.
pub fn oct_encode(n: [f32; 3]) -> [u16; 2] {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    let (mut u, mut v) = if l1 > 0.0 { (n[0] / l1, n[1] / l1) } else { (0.0, 0.0) };
    if n[2] < 0.0 {
        let (a, b) = (u, v);
        u = (1.0 - b.abs()) * a.signum();
        v = (1.0 - a.abs()) * b.signum();
    }
    [u, v].map(|c| ((c.clamp(-1.0, 1.0) * 0.5 + 0.5) * 65535.0).round() as u16)
}

/// The unit normal of two octahedral coordinates ([`oct_encode`]); every rank decodes the
/// same bits to the same normal.
pub fn oct_decode(q: [u16; 2]) -> [f32; 3] {
    let [u, v] = q.map(|c| c as f32 / 65535.0 * 2.0 - 1.0);
    let z = 1.0 - u.abs() - v.abs();
    let (x, y) = if z < 0.0 { ((1.0 - v.abs()) * u.signum(), (1.0 - u.abs()) * v.signum()) } else { (u, v) };
    let n = glam::Vec3::new(x, y, z);
    n.try_normalize().unwrap_or(glam::Vec3::Z).to_array()
}

/// A chunk's border table: the slots whose vertex other chunks share.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Border {
    /// Local slots, increasing.
    pub slots: Vec<u32>,
    /// Per slot: `None` for the vertex's first slot in the file, else that first slot.
    pub links: Vec<Option<u32>>,
    /// Per slot: the vertex's normal over the whole model.
    pub normals: Vec<[f32; 3]>,
}

impl Border {
    /// `(local slot, normal)` pairs, as a tile message carries border normals.
    pub fn slot_normals(&self) -> Vec<(u32, [f32; 3])> {
        self.slots.iter().copied().zip(self.normals.iter().copied()).collect()
    }

    pub(crate) fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(self.slots.len() * 16 + 8);
        put_varint(&mut b, self.slots.len() as u64);
        let mut last = 0;
        for (i, (&s, link)) in self.slots.iter().zip(&self.links).enumerate() {
            put_varint(&mut b, (s - if i == 0 { 0 } else { last }) as u64);
            put_varint(&mut b, link.map_or(0, |l| l as u64 + 1));
            last = s;
        }
        for n in &self.normals {
            for v in oct_encode(*n) {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        let crc = crc32fast::hash(&b);
        b.extend_from_slice(&crc.to_le_bytes());
        b
    }

    /// Parses and checks chunk `index`'s border table against its entry: slots in range and
    /// increasing, links to earlier slots of the file, finite normals.
    pub(super) fn from_bytes(b: &[u8], index: usize, e: &ChunkEntry) -> Result<Border, FormatError> {
        let Some(body_len) = b.len().checked_sub(4) else {
            return Err(chunk_err(index, "the border table is truncated"));
        };
        let (body, crc) = b.split_at(body_len);
        if crc32fast::hash(body) != u32::from_le_bytes(crc.try_into().unwrap()) {
            return Err(chunk_err(index, "checksum mismatch in the border table: the file is corrupt"));
        }
        let what = "border table";
        let mut pos = 0;
        let count = get_varint(Format::Bft, body, &mut pos, what)?;
        if count > e.slots as u64 {
            return Err(chunk_err(index, format!("the border table lists {count} slots of {}", e.slots)));
        }
        let mut border = Border::default();
        let mut last = 0u64;
        for i in 0..count {
            let gap = get_varint(Format::Bft, body, &mut pos, what)?;
            let link = get_varint(Format::Bft, body, &mut pos, what)?;
            let slot = if i == 0 { gap } else { last + gap };
            if (i > 0 && gap == 0) || slot >= e.slots as u64 {
                return Err(chunk_err(index, format!("border entry {i} (slot {slot}) is out of order or range")));
            }
            let global = e.first_slot as u64 + slot;
            if link > global {
                return Err(chunk_err(
                    index,
                    format!("border entry {i} links to slot {}, not an earlier one", link - 1),
                ));
            }
            border.slots.push(slot as u32);
            border.links.push(link.checked_sub(1).map(|l| l as u32));
            last = slot;
        }
        let normals = &body[pos..];
        if normals.len() != count as usize * 4 {
            return Err(chunk_err(index, "the border table's normals do not match its count"));
        }
        for n in normals.chunks_exact(4) {
            border.normals.push(oct_decode([u16::from_le_bytes([n[0], n[1]]), u16::from_le_bytes([n[2], n[3]])]));
        }
        Ok(border)
    }
}
