//! The `.bft` file: a magic number, a version, a checksummed header and four (or seven)
//! checksummed sections.
//!
//! ```text
//! offset  size  field
//! 0       8     magic  b"TESSBFT\x1a"
//! 8       2     version (u16 LE): 2, or 4 for a stream with attributes, or 6 for a
//!               prefix-coded one with normals; 1 to 6 are read (3 and 5 chunked)
//! 10      2     header length H in bytes (u16 LE)
//! 12      H     header (little-endian, see `Header`)
//! 12+H    4     CRC-32 of the header bytes
//! then four sections, in this order: CONN, GEOM, DUPS, LOOS (version 4: then COLR, NORM,
//! ORDR), each
//!         4     tag (ASCII)
//!         4     payload length N (u32 LE)
//!         N     payload
//!         4     CRC-32 of the payload
//! ```
//! `CONN` and `GEOM` are range-coded streams ([`crate::rangecoder`]), or prefix-coded ones
//! when the header's coding byte (offset 41 of the header) says so ([`Coding`]). Version 2
//! gave that byte its meaning; in version 1 it was reserved and zero, so a version 1 file is
//! range-coded (and one with a non-zero byte 41 is corrupt), and a reader of version 1 alone
//! refuses a version 2 file rather than misread a prefix-coded one. A coding added since takes
//! a new value of byte 41 ([`Coding::Prefix`] is 2), which a reader that does not know it
//! refuses by number. `DUPS` is the duplicate
//! table (LEB128: count, then per entry the slot's gap from the previous entry and the
//! source slot); `LOOS` holds loose triangles (LEB128: three slots each). Nothing may follow
//! the last section.
//!
//! Version 4 adds per-vertex attributes ([`super::attributes`]): header byte 42 flags them
//! (bit 0 colours, bit 1 their alpha, bit 2 normals, bit 3 the input order), byte 43 gives the
//! normals' octahedral bits. `COLR` and `NORM` are range-coded streams, `ORDR` the input
//! vertex order (`super::order`); a section whose flag is clear is empty. A file without
//! attributes is written as version 2, byte for byte as before; a version 2 file has zero in
//! both bytes.
//!
//! Version 6 is version 4 whose `NORM` section is prefix-coded as its commands and positions
//! are ([`super::attributes`]): what a prefix-coded stream with normals is written as (a tile
//! re-codes its normals every frame). A version 6 stream is prefix-coded and has normals; a
//! prefix-coded version 4 stream, as written before version 6, has range-coded normals and
//! still reads.

pub(crate) use crate::container::put_varint;
use crate::container::Layout;
pub use crate::container::{Format, FormatError};

pub const MAGIC: [u8; 8] = crate::kind::BFT_MAGIC;

/// The version of a chunked file (many streams behind a directory, `super::chunked`).
pub(crate) const CHUNKED_VERSION: u16 = 3;

/// The version of a chunked file with a level-of-detail hierarchy (`super::chunked::lod`).
pub(crate) const LOD_VERSION: u16 = 5;

/// Whether `bytes` start like a chunked `.bft` file (magic and version 3 or 5).
pub fn is_chunked(bytes: &[u8]) -> bool {
    bytes.len() >= 10
        && bytes[..8] == MAGIC
        && matches!(u16::from_le_bytes([bytes[8], bytes[9]]), CHUNKED_VERSION | LOD_VERSION)
}
/// The version written for a stream without attributes.
pub const VERSION: u16 = 2;
/// The version written for a stream with attributes.
pub const VERSION_ATTRIBUTES: u16 = 4;
/// The version written for a prefix-coded stream with normals.
pub const VERSION_PREFIX_NORMALS: u16 = 6;
/// The versions read: 1 (before the coding byte), 2, 3 (chunked files, [`super::chunked`];
/// a single stream is never version 3), 4 (a stream with attributes), 5 (a chunked file
/// with a level-of-detail hierarchy) and 6 (a prefix-coded stream with prefix-coded normals).
pub const READS: &[u16] = &[1, 2, 3, 4, 5, 6];
const HEADER_LEN: usize = 4 * 10 + 4 + 4 * 7;
pub(crate) const SECTION_TAGS: [[u8; 4]; 4] = [*b"CONN", *b"GEOM", *b"DUPS", *b"LOOS"];
/// The sections of a stream, attributes included (version 4 has them all).
pub(crate) const SECTIONS: usize = 7;

/// Which attributes a stream carries (header bytes 42 and 43).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AttributeFlags {
    pub colors: bool,
    /// Colours with alpha (only with `colors`).
    pub alpha: bool,
    /// Bits per octahedral normal coordinate; 0 for no normals.
    pub normal_bits: u8,
    /// The input vertex order is stored (`encode --keep-order`).
    pub order: bool,
}

impl AttributeFlags {
    pub fn is_none(&self) -> bool {
        *self == AttributeFlags::default()
    }

    fn byte(&self) -> u8 {
        self.colors as u8 | (self.alpha as u8) << 1 | ((self.normal_bits > 0) as u8) << 2 | (self.order as u8) << 3
    }

    fn from_bytes(flags: u8, bits: u8) -> Result<Self, BftError> {
        let f = AttributeFlags {
            colors: flags & 1 != 0,
            alpha: flags & 2 != 0,
            normal_bits: if flags & 4 != 0 { bits } else { 0 },
            order: flags & 8 != 0,
        };
        if flags >> 4 != 0 || (f.alpha && !f.colors) || (flags & 4 == 0 && bits != 0) {
            return Err(corrupt(format!("unknown attribute flags {flags:#x}/{bits}")));
        }
        if flags & 4 != 0 && !(4..=16).contains(&bits) {
            return Err(corrupt(format!("normals of {bits} bits are outside 4..=16")));
        }
        Ok(f)
    }
}

/// Everything that can be wrong with `.bft` bytes: the container error type both formats
/// share.
pub type BftError = FormatError;

pub(crate) fn corrupt(msg: impl Into<String>) -> BftError {
    FormatError::Corrupt(Format::Bft, msg.into())
}

/// Reads a LEB128 integer of a `.bft` section.
pub(crate) fn get_varint(b: &[u8], pos: &mut usize, what: &'static str) -> Result<u64, BftError> {
    crate::container::get_varint(Format::Bft, b, pos, what)
}

/// How a file's `CONN` and `GEOM` streams are entropy-coded (header byte 41).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Coding {
    /// The adaptive binary range coder with context models: the smallest streams (but for
    /// small ones, such as a chunked file's chunks), and what `tessera encode` writes by
    /// default.
    #[default]
    Range = 0,
    /// Static canonical Huffman codes, a table per context stored at the head of each stream,
    /// sign and mantissa bits raw, with a command's table chosen by the previous command's
    /// class and the left vertex's degree. What the tile sort wrote before
    /// [`Coding::Prefix`]; still read, and written only where asked for.
    PrefixByDegree = 1,
    /// As [`Coding::PrefixByDegree`], with a command's table chosen by the previous command
    /// alone: a few percent larger than [`Coding::Range`] and several times faster to write
    /// and read. The tile sort's fast mode writes it (see `codec::bft::prefix`).
    Prefix = 2,
}

/// The fixed header: counts, quantization and bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Header {
    /// Vertices in the input mesh, used or not.
    pub input_vertices: u32,
    /// Decoded vertex slots, duplicates included.
    pub slots: u32,
    /// Triangles, loose ones included.
    pub triangles: u32,
    pub loose_triangles: u32,
    pub commands: u32,
    /// `SEED` commands: connected pieces the traversal started.
    pub seeds: u32,
    pub duplicates: u32,
    /// Slots created after the traversal for vertices only loose triangles use.
    pub tail_slots: u32,
    /// Connected components (triangles joined through shared vertices).
    pub components: u32,
    pub quant_bits: u8,
    pub coding: Coding,
    pub bbox_min: [f32; 3],
    pub step: f32,
    pub bbox_max: [f32; 3],
    /// Per-vertex attributes (version 4).
    pub attributes: AttributeFlags,
}

impl Header {
    pub fn unique_vertices(&self) -> u32 {
        self.slots - self.duplicates
    }

    fn to_bytes(self) -> Vec<u8> {
        let mut b = Vec::with_capacity(HEADER_LEN);
        for v in [
            self.input_vertices,
            self.slots,
            self.triangles,
            self.loose_triangles,
            self.commands,
            self.seeds,
            self.duplicates,
            self.tail_slots,
            self.components,
            0,
        ] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&[self.quant_bits, self.coding as u8, self.attributes.byte(), self.attributes.normal_bits]);
        put_box(&mut b, self.bbox_min, self.step, self.bbox_max);
        debug_assert_eq!(b.len(), HEADER_LEN);
        b
    }

    fn from_bytes(b: &[u8]) -> Result<Self, BftError> {
        if b.len() != HEADER_LEN {
            return Err(corrupt(format!("header is {} bytes, expected {HEADER_LEN}", b.len())));
        }
        let u = |i: usize| u32::from_le_bytes(b[4 * i..4 * i + 4].try_into().unwrap());
        let f = |off: usize| f32::from_le_bytes(b[off..off + 4].try_into().unwrap());
        let h = Header {
            input_vertices: u(0),
            slots: u(1),
            triangles: u(2),
            loose_triangles: u(3),
            commands: u(4),
            seeds: u(5),
            duplicates: u(6),
            tail_slots: u(7),
            components: u(8),
            quant_bits: b[40],
            coding: match b[41] {
                0 => Coding::Range,
                1 => Coding::PrefixByDegree,
                2 => Coding::Prefix,
                c => return Err(corrupt(format!("unknown entropy coding {c}"))),
            },
            bbox_min: [f(44), f(48), f(52)],
            step: f(56),
            bbox_max: [f(60), f(64), f(68)],
            attributes: AttributeFlags::from_bytes(b[42], b[43])?,
        };
        check_quantization(h.quant_bits, h.bbox_min, h.step, h.bbox_max)?;
        if h.loose_triangles > h.triangles || h.duplicates > h.slots || h.tail_slots > h.slots {
            return Err(corrupt("inconsistent counts in header"));
        }
        h.check_counts()?;
        Ok(h)
    }

    /// Refuses counts whose decoded arrays would exceed the cap on decompressed input
    /// ([`crate::input::max_decompressed_bytes`]), before the decoder allocates them: per slot
    /// its position and the attributes the stream carries (as the decoded mesh holds them:
    /// 12 bytes, colours 4, normals 12, the input index 4), per triangle 12 bytes, per
    /// command 8 (the tile sort records them), and with the input order every input vertex
    /// (`Decoded::to_mesh` gives each a place, with its colour and normal).
    fn check_counts(&self) -> Result<(), BftError> {
        let a = self.attributes;
        let per_vertex = 12 + if a.colors { 4 } else { 0 } + if a.normal_bits > 0 { 12 } else { 0 };
        let per_slot = per_vertex + if a.order { 4 } else { 0 };
        let check = |field: &str, count: u32, unit: &str, each: u64| {
            crate::input::check_decoded(&format!("header field {field}"), count.into(), unit, each)
                .map_err(BftError::TooLarge)
        };
        check("slots", self.slots, "vertex slots", per_slot)?;
        check("triangles", self.triangles, "triangles", 12)?;
        check("commands", self.commands, "commands", 8)?;
        if a.order {
            check("input_vertices", self.input_vertices, "input vertices", per_vertex)?;
        }
        Ok(())
    }
}

/// Appends the quantization's box both `.bft` headers end with: its min corner, step and max
/// corner, seven `f32` LE.
pub(crate) fn put_box(b: &mut Vec<u8>, min: [f32; 3], step: f32, max: [f32; 3]) {
    for v in min.iter().chain(&[step]).chain(&max) {
        b.extend_from_slice(&v.to_le_bytes());
    }
}

/// The checks of a header's quantization, single-stream or chunked: 8 to 24 bits, a finite
/// positive step, a finite and ordered box, and a grid whose every point fits `f32` (the
/// far corner `bbox_min + step * (2^bits - 1)`, computed as dequantization computes it), so
/// that no decoded position, chunk box or camera built from them is infinite.
pub(crate) fn check_quantization(bits: u8, min: [f32; 3], step: f32, max: [f32; 3]) -> Result<(), BftError> {
    if !(8..=24).contains(&bits) {
        return Err(corrupt(format!("header field quant_bits: {bits} bits is outside 8..=24")));
    }
    if !(step.is_finite() && step > 0.0) {
        return Err(corrupt(format!("header field step: {step} is not a finite number above zero")));
    }
    const AXES: [&str; 3] = ["x", "y", "z"];
    for a in 0..3 {
        if !min[a].is_finite() || !max[a].is_finite() {
            return Err(corrupt(format!(
                "header field bbox: {} .. {} on {} does not fit f32",
                min[a], max[a], AXES[a]
            )));
        }
        if min[a] > max[a] {
            return Err(corrupt(format!("header field bbox: {} .. {} on {} is not ordered", min[a], max[a], AXES[a])));
        }
        let levels = (1u32 << bits) - 1;
        let far = min[a] + levels as f32 * step;
        if !far.is_finite() {
            return Err(corrupt(format!(
                "header field step: {} + {step} x {levels} on {} does not fit f32",
                min[a], AXES[a]
            )));
        }
    }
    Ok(())
}

/// The parts of a `.bft` file, borrowed from its bytes: CONN, GEOM, DUPS, LOOS, COLR, NORM,
/// ORDR (the last three empty before version 4).
pub(crate) struct Parts<'a> {
    pub header: Header,
    pub sections: [&'a [u8]; SECTIONS],
    /// `NORM` is prefix-coded (version 6).
    pub prefix_normals: bool,
}

/// The `.bft` container: sections CONN, GEOM, DUPS, LOOS.
const LAYOUT: Layout<4> = Layout {
    format: Format::Bft,
    magic: MAGIC,
    version: VERSION,
    reads: READS,
    tags: SECTION_TAGS,
    names: ["connectivity section", "geometry section", "duplicate table", "loose triangles"],
};

/// The version 4 container: the attribute sections too.
const LAYOUT_ATTRIBUTES: Layout<SECTIONS> = Layout {
    format: Format::Bft,
    magic: MAGIC,
    version: VERSION_ATTRIBUTES,
    reads: READS,
    tags: [*b"CONN", *b"GEOM", *b"DUPS", *b"LOOS", *b"COLR", *b"NORM", *b"ORDR"],
    names: [
        "connectivity section",
        "geometry section",
        "duplicate table",
        "loose triangles",
        "colour section",
        "normal section",
        "vertex order",
    ],
};

/// The version 6 container: version 4's sections, `NORM` prefix-coded.
const LAYOUT_PREFIX_NORMALS: Layout<SECTIONS> = Layout { version: VERSION_PREFIX_NORMALS, ..LAYOUT_ATTRIBUTES };

/// Whether a stream with this header is written as version 6.
fn prefix_normals(header: &Header) -> bool {
    header.coding != Coding::Range && header.attributes.normal_bits > 0
}

/// Writes a stream: version 2 when the header flags no attribute (the last three sections
/// are then empty), version 6 when it is prefix-coded with normals, else version 4.
pub(crate) fn write(header: &Header, sections: [&[u8]; SECTIONS]) -> Vec<u8> {
    if header.attributes.is_none() {
        debug_assert!(sections[4..].iter().all(|s| s.is_empty()));
        LAYOUT.write(&header.to_bytes(), [sections[0], sections[1], sections[2], sections[3]])
    } else if prefix_normals(header) {
        LAYOUT_PREFIX_NORMALS.write(&header.to_bytes(), sections)
    } else {
        LAYOUT_ATTRIBUTES.write(&header.to_bytes(), sections)
    }
}

pub(crate) fn parse(bytes: &[u8]) -> Result<Parts<'_>, BftError> {
    let version = bytes.get(8..10).map(|v| u16::from_le_bytes([v[0], v[1]]));
    let (header, version, sections) = if matches!(version, Some(VERSION_ATTRIBUTES | VERSION_PREFIX_NORMALS)) {
        let c = LAYOUT_ATTRIBUTES.parse(bytes)?;
        (c.header, c.version, c.sections)
    } else {
        let c = LAYOUT.parse(bytes)?;
        let [a, b, d, e] = c.sections;
        (c.header, c.version, [a, b, d, e, &[][..], &[][..], &[][..]])
    };
    let header = Header::from_bytes(header)?;
    if version == 1 && header.coding != Coding::Range {
        return Err(corrupt("a version 1 file has a non-zero reserved byte 41"));
    }
    let with_attributes = matches!(version, VERSION_ATTRIBUTES | VERSION_PREFIX_NORMALS);
    if !with_attributes && !header.attributes.is_none() {
        return Err(corrupt(format!("a version {version} file has non-zero reserved bytes 42 and 43")));
    }
    if with_attributes && header.attributes.is_none() {
        return Err(corrupt(format!("a version {version} file flags no attribute")));
    }
    let prefix_normals = version == VERSION_PREFIX_NORMALS;
    if prefix_normals && !self::prefix_normals(&header) {
        return Err(corrupt("a version 6 file is not a prefix-coded stream with normals"));
    }
    Ok(Parts { header, sections, prefix_normals })
}

/// Sizes and rates of a `.bft` file, as `tessera stats` reports them.
#[derive(Clone, Debug, PartialEq)]
pub struct Stats {
    pub header: Header,
    pub bytes: usize,
    pub connectivity_bytes: usize,
    pub geometry_bytes: usize,
    /// The attribute sections: colours, normals, input order.
    pub color_bytes: usize,
    pub normal_bytes: usize,
    pub order_bytes: usize,
    /// Chunks of a chunked file (1 for a single stream).
    pub chunks: u32,
    /// A chunked file's border tables (shared vertices' links and normals).
    pub border_bytes: usize,
    /// Their entries (slots of a vertex other chunks share), of which `border_links` name
    /// the vertex's first slot in an earlier chunk or earlier in the chunk; each entry's
    /// normal takes 4 bytes of the tables.
    pub border_entries: u64,
    pub border_links: u64,
}

impl Stats {
    /// The sizes of a single-stream file (`Stats::of` takes a chunked file too).
    pub(crate) fn of_stream(bytes: &[u8]) -> Result<Stats, BftError> {
        let p = parse(bytes)?;
        Ok(Stats {
            header: p.header,
            bytes: bytes.len(),
            connectivity_bytes: p.sections[0].len() + p.sections[2].len() + p.sections[3].len(),
            geometry_bytes: p.sections[1].len(),
            color_bytes: p.sections[4].len(),
            normal_bytes: p.sections[5].len(),
            order_bytes: p.sections[6].len(),
            chunks: 1,
            border_bytes: 0,
            border_entries: 0,
            border_links: 0,
        })
    }

    /// Connectivity (commands, offsets, duplicate table, loose triangles) per triangle.
    pub fn connectivity_bits_per_triangle(&self) -> f64 {
        self.connectivity_bytes as f64 * 8.0 / self.header.triangles.max(1) as f64
    }

    pub fn geometry_bits_per_vertex(&self) -> f64 {
        self.per_vertex(self.geometry_bytes)
    }

    /// Bits per (unique) vertex of `bytes`.
    pub fn per_vertex(&self, bytes: usize) -> f64 {
        bytes as f64 * 8.0 / self.header.unique_vertices().max(1) as f64
    }
}

/// Wraps arbitrary bytes in a well-formed container (small counts from the first bytes,
/// the rest split into the four sections, checksums computed), so that a fuzzer reaches
/// the stream decoders instead of stopping at a checksum. Not a file format.
#[doc(hidden)]
pub fn wrap_for_fuzzing(data: &[u8]) -> Vec<u8> {
    let byte = |i: usize| data.get(i).copied().unwrap_or(0) as u32;
    let small = |i: usize| byte(i) | (byte(i + 1) << 8);
    let header = Header {
        input_vertices: small(0),
        slots: small(2),
        triangles: small(4),
        loose_triangles: byte(6) % 4,
        commands: small(7),
        seeds: 0,
        duplicates: byte(9) % 4,
        tail_slots: byte(10) % 4,
        components: 0,
        quant_bits: 8 + (byte(11) % 17) as u8,
        coding: [Coding::Range, Coding::PrefixByDegree, Coding::Prefix][byte(12) as usize % 3],
        bbox_min: [0.0; 3],
        step: 1.0,
        bbox_max: [1.0; 3],
        attributes: AttributeFlags {
            colors: byte(13) & 1 != 0,
            alpha: byte(13) & 3 == 3,
            normal_bits: if byte(13) & 4 != 0 { 4 + byte(14) as u8 % 13 } else { 0 },
            order: false,
        },
    };
    let rest = data.get(15..).unwrap_or(&[]);
    let (conn, rest) = rest.split_at(rest.len() / 2);
    let (geom, rest) = rest.split_at(rest.len() * 3 / 4);
    let (dups, rest) = rest.split_at(rest.len() / 2);
    let (loose, rest) = rest.split_at(rest.len() / 2);
    let (colors, normals) = rest.split_at(rest.len() / 2);
    let (colors, normals) = (
        if header.attributes.colors { colors } else { &[][..] },
        if header.attributes.normal_bits > 0 { normals } else { &[][..] },
    );
    write(&header, [conn, geom, dups, loose, colors, normals, &[]])
}
