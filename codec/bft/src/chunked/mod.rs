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

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use crate::container::{get_varint, put_varint, Format, FormatError};
use crate::mesh::Quantization;

use super::decode::Decoded;
use super::format::{check_quantization, put_box, Coding, Header, MAGIC};

mod encode;
pub mod sort;

pub use encode::{
    encode_chunked, encode_mesh_chunked, ChunkOptions, ChunkedEncoded, EncodeChunkError, Progress, TriangleSink,
};

/// The version of chunked files.
pub const VERSION: u16 = super::format::CHUNKED_VERSION;
pub use super::format::is_chunked;
/// The default number of triangles per chunk (see `ChunkOptions::chunk_triangles`).
pub const DEFAULT_CHUNK_TRIANGLES: u32 = 4096;
const HEADER_LEN: usize = 4 * 8 + 4 + 4 * 7;
/// Bytes of one directory entry.
pub const ENTRY_LEN: usize = 56;

fn corrupt(msg: impl Into<String>) -> FormatError {
    FormatError::Corrupt(Format::Bft, msg.into())
}

fn chunk_err(i: usize, msg: impl std::fmt::Display) -> FormatError {
    corrupt(format!("chunk {i}: {msg}"))
}

/// An error of chunk `i`'s own stream, named by its chunk: a corrupt stream's message once
/// ("corrupt .bft data: chunk 3: ..."), a stream too large for the cap still too large, and a
/// read that failed as it was.
fn in_chunk(i: usize, e: FormatError) -> FormatError {
    match e {
        FormatError::Corrupt(f, m) => FormatError::Corrupt(f, format!("chunk {i}: {m}")),
        FormatError::TooLarge(m) => FormatError::TooLarge(format!("chunk {i}: {m}")),
        FormatError::Checksum(what) => chunk_err(i, format!("checksum mismatch in its {what}")),
        FormatError::Truncated(what) => chunk_err(i, format!("its {what} is truncated")),
        e @ FormatError::Io(_) => e,
        e => chunk_err(i, e),
    }
}

/// Where a chunked file's bytes come from: bytes in memory (anything `AsRef<[u8]>`: a `Vec`,
/// a slice, a memory map) or a file read with positioned reads ([`FileSource`]). A chunk is
/// read when it is used, so a file larger than memory is never held whole.
pub trait ChunkSource: Sync {
    /// The file's length (when it was opened, for a file).
    fn len(&self) -> u64;

    /// Whether the file has no bytes.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// `len` bytes at `offset`, borrowed from memory or read; `what` names them in an error
    /// ("chunk 12", "the chunk directory").
    fn read_at(&self, offset: u64, len: usize, what: &str) -> Result<Cow<'_, [u8]>, FormatError>;
}

impl<B: AsRef<[u8]> + Sync> ChunkSource for B {
    fn len(&self) -> u64 {
        self.as_ref().len() as u64
    }

    fn read_at(&self, offset: u64, len: usize, what: &str) -> Result<Cow<'_, [u8]>, FormatError> {
        let b = self.as_ref();
        usize::try_from(offset).ok().and_then(|o| b.get(o..o.checked_add(len)?)).map(Cow::Borrowed).ok_or_else(|| {
            FormatError::Io(format!("{what}: {len} bytes at offset {offset} lie past the end ({} bytes)", b.len()))
        })
    }
}

/// A chunked file on disk, read with `pread` (`FileExt::read_exact_at`) chunk by chunk
/// instead of memory-mapped: a file truncated while in use gives an error that names it and
/// the chunk, where a mapping would kill the process with SIGBUS. A file replaced by a rename
/// is still read through the descriptor opened here, unchanged; one rewritten in place is
/// caught by each chunk's checksums (its stream's header and sections, its border table) and
/// its directory entry (counts and box), as any corrupt chunk is.
pub struct FileSource {
    file: std::fs::File,
    path: PathBuf,
    len: u64,
}

impl FileSource {
    /// Opens a regular file (anything else is refused, as [`crate::input::read_file`] does).
    pub fn open(path: &Path) -> Result<FileSource, FormatError> {
        let (file, len) =
            crate::input::open_regular(path).map_err(|e| FormatError::Io(format!("{}: {e}", path.display())))?;
        Ok(FileSource { file, path: path.to_path_buf(), len })
    }

    /// The path the file was opened by.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl ChunkSource for FileSource {
    fn len(&self) -> u64 {
        self.len
    }

    fn read_at(&self, offset: u64, len: usize, what: &str) -> Result<Cow<'_, [u8]>, FormatError> {
        use std::os::unix::fs::FileExt;
        let mut buf = vec![0u8; len];
        self.file.read_exact_at(&mut buf, offset).map_err(|e| {
            let path = self.path.display();
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                FormatError::Io(format!(
                    "{path}: {what}: the file was truncated or replaced while in use (expected {len} bytes at offset {offset})"
                ))
            } else {
                FormatError::Io(format!("{path}: {what}: cannot read {len} bytes at offset {offset}: {e}"))
            }
        })?;
        Ok(Cow::Owned(buf))
    }
}

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
    fn model_header(&self) -> Header {
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

    fn from_bytes(b: &[u8]) -> Result<Self, FormatError> {
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
        // A decoded model gives input vertices a place (with the input order kept, every one
        // of them: `Decoded::to_mesh`), 12 bytes each at least; the chunks' own counts are
        // checked as each chunk's stream is read.
        crate::input::check_decoded("header field input_vertices", h.input_vertices.into(), "input vertices", 12)
            .map_err(FormatError::TooLarge)?;
        Ok(h)
    }
}

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

    fn read(b: &[u8]) -> ChunkEntry {
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

    fn border_range(&self) -> std::ops::Range<usize> {
        let start = self.offset as usize + self.bft_len as usize;
        start..start + self.border_len as usize
    }
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
    fn from_bytes(b: &[u8], index: usize, e: &ChunkEntry) -> Result<Border, FormatError> {
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

/// A chunked file opened on its source (bytes in memory, or a file read by positioned reads:
/// only the header and the directory are read here).
pub struct ChunkedFile<B: ChunkSource> {
    bytes: B,
    pub header: ChunkedHeader,
    pub entries: Vec<ChunkEntry>,
}

impl<B: AsRef<[u8]> + Sync> ChunkedFile<B> {
    /// The file's bytes, for a file held in memory.
    pub fn bytes(&self) -> &[u8] {
        self.bytes.as_ref()
    }
}

impl<B: ChunkSource> ChunkedFile<B> {
    /// Reads and checks the header and the directory: entries contiguous and in order from the
    /// end of the directory to the end of the file, running sums and totals that agree with
    /// the header, boxes inside the quantization grid. Chunks are checked when read.
    pub fn open(bytes: B) -> Result<Self, FormatError> {
        let len = bytes.len();
        // The fixed head (magic, version, header length, and a header of at most 64 KiB with
        // its checksum), as much of it as the file has.
        let head = bytes.read_at(0, len.min(16 + u16::MAX as u64) as usize, "the header")?;
        let b = &head[..];
        if b.len() < 8 || b[..8] != MAGIC {
            return Err(if MAGIC.starts_with(b) {
                FormatError::Truncated("magic number")
            } else {
                FormatError::BadMagic(Format::Bft)
            });
        }
        let take =
            |from: usize, n: usize, what: &'static str| b.get(from..from + n).ok_or(FormatError::Truncated(what));
        let version = u16::from_le_bytes(take(8, 2, "version")?.try_into().unwrap());
        if version != VERSION {
            return Err(FormatError::UnsupportedVersion { format: Format::Bft, found: version, known: super::READS });
        }
        let hlen = u16::from_le_bytes(take(10, 2, "header length")?.try_into().unwrap()) as usize;
        let hbytes = take(12, hlen, "header")?;
        let crc = u32::from_le_bytes(take(12 + hlen, 4, "header checksum")?.try_into().unwrap());
        if crc != crc32fast::hash(hbytes) {
            return Err(FormatError::Checksum("header"));
        }
        let header = ChunkedHeader::from_bytes(hbytes)?;
        let dir_start = 16 + hlen;
        let dir_len = header.chunks as usize * ENTRY_LEN;
        if (len - (dir_start as u64).min(len)) / (ENTRY_LEN as u64) < header.chunks as u64
            || len - ((dir_start + dir_len) as u64).min(len) < 4
        {
            return Err(FormatError::Truncated("chunk directory"));
        }
        // Read only now that the file is known to hold it: the directory's length is the
        // header's chunk count times 56 bytes.
        let dir_bytes = bytes.read_at(dir_start as u64, dir_len + 4, "the chunk directory")?;
        let (dir, crc) = dir_bytes.split_at(dir_len);
        let crc = u32::from_le_bytes(crc.try_into().unwrap());
        if crc != crc32fast::hash(dir) {
            return Err(FormatError::Checksum("chunk directory"));
        }
        let max_level = (1u32 << header.quant_bits) - 1;
        let mut entries = Vec::with_capacity(header.chunks as usize);
        let (mut offset, mut tris, mut slots) = ((dir_start + dir_len + 4) as u64, 0u64, 0u64);
        for (i, raw) in dir.chunks_exact(ENTRY_LEN).enumerate() {
            let e = ChunkEntry::read(raw);
            if e.offset != offset {
                return Err(chunk_err(
                    i,
                    format!("its bytes start at {} but the previous chunk ends at {offset} (ranges overlap, leave gaps or are out of order)", e.offset),
                ));
            }
            let end = e.offset + e.bft_len as u64 + e.border_len as u64;
            if end > len {
                return Err(chunk_err(i, format!("its bytes end at {end}, past the end of the file ({len} bytes)")));
            }
            if e.first_triangle as u64 != tris || e.first_slot as u64 != slots {
                return Err(chunk_err(i, "its first triangle or slot disagrees with the chunks before it"));
            }
            if e.triangles == 0 || e.slots == 0 {
                return Err(chunk_err(i, "it holds no triangle"));
            }
            if (0..3).any(|a| e.qmin[a] > e.qmax[a] || e.qmax[a] > max_level) {
                return Err(chunk_err(i, "its bounding box is not ordered inside the quantization grid"));
            }
            offset = end;
            tris += e.triangles as u64;
            slots += e.slots as u64;
            entries.push(e);
        }
        if tris != header.triangles as u64 || slots != header.slots as u64 {
            return Err(corrupt(format!(
                "the chunks hold {tris} triangles and {slots} slots, the header says {} and {}",
                header.triangles, header.slots
            )));
        }
        if offset != len {
            return Err(FormatError::TrailingBytes((len - offset) as usize));
        }
        Ok(ChunkedFile { bytes, header, entries })
    }

    /// The file's length in bytes.
    pub fn file_len(&self) -> u64 {
        self.bytes.len()
    }

    /// The source the file is read from.
    pub fn source(&self) -> &B {
        &self.bytes
    }

    /// The whole file's sizes, as `tessera stats` reports them: the chunks' headers summed
    /// (their sections' bytes, and counts), the border tables apart. Every chunk's container
    /// is parsed and checked (not decoded).
    pub fn stats(&self) -> Result<super::Stats, FormatError> {
        let g = &self.header;
        // Every slot beyond the first of its vertex, in a chunk or across chunks.
        let mut header = Header { duplicates: g.slots - g.unique_vertices, ..g.model_header() };
        let (mut connectivity_bytes, mut geometry_bytes, mut border_bytes) = (0, 0, 0);
        let (mut color_bytes, mut normal_bytes, mut order_bytes) = (0, 0, 0);
        for i in 0..self.entries.len() {
            let bft = self.chunk_bft(i)?;
            let p = super::format::parse(&bft).map_err(|e| in_chunk(i, e))?;
            connectivity_bytes += p.sections[0].len() + p.sections[2].len() + p.sections[3].len();
            geometry_bytes += p.sections[1].len();
            color_bytes += p.sections[4].len();
            normal_bytes += p.sections[5].len();
            order_bytes += p.sections[6].len();
            border_bytes += self.entries[i].border_len as usize;
            add_chunk_counts(&mut header, &p.header);
        }
        Ok(super::Stats {
            header,
            bytes: self.file_len() as usize,
            connectivity_bytes,
            geometry_bytes,
            color_bytes,
            normal_bytes,
            order_bytes,
            chunks: self.entries.len() as u32,
            border_bytes,
        })
    }

    /// Chunk `i`'s `.bft` stream (not yet checked): borrowed from bytes in memory, read from a
    /// file (an error if the file no longer holds it).
    pub fn chunk_bft(&self, i: usize) -> Result<Cow<'_, [u8]>, FormatError> {
        let e = &self.entries[i];
        self.bytes.read_at(e.offset, e.bft_len as usize, &format!("chunk {i}"))
    }

    /// Chunk `i`'s border table, checked.
    pub fn border(&self, i: usize) -> Result<Border, FormatError> {
        let e = &self.entries[i];
        let r = e.border_range();
        let b = self.bytes.read_at(r.start as u64, r.len(), &format!("chunk {i}"))?;
        Border::from_bytes(&b, i, e)
    }

    /// The float bounding box of chunk `i`'s dequantized slots (dequantization is monotone,
    /// so it holds every slot's float position).
    pub fn chunk_box(&self, i: usize) -> ([f32; 3], [f32; 3]) {
        let q = self.header.quantization();
        (q.dequantize(self.entries[i].qmin), q.dequantize(self.entries[i].qmax))
    }

    /// Checks that a decoded chunk agrees with its entry and the file: the same
    /// quantization, counts and bounding box.
    pub fn check_chunk(&self, i: usize, h: &Header, positions: &[[u32; 3]]) -> Result<(), FormatError> {
        let (e, g) = (&self.entries[i], &self.header);
        if h.quant_bits != g.quant_bits || h.bbox_min != g.bbox_min || h.step.to_bits() != g.step.to_bits() {
            return Err(chunk_err(i, "its quantization differs from the file's"));
        }
        if h.triangles != e.triangles || h.slots != e.slots {
            return Err(chunk_err(
                i,
                format!(
                    "it holds {} triangles and {} slots, the directory says {} and {}",
                    h.triangles, h.slots, e.triangles, e.slots
                ),
            ));
        }
        if positions.iter().any(|p| (0..3).any(|a| p[a] < e.qmin[a] || p[a] > e.qmax[a])) {
            return Err(chunk_err(i, "a position lies outside the chunk's bounding box"));
        }
        Ok(())
    }

    /// Decodes chunk `i` with the ordinary decoder and checks it against the directory.
    pub fn decode_chunk(&self, i: usize) -> Result<Decoded, FormatError> {
        let d = super::decode::decode_stream(&self.chunk_bft(i)?).map_err(|e| in_chunk(i, e))?;
        self.check_chunk(i, &d.header, &d.positions)?;
        Ok(d)
    }

    /// The whole file as one decoded model: every chunk's slots and triangles renumbered
    /// after the chunks before it, and the duplicate table extended with the border links,
    /// so that [`Decoded::to_mesh`] welds each input vertex back into one.
    pub fn decode_all(&self) -> Result<Decoded, FormatError> {
        use rayon::prelude::*;
        let parts: Vec<(Decoded, Border)> = (0..self.entries.len())
            .into_par_iter()
            .map(|i| Ok((self.decode_chunk(i)?, self.border(i)?)))
            .collect::<Result<_, FormatError>>()?;
        let g = &self.header;
        let mut out = Decoded {
            header: g.model_header(),
            positions: Vec::with_capacity(g.slots as usize),
            triangles: Vec::with_capacity(g.triangles as usize),
            duplicates: Vec::new(),
            attributes: Default::default(),
        };
        for (i, (e, (d, border))) in self.entries.iter().zip(parts).enumerate() {
            let base = e.first_slot;
            // Every chunk carries the model's attributes (alpha only where some is not 255).
            let (a, flags) = (&mut out.attributes, d.header.attributes);
            if i == 0 {
                a.normal_bits = flags.normal_bits;
                out.header.attributes.colors = flags.colors;
                out.header.attributes.order = flags.order;
            }
            if (flags.colors, flags.normal_bits) != (out.header.attributes.colors, a.normal_bits) {
                return Err(chunk_err(i, "its attributes differ from the first chunk's"));
            }
            a.alpha |= flags.alpha;
            if flags.order != out.header.attributes.order && i > 0 {
                return Err(chunk_err(i, "it keeps the input order and the first chunk does not, or the reverse"));
            }
            a.order.extend_from_slice(&d.attributes.order);
            a.colors.extend_from_slice(&d.attributes.colors);
            a.normals.extend_from_slice(&d.attributes.normals);
            out.positions.extend_from_slice(&d.positions);
            out.triangles.extend(d.triangles.iter().map(|t| t.map(|s| s + base)));
            // A slot's link to an earlier chunk replaces its duplicate entry inside the
            // chunk: both name the same input vertex.
            let mut links =
                border.slots.iter().zip(&border.links).filter_map(|(&s, l)| l.map(|l| (s + base, l))).peekable();
            let mut dups = d.duplicates.iter().map(|&(s, src)| (s + base, src + base)).peekable();
            loop {
                let next = match (dups.peek(), links.peek()) {
                    (None, None) => break,
                    (Some(&a), Some(&b)) if a.0 < b.0 => dups.next(),
                    (Some(&a), Some(&b)) if a.0 == b.0 => {
                        dups.next();
                        links.next()
                    }
                    (Some(_), None) => dups.next(),
                    _ => links.next(),
                };
                out.duplicates.push(next.expect("peeked"));
            }
            add_chunk_counts(&mut out.header, &d.header);
        }
        out.header.duplicates = out.duplicates.len() as u32;
        // The chunks' streams checked their own counts; with the input order kept, the whole
        // model's mesh gives every input vertex of the file's header a place.
        let a = out.header.attributes;
        if a.order {
            let each = 12 + if a.colors { 4 } else { 0 } + if a.normal_bits > 0 { 12 } else { 0 };
            crate::input::check_decoded("header field input_vertices", g.input_vertices.into(), "input vertices", each)
                .map_err(FormatError::TooLarge)?;
        }
        Ok(out)
    }
}

/// Adds a chunk's own counts (loose triangles, commands, seeds, tail slots, components) to
/// the whole model's header.
fn add_chunk_counts(model: &mut Header, chunk: &Header) {
    model.loose_triangles += chunk.loose_triangles;
    model.commands += chunk.commands;
    model.seeds += chunk.seeds;
    model.tail_slots += chunk.tail_slots;
    model.components += chunk.components;
    // The model has alpha where some chunk has it.
    let (m, c) = (&mut model.attributes, chunk.attributes);
    m.colors |= c.colors;
    m.alpha |= c.alpha;
    m.normal_bits = m.normal_bits.max(c.normal_bits);
    m.order |= c.order;
}

/// Writes a chunked file's header and directory (what precedes the chunks).
pub(crate) fn write_head(header: &ChunkedHeader, entries: &[ChunkEntry]) -> Vec<u8> {
    let h = header.to_bytes();
    let mut out = Vec::with_capacity(20 + h.len() + entries.len() * ENTRY_LEN);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&(h.len() as u16).to_le_bytes());
    out.extend_from_slice(&h);
    out.extend_from_slice(&crc32fast::hash(&h).to_le_bytes());
    let dir_start = out.len();
    for e in entries {
        e.write(&mut out);
    }
    let crc = crc32fast::hash(&out[dir_start..]);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// The length of [`write_head`]'s output for `chunks` chunks: where the first chunk starts.
pub(crate) fn head_len(chunks: usize) -> u64 {
    (16 + HEADER_LEN + chunks * ENTRY_LEN + 4) as u64
}

/// Wraps arbitrary bytes in a chunked file whose header and directory checksums are valid
/// (counts and directory entries taken from the bytes, the rest as chunk data), so that a
/// fuzzer reaches the directory's checks and the chunks' parsers instead of stopping at a
/// checksum. Not a file format.
#[doc(hidden)]
pub fn wrap_for_fuzzing(data: &[u8]) -> Vec<u8> {
    let byte = |i: usize| data.get(i).copied().unwrap_or(0);
    let chunks = (byte(0) % 5) as usize;
    let dir = data.get(1..).unwrap_or(&[]);
    let dir_len = (chunks * ENTRY_LEN).min(dir.len());
    let (raw_dir, rest) = dir.split_at(dir_len);
    let mut entries: Vec<ChunkEntry> = raw_dir.chunks_exact(ENTRY_LEN).map(ChunkEntry::read).collect();
    // Half the time, lay the entries out consistently so that the chunks themselves are read.
    let body = head_len(entries.len());
    if byte(1) & 1 == 0 && !entries.is_empty() {
        let per = rest.len() / entries.len();
        let (mut offset, mut tris, mut slots) = (body, 0u32, 0u32);
        for e in &mut entries {
            e.offset = offset;
            e.bft_len = e.bft_len.min(per as u32);
            e.border_len = per as u32 - e.bft_len;
            e.first_triangle = tris;
            e.first_slot = slots;
            offset += per as u64;
            tris = tris.wrapping_add(e.triangles);
            slots = slots.wrapping_add(e.slots);
        }
    }
    let header = ChunkedHeader {
        input_vertices: entries.iter().fold(0u32, |a, e| a.wrapping_add(e.slots)),
        slots: entries.iter().fold(0u32, |a, e| a.wrapping_add(e.slots)),
        triangles: entries.iter().fold(0u32, |a, e| a.wrapping_add(e.triangles)),
        chunks: entries.len() as u32,
        chunk_triangles: 1,
        border_slots: 0,
        unique_vertices: 0,
        commands: 0,
        quant_bits: 8 + byte(2) % 17,
        bbox_min: [0.0; 3],
        step: 1.0,
        bbox_max: [1.0; 3],
    };
    let mut out = write_head(&header, &entries);
    let used = entries.len() * (rest.len() / entries.len().max(1));
    out.extend_from_slice(&rest[..used.min(rest.len())]);
    out
}
