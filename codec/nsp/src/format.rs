//! The `.nsp` layout (NSP.md 5.3, simplified). All integers little-endian.
//!
//! ```text
//! 0     4   magic b"TNSP"
//! 4     2   version = 1
//! 6     2   flags = 0
//! 8     H   header (HEADER_LEN bytes, below), then its CRC-32
//!       T   the static probability table: u16 count N, then N pairs (u16 context, u16
//!           probability of a 0 in 1/2048), contexts increasing; every other context is
//!           1024; then its CRC-32
//!       ... the cell streams, back to back, in postorder (an empty cell has none)
//!       ... the cell table, in postorder, a row per cell: flags u8 (bit 0 split, bit 1
//!           empty: an empty cell's row ends here), stream length u32,
//!           stream CRC-32, kd-cells at most u32, top-simplices at most u32, the bounding box
//!           of the cell's simplices (inside and outside it) on the full-precision grid, 6 x
//!           u32 (lo, hi inclusive), then the stream's segments: count u8 (one per bit of
//!           precision the cell refines, 0 for an empty cell), each segment's length (LEB128),
//!           each segment's CRC-32; then the table's CRC-32
//! end-20    footer: u64 offset of the cell table, u32 cells, u32 CRC-32 of those 12 bytes,
//!           magic b"TNSP"
//! ```
//! The header holds the parameters, the cube and the canonical complex's counts. The
//! "at most" figures bound what a decoder of that cell may allocate, so a corrupt stream
//! cannot make it grow without end. A reader reads the header, table and footer and then
//! single cells; no checksum covers the whole file, so a file larger than memory is opened
//! without reading it.

use super::canonical::Canonical;
use super::canonical::{Cube, AXES};
use super::complex::CONTEXTS;
use super::error::NspError;
use super::params::Params;

pub const MAGIC: [u8; 4] = crate::kind::NSP_MAGIC;
/// 2: a split's star is coded in kd-cell id order (1: kd-index order), and files may carry
/// the geometry advance.
pub const VERSION: u16 = 2;
pub const HEADER_LEN: usize = 4 + 4 + 4 * 8 + 6 * 8 + 4 + 4 + 3 * 8 + 8;
/// Bytes of a cell table row before its segments.
pub const ROW_FIXED: usize = 41;
pub const FOOTER_LEN: usize = 20;
/// Bytes before the table: magic, version, flags, header and its CRC.
pub const PREFIX_LEN: usize = 8 + HEADER_LEN + 4;
/// Bytes of the smallest table (no entries).
pub const MIN_TABLE_LEN: usize = 2 + 4;
/// A context's probability when the table does not list it.
pub const DEFAULT_PROB: u16 = 1024;

/// Bytes a reader holds per cell before decoding any (its parsed row and its tree node):
/// the footer's count of cells times this is checked against `--max-decompressed`
/// ([`crate::input::max_decompressed_bytes`]) before the table is read, and a build refuses
/// to make more cells than that ([`max_cells`]).
pub const CELL_BYTES: u64 = (std::mem::size_of::<CellEntry>() + std::mem::size_of::<super::tree::Node>() + 8) as u64;

/// Bytes a cell's decoder holds per kd-cell and per top-simplex, at least: a row's "at most"
/// figures times these are checked against `--max-decompressed` when the table is read.
pub const KD_CELL_BYTES: u64 =
    (std::mem::size_of::<super::complex::KdCell>() + std::mem::size_of::<smallvec::SmallVec<[u32; 8]>>() + 4) as u64;
pub const TOP_BYTES: u64 = (std::mem::size_of::<super::complex::Top>() + 3 * 4) as u64;

/// Refuses `count` things of `each` bytes (`what` names them, `field` the file's field) where
/// they would take more than `--max-decompressed`.
fn check_cap(count: u64, each: u64, what: impl FnOnce() -> String) -> Result<(), NspError> {
    let need = count.saturating_mul(each);
    let cap = crate::input::max_decompressed_bytes();
    if need > cap {
        return Err(NspError::TooLarge(format!("{} ({} in memory, the cap is {})", what(), size(need), size(cap))));
    }
    Ok(())
}

/// Bytes for a message: in MiB from 1 MiB up.
fn size(bytes: u64) -> String {
    if bytes < 1 << 20 {
        format!("{bytes} bytes")
    } else {
        format!("{} MiB", bytes >> 20)
    }
}

/// The most cells a reader opens under the `--max-decompressed` now in force (a build makes
/// no more: [`Params::check_cells`](super::params::Params::check_cells)).
pub fn max_cells() -> u64 {
    crate::input::max_decompressed_bytes() / CELL_BYTES
}

impl Params {
    /// Refuses a tree of at least `cells` cells where a reader would not open it
    /// ([`max_cells`]): how many cells a model is cut into follows from `--splits`
    /// and `--min-simplices` (with `--bits` and `--root-bits`, the depth), so the message
    /// names them.
    pub fn check_cells(&self, cells: u64) -> Result<(), NspError> {
        if cells <= max_cells() {
            return Ok(());
        }
        Err(NspError::TooManyCells(format!(
            "--splits {} with --min-simplices {} cuts this model into at least {cells} cells, more than the {} \
                 a reader opens under --max-decompressed ({} MiB at {} bytes a cell); raise --min-simplices or \
                 lower {}",
            self.splits,
            self.min_simplices,
            max_cells(),
            crate::input::max_decompressed_bytes() >> 20,
            CELL_BYTES,
            if self.splits > 2 { "--splits" } else { "--bits" }
        )))
    }
}

/// Bytes of the table written for `table`.
pub fn table_len(table: &[u16]) -> usize {
    MIN_TABLE_LEN + 4 * table.iter().filter(|&&p| p != DEFAULT_PROB).count()
}

/// What the header says.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Header {
    pub params: Params,
    pub cube: Cube,
    pub points: u64,
    pub triangles: u64,
    pub edges: u64,
    pub isolated: u64,
    pub input_triangles: u64,
    pub input_vertices: u64,
    pub cells: u32,
    /// The points' bounding box's extent from the cube's origin (for the default camera).
    pub extent: [f64; 3],
    /// Sum over the leaves of the top-simplices each holds (border duplicates counted).
    pub leaf_simplices: u64,
}

impl Header {
    pub fn new(params: Params, canon: &Canonical) -> Header {
        let count = |d: u8| canon.simplices.iter().filter(|s| s.dim == d).count() as u64;
        Header {
            params,
            cube: canon.cube,
            points: canon.points.len() as u64,
            triangles: count(2),
            edges: count(1),
            isolated: count(0),
            input_triangles: canon.input_triangles,
            input_vertices: canon.input_vertices,
            cells: 0,
            extent: canon.cube_extent,
            leaf_simplices: 0,
        }
    }

    fn put(&self, out: &mut Vec<u8>) {
        let p = &self.params;
        out.extend_from_slice(&[p.bits, p.root_bits, p.splits as u8, p.advance]);
        out.extend_from_slice(&p.min_simplices.to_le_bytes());
        for a in 0..3 {
            out.extend_from_slice(&self.cube.origin[a].to_le_bytes());
        }
        out.extend_from_slice(&self.cube.side.to_le_bytes());
        for v in [self.points, self.triangles, self.edges, self.isolated, self.input_triangles, self.input_vertices] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&self.cells.to_le_bytes());
        out.extend_from_slice(&(CONTEXTS as u32).to_le_bytes());
        for a in 0..3 {
            out.extend_from_slice(&self.extent[a].to_le_bytes());
        }
        out.extend_from_slice(&self.leaf_simplices.to_le_bytes());
    }

    fn get(b: &[u8]) -> Result<Header, NspError> {
        let u64_at = |o: usize| u64::from_le_bytes(b[o..o + 8].try_into().unwrap());
        let f64_at = |o: usize| f64::from_le_bytes(b[o..o + 8].try_into().unwrap());
        let u32_at = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
        let params =
            Params { bits: b[0], root_bits: b[1], splits: b[2] as u32, advance: b[3], min_simplices: u32_at(4) };
        params.validate().map_err(|e| NspError::Format(format!("header: {e}")))?;
        let cube = Cube { origin: [f64_at(8), f64_at(16), f64_at(24)], side: f64_at(32), bits: params.bits };
        if let Err(what) = cube.check_f32() {
            return Err(NspError::Format(format!("header: {what}")));
        }
        let h = Header {
            params,
            cube,
            points: u64_at(40),
            triangles: u64_at(48),
            edges: u64_at(56),
            isolated: u64_at(64),
            input_triangles: u64_at(72),
            input_vertices: u64_at(80),
            cells: u32_at(88),
            extent: [f64_at(96), f64_at(104), f64_at(112)],
            leaf_simplices: u64_at(120),
        };
        if let Some(a) = (0..3).find(|&a| !(h.extent[a].is_finite() && (0.0..=h.cube.side).contains(&h.extent[a]))) {
            return Err(NspError::Format(format!(
                "header: the bounding box's extent on {} is {}, outside the cube's side {}",
                AXES[a],
                super::canonical::num(h.extent[a]),
                super::canonical::num(h.cube.side)
            )));
        }
        if u32_at(92) as usize != CONTEXTS {
            return Err(NspError::Format(format!("header: {} contexts, this reader knows {CONTEXTS}", u32_at(92))));
        }
        Ok(h)
    }
}

/// One row of the cell table.
#[derive(Clone, Debug, PartialEq)]
pub struct CellEntry {
    pub split: bool,
    /// Byte offset of the stream in the file (not stored: running sums of the lengths).
    pub offset: u64,
    pub len: u32,
    pub crc: u32,
    pub max_cells: u32,
    pub max_tops: u32,
    /// The bounding box of the cell's simplices on the full-precision grid (lo, hi
    /// inclusive); what a view must see of the cell to need it.
    pub reach: [[u32; 3]; 2],
    /// Per bit of precision above the minimal one, the stream's end of the bytes a decoder
    /// needs to reach it (increasing; the last is `len`), and the CRC-32 of each segment
    /// (the bytes since the previous end): a view sends and checks only what it decodes.
    pub ends: Vec<u32>,
    pub segment_crcs: Vec<u32>,
}

impl CellEntry {
    /// Bytes of the stream a decoder needs to reach `bits` of precision (the cell's
    /// precision range clamps it; 0 for an empty cell or at its minimal precision).
    pub fn needed(&self, min_prec: u8, bits: u8) -> u32 {
        if bits <= min_prec || self.ends.is_empty() {
            return 0;
        }
        self.ends[((bits - min_prec) as usize).min(self.ends.len()) - 1]
    }

    /// Checks `bytes`, the stream's bytes `from..from + bytes.len()` (whole segments),
    /// against their segments' CRCs; the index of the first bad segment otherwise.
    pub fn check(&self, bytes: &[u8], from: u32) -> Result<(), usize> {
        let to = from + bytes.len() as u32;
        let mut start = 0u32;
        for (k, (&end, &crc)) in self.ends.iter().zip(&self.segment_crcs).enumerate() {
            if start >= from
                && end <= to
                && crc32fast::hash(&bytes[(start - from) as usize..(end - from) as usize]) != crc
            {
                return Err(k);
            }
            start = end;
        }
        Ok(())
    }

    /// Whether `at` is the end of a segment (or 0).
    pub fn is_boundary(&self, at: u32) -> bool {
        at == 0 || self.ends.contains(&at)
    }
}

/// Writes a whole file.
pub fn write(header: &Header, table: &[u16], streams: &[Vec<u8>], entries: &[CellEntry]) -> Vec<u8> {
    let mut header = *header;
    header.cells = entries.len() as u32;
    let mut out = write_prefix(&header, table);
    for s in streams {
        out.extend_from_slice(s);
    }
    let offset = out.len() as u64;
    out.extend_from_slice(&write_cell_table(entries, offset));
    out
}

/// The bytes before the cell streams: magic, version, flags, header, probability table.
pub fn write_prefix(header: &Header, table: &[u16]) -> Vec<u8> {
    let mut out = Vec::with_capacity(PREFIX_LEN + table_len(table));
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    let h0 = out.len();
    header.put(&mut out);
    debug_assert_eq!(out.len() - h0, HEADER_LEN);
    let crc = crc32fast::hash(&out[h0..]);
    out.extend_from_slice(&crc.to_le_bytes());
    let t0 = out.len();
    let listed: Vec<(usize, u16)> = table.iter().copied().enumerate().filter(|&(_, p)| p != DEFAULT_PROB).collect();
    out.extend_from_slice(&(listed.len() as u16).to_le_bytes());
    for (ctx, p) in listed {
        out.extend_from_slice(&(ctx as u16).to_le_bytes());
        out.extend_from_slice(&p.to_le_bytes());
    }
    let crc = crc32fast::hash(&out[t0..]);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// The bytes after the cell streams, which end at `table_offset`: the cell table and the
/// footer.
pub fn write_cell_table(entries: &[CellEntry], table_offset: u64) -> Vec<u8> {
    let mut out = Vec::with_capacity(entries.len() * (ROW_FIXED + 32) + 4 + FOOTER_LEN);
    for e in entries {
        if e.len == 0 {
            out.push(e.split as u8 | 2);
            continue;
        }
        out.push(e.split as u8);
        for v in [e.len, e.crc, e.max_cells, e.max_tops].iter().chain(e.reach.iter().flatten()) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.push(e.ends.len() as u8);
        let mut prev = 0;
        for &end in &e.ends {
            crate::container::put_varint(&mut out, (end - prev) as u64);
            prev = end;
        }
        for crc in &e.segment_crcs {
            out.extend_from_slice(&crc.to_le_bytes());
        }
    }
    let crc = crc32fast::hash(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    let f0 = out.len();
    out.extend_from_slice(&table_offset.to_le_bytes());
    out.extend_from_slice(&(entries.len() as u32).to_le_bytes());
    let crc = crc32fast::hash(&out[f0..]);
    out.extend_from_slice(&crc.to_le_bytes());
    out.extend_from_slice(&MAGIC);
    out
}

fn check_crc<'a>(bytes: &'a [u8], what: &str) -> Result<&'a [u8], NspError> {
    let (body, crc) = bytes.split_at(bytes.len() - 4);
    if crc32fast::hash(body).to_le_bytes() != crc {
        return Err(NspError::Format(format!("{what}: checksum mismatch")));
    }
    Ok(body)
}

/// The length of the prefix (magic, header, table) from its first `PREFIX_LEN + 2` bytes.
pub fn prefix_len(b: &[u8]) -> Result<usize, NspError> {
    if b.len() < PREFIX_LEN + 2 || b[..4] != MAGIC {
        return Err(NspError::Format("no TNSP magic, or the file is shorter than its header".into()));
    }
    let n = u16::from_le_bytes([b[PREFIX_LEN], b[PREFIX_LEN + 1]]) as usize;
    Ok(PREFIX_LEN + MIN_TABLE_LEN + 4 * n)
}

/// Parses the prefix (magic, header, table) of a file: the header, the table, and where
/// the cell streams start.
pub fn read_prefix(b: &[u8]) -> Result<(Header, Vec<u16>, usize), NspError> {
    let end = prefix_len(b)?;
    if b.len() < end {
        return Err(NspError::Format("the file is shorter than its probability table".into()));
    }
    let version = u16::from_le_bytes([b[4], b[5]]);
    if version != VERSION {
        return Err(NspError::Format(format!(
            "version {version}; this reader reads version {VERSION} (rebuild it with tessera nsp build)"
        )));
    }
    let header = Header::get(check_crc(&b[8..PREFIX_LEN], "header")?)?;
    let body = check_crc(&b[PREFIX_LEN..end], "probability table")?;
    let mut table = vec![DEFAULT_PROB; CONTEXTS];
    let mut last: Option<usize> = None;
    for pair in body[2..].chunks_exact(4) {
        let ctx = u16::from_le_bytes([pair[0], pair[1]]) as usize;
        let p = u16::from_le_bytes([pair[2], pair[3]]);
        if ctx >= CONTEXTS || last.is_some_and(|l| ctx <= l) {
            return Err(NspError::Format(format!("probability table: context {ctx} out of order or range")));
        }
        if p == 0 || p >= 2048 {
            return Err(NspError::Format(format!("probability table: context {ctx} has {p} (must be 1 to 2047)")));
        }
        table[ctx] = p;
        last = Some(ctx);
    }
    Ok((header, table, end))
}

/// Parses the footer: (table offset, cells).
pub fn read_footer(b: &[u8], file_len: u64, streams_start: usize) -> Result<(u64, u32), NspError> {
    if b.len() != FOOTER_LEN || b[16..] != MAGIC {
        return Err(NspError::Format("the footer is missing (truncated file?)".into()));
    }
    let body = check_crc(&b[..16], "footer")?;
    let offset = u64::from_le_bytes(body[..8].try_into().unwrap());
    let cells = u32::from_le_bytes(body[8..12].try_into().unwrap());
    let min_len = cells as u64 + 4;
    if offset < streams_start as u64 || offset.checked_add(min_len).is_none_or(|end| end > file_len - FOOTER_LEN as u64)
    {
        return Err(NspError::Format(format!(
            "footer: a cell table of {cells} cells at {offset} does not fit the file"
        )));
    }
    check_cap(cells as u64, CELL_BYTES, || format!("the footer counts {cells} cells"))?;
    let table_len = file_len - FOOTER_LEN as u64 - offset;
    check_cap(table_len, 1, || format!("the cell table is {table_len} bytes"))?;
    Ok((offset, cells))
}

/// Parses the cell table, giving each entry its offset and checking that the streams fill
/// exactly the bytes between the probability table and the cell table.
pub fn read_entries(b: &[u8], table_offset: u64, streams_start: usize) -> Result<Vec<CellEntry>, NspError> {
    let body = check_crc(b, "cell table")?;
    let mut offset = streams_start as u64;
    let mut out = Vec::new();
    let mut at = 0usize;
    while at < body.len() {
        let i = out.len() as u32;
        let bad = |what: &str| NspError::Cell { cell: i, what: format!("its cell table row {what}") };
        let flags = body[at];
        if flags > 3 {
            return Err(bad(&format!("has flags {flags}")));
        }
        if flags & 2 != 0 {
            at += 1;
            out.push(CellEntry {
                split: flags & 1 == 1,
                offset,
                len: 0,
                crc: 0,
                max_cells: 0,
                max_tops: 0,
                reach: [[u32::MAX; 3], [0; 3]],
                ends: Vec::new(),
                segment_crcs: Vec::new(),
            });
            continue;
        }
        let e = body.get(at..at + ROW_FIXED + 1).ok_or_else(|| bad("is truncated"))?;
        let u = |o: usize| u32::from_le_bytes(e[o..o + 4].try_into().unwrap());
        if u(1) == 0 {
            return Err(bad("has an empty stream without the empty flag"));
        }
        check_cap(u(9) as u64, KD_CELL_BYTES, || format!("cell {i}: its cell table row allows {} kd-cells", u(9)))?;
        check_cap(u(13) as u64, TOP_BYTES, || format!("cell {i}: its cell table row allows {} top-simplices", u(13)))?;
        let reach = [[u(17), u(21), u(25)], [u(29), u(33), u(37)]];
        if (0..3).any(|a| reach[0][a] > reach[1][a]) && u(1) > 0 {
            return Err(bad("has an empty bounding box"));
        }
        let n = e[ROW_FIXED] as usize;
        at += ROW_FIXED + 1;
        let mut ends = Vec::with_capacity(n);
        let mut end = 0u64;
        for _ in 0..n {
            let (d, used) = leb128(&body[at.min(body.len())..]).ok_or_else(|| bad("is truncated"))?;
            at += used;
            end += d;
            if end > u(1) as u64 {
                return Err(bad("has segments longer than the stream"));
            }
            ends.push(end as u32);
        }
        if ends.last().copied().unwrap_or(0) != u(1) {
            return Err(bad("has segments that do not end with the stream"));
        }
        let crcs = body.get(at..at + 4 * n).ok_or_else(|| bad("is truncated"))?;
        let segment_crcs = crcs.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect();
        at += 4 * n;
        out.push(CellEntry {
            split: e[0] == 1,
            offset,
            len: u(1),
            crc: u(5),
            max_cells: u(9),
            max_tops: u(13),
            reach,
            ends,
            segment_crcs,
        });
        offset += u(1) as u64;
    }
    if offset != table_offset {
        return Err(NspError::Format(format!(
            "cell table: the streams end at byte {offset}, but the table starts at {table_offset}"
        )));
    }
    Ok(out)
}

/// Recomputes every checksum of the cell table from the streams as they are (for tests and
/// fuzzing: damage a stream, then make its checksums match so the decoder sees the damage).
pub fn refresh_checksums(file: &mut Vec<u8>) -> Result<(), NspError> {
    let n = file.len();
    let (_, _, start) = read_prefix(&file[..n - FOOTER_LEN])?;
    let (offset, _) = read_footer(&file[n - FOOTER_LEN..], n as u64, start)?;
    let mut entries = read_entries(&file[offset as usize..n - FOOTER_LEN], offset, start)?;
    for e in &mut entries {
        let stream = &file[e.offset as usize..(e.offset + e.len as u64) as usize];
        e.crc = crc32fast::hash(stream);
        let mut from = 0;
        for (k, &end) in e.ends.iter().enumerate() {
            e.segment_crcs[k] = crc32fast::hash(&stream[from as usize..end as usize]);
            from = end;
        }
    }
    file.truncate(offset as usize);
    file.extend_from_slice(&write_cell_table(&entries, offset));
    Ok(())
}

/// A LEB128 number and its length in bytes; `None` if it is cut short or wider than 64 bits.
fn leb128(b: &[u8]) -> Option<(u64, usize)> {
    let mut v = 0u64;
    for (i, &byte) in b.iter().enumerate().take(10) {
        v |= ((byte & 0x7f) as u64).checked_shl(7 * i as u32)?;
        if byte & 0x80 == 0 {
            return Some((v, i + 1));
        }
    }
    None
}

/// A valid file whose only cell (a leaf root at 10 bits, decisions at even odds, at most
/// 4,096 kd-cells and 16,384 top-simplices) has `data` after its first byte as its stream,
/// with the geometry advance that byte picks: lets a fuzzer reach the cell decoder past the
/// checksums (`fuzz/fuzz_targets/decode_nsp.rs`).
pub fn wrap_for_fuzzing(data: &[u8]) -> Vec<u8> {
    // The first byte picks the geometry advance (0 to 3), so its prologue and descendant
    // lists are fuzzed too; the rest is the stream.
    let (advance, stream) = match data.split_first() {
        Some((&a, rest)) => (a % 4, rest),
        None => (0, data),
    };
    let params = Params { bits: 10, root_bits: 7, splits: 4, min_simplices: 8000, advance };
    let header = Header {
        params,
        cube: Cube { origin: [0.0; 3], side: 1.0, bits: 10 },
        points: 0,
        triangles: 0,
        edges: 0,
        isolated: 0,
        input_triangles: 0,
        input_vertices: 0,
        cells: 1,
        extent: [1.0; 3],
        leaf_simplices: 0,
    };
    let entry = CellEntry {
        split: false,
        offset: 0,
        len: stream.len() as u32,
        crc: crc32fast::hash(stream),
        max_cells: 4096,
        max_tops: 16384,
        reach: [[0; 3], [1023; 3]],
        ends: if stream.is_empty() { vec![] } else { vec![stream.len() as u32; 10] },
        segment_crcs: if stream.is_empty() { vec![] } else { vec![crc32fast::hash(stream), 0, 0, 0, 0, 0, 0, 0, 0, 0] },
    };
    write(&header, &[DEFAULT_PROB; CONTEXTS], &[stream.to_vec()], &[entry])
}
