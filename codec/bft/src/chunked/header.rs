//! A chunked file's fixed header and directory entries, and the writing of both.

use super::error::corrupt;
use super::lod::Hierarchy;
use super::{LOD_VERSION, VERSION};
use crate::bft::format::{check_quantization, put_box, Coding, Header, MAGIC};
use crate::container::FormatError;
use crate::mesh::Quantization;

/// Bytes of the fixed header.
pub(crate) const HEADER_LEN: usize = 4 * 8 + 4 + 4 * 7;
/// Bytes of one directory entry.
pub const ENTRY_LEN: usize = 56;

/// The fixed header of a chunked file: the whole model's counts and quantization.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChunkedHeader {
    /// Vertices of the input mesh, used or not.
    pub input_vertices: u32,
    /// Slots of all chunks.
    pub slots: u32,
    pub triangles: u32,
    pub chunks: u32,
    /// The chunk size the encoder aimed at (triangles per chunk).
    pub chunk_triangles: u32,
    /// Entries of all border tables.
    pub border_slots: u32,
    /// Input vertices that triangles use (the whole file welds to this many).
    pub unique_vertices: u32,
    pub commands: u32,
    pub quant_bits: u8,
    pub bbox_min: [f32; 3],
    pub step: f32,
    pub bbox_max: [f32; 3],
}

impl ChunkedHeader {
    pub fn quantization(&self) -> Quantization {
        Quantization { bits: self.quant_bits, min: self.bbox_min, step: self.step }
    }

    /// The whole model as a single-stream header: its counts and quantization, the
    /// per-chunk counts at zero for [`add_chunk_counts`] to sum.
    pub(super) fn model_header(&self) -> Header {
        Header {
            input_vertices: self.input_vertices,
            slots: self.slots,
            triangles: self.triangles,
            loose_triangles: 0,
            commands: 0,
            seeds: 0,
            duplicates: 0,
            tail_slots: 0,
            components: 0,
            quant_bits: self.quant_bits,
            coding: Coding::Range,
            bbox_min: self.bbox_min,
            step: self.step,
            bbox_max: self.bbox_max,
            attributes: Default::default(),
        }
    }

    fn to_bytes(self) -> Vec<u8> {
        let mut b = Vec::with_capacity(HEADER_LEN);
        for v in [
            self.input_vertices,
            self.slots,
            self.triangles,
            self.chunks,
            self.chunk_triangles,
            self.border_slots,
            self.unique_vertices,
            self.commands,
        ] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&[self.quant_bits, 0, 0, 0]);
        put_box(&mut b, self.bbox_min, self.step, self.bbox_max);
        debug_assert_eq!(b.len(), HEADER_LEN);
        b
    }

    pub(super) fn from_bytes(b: &[u8]) -> Result<Self, FormatError> {
        if b.len() != HEADER_LEN {
            return Err(corrupt(format!("chunked header is {} bytes, expected {HEADER_LEN}", b.len())));
        }
        let u = |i: usize| u32::from_le_bytes(b[4 * i..4 * i + 4].try_into().unwrap());
        let f = |off: usize| f32::from_le_bytes(b[off..off + 4].try_into().unwrap());
        let h = ChunkedHeader {
            input_vertices: u(0),
            slots: u(1),
            triangles: u(2),
            chunks: u(3),
            chunk_triangles: u(4),
            border_slots: u(5),
            unique_vertices: u(6),
            commands: u(7),
            quant_bits: b[32],
            bbox_min: [f(36), f(40), f(44)],
            step: f(48),
            bbox_max: [f(52), f(56), f(60)],
        };
        if b[33..36] != [0, 0, 0] {
            return Err(corrupt("reserved header bytes are not zero"));
        }
        check_quantization(h.quant_bits, h.bbox_min, h.step, h.bbox_max)?;
        if h.border_slots > h.slots || h.unique_vertices > h.slots || h.unique_vertices > h.input_vertices {
            return Err(corrupt("inconsistent counts in the chunked header"));
        }
        // The whole model's counts are checked against `--max-decompressed` where the whole
        // model is decoded ([`super::ChunkedFile::decode_all`]), not here: a sort or a render
        // reads a chunk at a time, and a 223M-triangle model's 112M input vertices would
        // take 1.3 GiB decoded whole. Each chunk's own counts are checked as it is read.
        Ok(h)
    }
}

/// One chunk's directory entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChunkEntry {
    /// Byte offset of the chunk's `.bft` stream in the file.
    pub offset: u64,
    /// Bytes of the `.bft` stream, then of the border table.
    pub bft_len: u32,
    pub border_len: u32,
    pub triangles: u32,
    pub slots: u32,
    /// The chunk's first triangle and first slot in the whole model's numbering.
    pub first_triangle: u32,
    pub first_slot: u32,
    /// The quantized bounding box of the chunk's slots.
    pub qmin: [u32; 3],
    pub qmax: [u32; 3],
}

impl ChunkEntry {
    fn write(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.offset.to_le_bytes());
        for v in [self.bft_len, self.border_len, self.triangles, self.slots, self.first_triangle, self.first_slot] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in self.qmin.iter().chain(&self.qmax) {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }

    pub(super) fn read(b: &[u8]) -> ChunkEntry {
        let u = |i: usize| u32::from_le_bytes(b[8 + 4 * i..12 + 4 * i].try_into().unwrap());
        ChunkEntry {
            offset: u64::from_le_bytes(b[..8].try_into().unwrap()),
            bft_len: u(0),
            border_len: u(1),
            triangles: u(2),
            slots: u(3),
            first_triangle: u(4),
            first_slot: u(5),
            qmin: [u(6), u(7), u(8)],
            qmax: [u(9), u(10), u(11)],
        }
    }

    /// The byte range of the chunk's `.bft` stream.
    pub fn bft_range(&self) -> std::ops::Range<usize> {
        self.offset as usize..self.offset as usize + self.bft_len as usize
    }

    pub(super) fn border_range(&self) -> std::ops::Range<usize> {
        let start = self.offset as usize + self.bft_len as usize;
        start..start + self.border_len as usize
    }
}

/// Writes a chunked file's header and directory, and its hierarchy if it has one (what
/// precedes the chunks).
pub(crate) fn write_head(header: &ChunkedHeader, entries: &[ChunkEntry], lod: Option<&Hierarchy>) -> Vec<u8> {
    let h = header.to_bytes();
    let mut out = Vec::with_capacity(head_len(entries.len(), lod) as usize);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&if lod.is_some() { LOD_VERSION } else { VERSION }.to_le_bytes());
    out.extend_from_slice(&(h.len() as u16).to_le_bytes());
    out.extend_from_slice(&h);
    out.extend_from_slice(&crc32fast::hash(&h).to_le_bytes());
    let dir_start = out.len();
    for e in entries {
        e.write(&mut out);
    }
    let crc = crc32fast::hash(&out[dir_start..]);
    out.extend_from_slice(&crc.to_le_bytes());
    if let Some(lod) = lod {
        out.extend_from_slice(&lod.to_bytes());
    }
    out
}

/// The length of [`write_head`]'s output for `chunks` chunks: where the first chunk starts.
pub(crate) fn head_len(chunks: usize, lod: Option<&Hierarchy>) -> u64 {
    let section = lod.map_or(0, |h| Hierarchy::section_len(chunks, h.groups.len()));
    (16 + HEADER_LEN + chunks * ENTRY_LEN + 4 + section) as u64
}
