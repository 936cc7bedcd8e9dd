//! PLY for the streaming reader: a header parser that accepts the headers ply-rs accepts,
//! and also their lines with spaces or tabs before a keyword or several between words, as
//! Draco's reader (`SplitWords`: any run of whitespace separates words) reads them; and record
//! readers that decode a binary record in place in the read buffer and
//! an ASCII record from its line, handing the values they are asked for to a [`Sink`].
//!
//! What `load_path` (through ply-rs) makes of a file, and so what this reader reproduces:
//! * a header element or property named like an earlier one of the same scope replaces it
//!   and moves to the end (ply-rs keeps them in a linked hash map);
//! * a vertex's position is its scalar `x`, `y`, `z` properties, each converted to `f64`
//!   from the type it is stored in and then to `f32`; a missing one, or a list, is 0;
//! * a face's or strip's corners are its last integer list property named `vertex_indices`
//!   or `vertex_index`; an element without one has no corners;
//! * faces of fewer than three corners are dropped before their indices are looked at;
//!   a negative index in a kept face is an error; strips restart at a negative index;
//! * ASCII: one record a line, numbers as ply-rs's grammar has them
//!   (`[-+]?[0-9]+(\.[0-9]+)?(e[-+]?[0-9]+)?`, separated by spaces or tabs), each parsed as
//!   its property's type (a list's count as an unsigned integer, whatever its declared
//!   type); values after the last property are checked but ignored;
//! * binary: a list count of floating-point type is an error, a negative one too;
//! * anything after the last element is ignored.

use std::fmt;
use std::path::Path;

use super::emitter::Emitter;
use super::source::{Input, Source};
use crate::load::error::{err, LoadError};
use crate::Mesh;

/// The longest header line read. ply-rs has no limit, but a header line is a keyword and a
/// few words (or a comment); the limit keeps a binary file that is no PLY from being read
/// whole as one "line".
const MAX_HEADER_LINE: usize = 1 << 16;

/// Vertex elements may not claim more vertices than 32-bit indices address.
const MAX_VERTICES: u64 = 1 << 32;

/// Vertex elements whose records hold no bytes (no properties) may not claim more vertices
/// than this: each would cost 12 bytes of positions and nothing of the file.
const MAX_EMPTY_VERTICES: u64 = 1 << 24;

/// The scalar types of PLY properties, under either of their names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

/// The first `N` bytes of `b` (which the callers have made sure it holds).
#[inline]
fn array<const N: usize>(b: &[u8]) -> [u8; N] {
    let mut a = [0; N];
    a.copy_from_slice(&b[..N]);
    a
}

macro_rules! decode {
    ($t:ty, $b:expr, $big:expr) => {{
        let bytes = array($b);
        if $big {
            <$t>::from_be_bytes(bytes)
        } else {
            <$t>::from_le_bytes(bytes)
        }
    }};
}

impl Scalar {
    fn from_name(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// The binary value at the start of `b` as `f64`, as `load.rs` converts ply-rs's values.
    #[inline(always)]
    fn f64_at(self, b: &[u8], big: bool) -> f64 {
        match self {
            Scalar::I8 => f64::from(decode!(i8, b, big)),
            Scalar::U8 => f64::from(b[0]),
            Scalar::I16 => f64::from(decode!(i16, b, big)),
            Scalar::U16 => f64::from(decode!(u16, b, big)),
            Scalar::I32 => f64::from(decode!(i32, b, big)),
            Scalar::U32 => f64::from(decode!(u32, b, big)),
            Scalar::F32 => f64::from(decode!(f32, b, big)),
            Scalar::F64 => decode!(f64, b, big),
        }
    }

    /// The binary integer at the start of `b`. Floating-point types are never indices or
    /// counts here (the callers check); they convert with `as`.
    #[inline(always)]
    fn int_at(self, b: &[u8], big: bool) -> i64 {
        match self {
            Scalar::I8 => i64::from(decode!(i8, b, big)),
            Scalar::U8 => i64::from(b[0]),
            Scalar::I16 => i64::from(decode!(i16, b, big)),
            Scalar::U16 => i64::from(decode!(u16, b, big)),
            Scalar::I32 => i64::from(decode!(i32, b, big)),
            Scalar::U32 => i64::from(decode!(u32, b, big)),
            Scalar::F32 => decode!(f32, b, big) as i64,
            Scalar::F64 => decode!(f64, b, big) as i64,
        }
    }

    /// An ASCII token parsed as this type (as ply-rs parses it), as `f64`.
    fn ascii_f64(self, token: &str) -> Option<f64> {
        match self {
            Scalar::I8 => token.parse::<i8>().ok().map(f64::from),
            Scalar::U8 => token.parse::<u8>().ok().map(f64::from),
            Scalar::I16 => token.parse::<i16>().ok().map(f64::from),
            Scalar::U16 => token.parse::<u16>().ok().map(f64::from),
            Scalar::I32 => token.parse::<i32>().ok().map(f64::from),
            Scalar::U32 => token.parse::<u32>().ok().map(f64::from),
            Scalar::F32 => token.parse::<f32>().ok().map(f64::from),
            Scalar::F64 => token.parse::<f64>().ok(),
        }
    }

    /// An ASCII token parsed as this (integer) type, as `i64`.
    fn ascii_int(self, token: &str) -> Option<i64> {
        match self {
            Scalar::I8 => token.parse::<i8>().ok().map(i64::from),
            Scalar::U8 => token.parse::<u8>().ok().map(i64::from),
            Scalar::I16 => token.parse::<i16>().ok().map(i64::from),
            Scalar::U16 => token.parse::<u16>().ok().map(i64::from),
            Scalar::I32 => token.parse::<i32>().ok().map(i64::from),
            Scalar::U32 => token.parse::<u32>().ok().map(i64::from),
            Scalar::F32 | Scalar::F64 => None,
        }
    }
}

impl fmt::Display for Scalar {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let name = match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        };
        f.write_str(name)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug, PartialEq)]
pub(super) struct Property {
    pub name: String,
    pub kind: Kind,
}

#[derive(Clone, Debug, PartialEq)]
pub(super) struct Element {
    pub name: String,
    pub count: u64,
    pub properties: Vec<Property>,
}

impl Element {
    /// The size of a binary record, if it has no lists.
    fn fixed_size(&self) -> Option<u64> {
        self.properties
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(t) => Some(t.size() as u64),
                Kind::List { .. } => None,
            })
            .sum()
    }

    /// The fewest bytes a record takes: in binary its scalars and list counts, in ASCII a
    /// character for each value and a separator between them.
    fn min_record_bytes(&self, ascii: bool) -> u64 {
        let n = self.properties.len() as u64;
        if ascii {
            return (2 * n).saturating_sub(1);
        }
        let size = |p: &Property| match p.kind {
            Kind::Scalar(t) | Kind::List { count: t, .. } => t.size() as u64,
        };
        self.properties.iter().map(size).sum()
    }

    /// The property `load_path` takes a face's or strip's corners from: the last integer
    /// list named `vertex_indices` or `vertex_index` (load.rs's `PlyIndices` keeps the last
    /// one ply-rs hands it and ignores lists of floats).
    fn index_property(&self) -> Option<usize> {
        self.properties.iter().rposition(|p| {
            (p.name == "vertex_indices" || p.name == "vertex_index")
                && matches!(p.kind, Kind::List { item, .. } if item.is_integer())
        })
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Encoding {
    Ascii,
    BigEndian,
    LittleEndian,
}

#[derive(Debug, PartialEq)]
pub(super) struct Header {
    pub encoding: Encoding,
    pub elements: Vec<Element>,
    /// How many lines the header has, so that ASCII data lines can be numbered in the file.
    pub lines: u64,
}

/// One header line, as ply-rs's grammar reads it.
#[derive(Debug, PartialEq)]
enum Line<'s> {
    Magic,
    End,
    Format(Encoding, (u16, u8)),
    /// A comment or `obj_info`.
    Note,
    Element(&'s str, u64),
    Property(&'s str, Kind),
}

/// The characters that separate the words of a header line, as in Draco's reader: spaces,
/// tabs, vertical tabs and form feeds (line breaks end the line).
const BLANKS: [char; 4] = [' ', '\t', '\x0b', '\x0c'];

/// A header line without its line break (`\r\n`, `\n` or `\r`) and the spaces and tabs
/// around it; `None` if another line break is left inside it (a line feed in a file whose
/// lines end in carriage returns, or the other way round).
fn header_content(text: &str) -> Option<&str> {
    let t = text.strip_suffix("\r\n").or_else(|| text.strip_suffix(['\n', '\r'])).unwrap_or(text);
    if t.contains(['\r', '\n']) {
        return None;
    }
    Some(t.trim_matches(BLANKS))
}

/// A PLY identifier as ply-rs's grammar has it: `[A-Za-z_][A-Za-z0-9_-]*`.
fn is_ident(s: &str) -> bool {
    let mut chars = s.chars();
    chars.next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

fn digits(s: &str) -> Option<u64> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

/// Parses a header line's content (see [`header_content`]): a keyword and its words, separated
/// by any run of spaces or tabs (Draco reads them so; ply-rs wants the keyword first on the
/// line).
fn header_line(content: &str) -> Result<Line<'_>, String> {
    match content {
        "ply" => return Ok(Line::Magic),
        "end_header" => return Ok(Line::End),
        _ => {}
    }
    let (keyword, rest) = content.split_once(BLANKS).unwrap_or((content, ""));
    let words: Vec<&str> = rest.split(BLANKS).filter(|w| !w.is_empty()).collect();
    let scalar = |w: &str| Scalar::from_name(w).ok_or_else(|| format!("unknown property type '{w}'"));
    match (keyword, &words[..]) {
        ("comment" | "obj_info", _) => Ok(Line::Note),
        ("format", [encoding, version]) => {
            let encoding = match *encoding {
                "ascii" => Encoding::Ascii,
                "binary_big_endian" => Encoding::BigEndian,
                "binary_little_endian" => Encoding::LittleEndian,
                _ => return Err(format!("unknown format '{encoding}'")),
            };
            let (major, minor) = version
                .split_once('.')
                .and_then(|(a, b)| Some((digits(a)?, digits(b)?)))
                .ok_or_else(|| format!("bad version '{version}'"))?;
            // ply-rs keeps the version as (u16, u8), truncating, and compares it so.
            Ok(Line::Format(encoding, (major as u16, minor as u8)))
        }
        ("element", [name, count]) if is_ident(name) => {
            let count = digits(count).ok_or_else(|| format!("bad element count '{count}'"))?;
            Ok(Line::Element(name, count))
        }
        ("property", ["list", count, item, name]) if is_ident(name) => {
            Ok(Line::Property(name, Kind::List { count: scalar(count)?, item: scalar(item)? }))
        }
        ("property", [ty, name]) if is_ident(name) => Ok(Line::Property(name, Kind::Scalar(scalar(ty)?))),
        _ => Err("not a PLY header line".into()),
    }
}

/// Reads the header, leaving `src` at the first byte of the payload.
pub(super) fn read_header(src: &mut Source) -> Result<Header, LoadError> {
    let path = src.path;
    let mut line = Vec::new();
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut n = 0;
    src.detect_cr_lines(b"ply")?;
    loop {
        n += 1;
        let bad = |what: &str| err(path, format!("malformed PLY header, line {n}: {what}"));
        if !src.line(&mut line, MAX_HEADER_LINE).map_err(|e| bad(&e.message))? {
            return Err(bad(if n == 1 { "the file is empty" } else { "the file ends before 'end_header'" }));
        }
        let text = std::str::from_utf8(&line).map_err(|_| bad("not UTF-8 text"))?;
        let content = header_content(text).ok_or_else(|| bad("a line break of another kind inside the line"))?;
        let parsed = header_line(content).map_err(|e| bad(&e));
        if n == 1 {
            if parsed.ok() != Some(Line::Magic) {
                return Err(err(path, "not a PLY file: the first line is not 'ply'"));
            }
            continue;
        }
        match parsed? {
            Line::Magic => return Err(bad("a second 'ply' line")),
            Line::Format(encoding, version) => match format {
                None => format = Some((encoding, version)),
                Some(f) if f != (encoding, version) => return Err(bad("a format other than the one before")),
                Some(_) => {}
            },
            Line::Note => {}
            Line::Element(name, count) => {
                elements.retain(|e| e.name != name);
                elements.push(Element { name: name.to_string(), count, properties: Vec::new() });
            }
            Line::Property(name, kind) => {
                let element = elements.last_mut().ok_or_else(|| bad("a property before any element"))?;
                element.properties.retain(|p| p.name != name);
                element.properties.push(Property { name: name.to_string(), kind });
            }
            Line::End => {
                let (encoding, _) = format.ok_or_else(|| err(path, "malformed PLY header: no 'format' line"))?;
                return Ok(Header { encoding, elements, lines: n });
            }
        }
    }
}

/// The content of an ASCII data line, if it is one by ply-rs's grammar: numbers separated
/// by spaces or tabs, with spaces or tabs around them and a line break after them allowed.
fn ascii_fields(line: &[u8]) -> Option<&str> {
    let body = line
        .strip_suffix(b"\r\n")
        .or_else(|| line.strip_suffix(b"\n"))
        .or_else(|| line.strip_suffix(b"\r"))
        .unwrap_or(line);
    if !body.split(|&b| b == b' ' || b == b'\t').filter(|t| !t.is_empty()).all(is_number) {
        return None;
    }
    std::str::from_utf8(body).ok()
}

/// `[-+]?[0-9]+(\.[0-9]+)?(e[-+]?[0-9]+)?`, ply-rs's number.
fn is_number(t: &[u8]) -> bool {
    let mut i = usize::from(matches!(t.first(), Some(b'-' | b'+')));
    let digits = |i: &mut usize| {
        let start = *i;
        while t.get(*i).is_some_and(u8::is_ascii_digit) {
            *i += 1;
        }
        *i > start
    };
    if !digits(&mut i) {
        return false;
    }
    if t.get(i) == Some(&b'.') {
        i += 1;
        if !digits(&mut i) {
            return false;
        }
    }
    if t.get(i) == Some(&b'e') {
        i += 1;
        if matches!(t.get(i), Some(b'-' | b'+')) {
            i += 1;
        }
        if !digits(&mut i) {
            return false;
        }
    }
    i == t.len()
}

/// Where a record is, for messages: `line 12, element 'face' 3` (ASCII) or
/// `element 'face' 3` (binary; records count from 0).
#[derive(Clone, Copy)]
struct At<'e> {
    line: Option<u64>,
    element: &'e str,
    record: u64,
}

impl fmt::Display for At<'_> {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        if let Some(line) = self.line {
            write!(f, "line {line}, ")?;
        }
        write!(f, "element '{}' {}", self.element, self.record)
    }
}

fn truncated(path: &Path, at: &At, count: u64) -> LoadError {
    err(path, format!("{at} (of {count}): the file ends inside it: truncated PLY"))
}

/// What a record reader does with a property.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Role {
    Skip,
    /// A coordinate of the vertex position: 0, 1, 2 for `x`, `y`, `z`.
    Axis(usize),
    /// The list of a face's or strip's corners.
    Corners,
}

/// Takes the values a record reader is asked for (see [`Role`]).
trait Sink {
    fn axis(&mut self, _axis: usize, _value: f64) {}
    /// A corner list of `n` items starts; whether to hand over its items.
    fn start(&mut self, _n: u64, _at: &At) -> Result<bool, LoadError> {
        Ok(false)
    }
    fn item(&mut self, _index: i64, _at: &At) -> Result<(), LoadError> {
        Ok(())
    }
    /// The record has been read.
    fn end(&mut self, _at: &At) -> Result<(), LoadError> {
        Ok(())
    }
}

struct Nothing;

impl Sink for Nothing {}

/// The values of a vertex record: `x y z`, `red green blue alpha`, `nx ny nz` (see
/// [`vertex_role`]); colours as the file has them, scaled by [`VertexRoles::scale`].
type VertexValues = [f32; VALUES];
const VALUES: usize = 10;

struct Vertex(VertexValues);

impl Sink for Vertex {
    fn axis(&mut self, axis: usize, value: f64) {
        self.0[axis] = value as f32;
    }
}

/// A vertex property's place among [`VertexValues`], by its name: the names PLY writers use
/// (`red` by most, `r` by some, `diffuse_red` by older scanners; `nx` by most, `normal_x` by
/// a few).
fn vertex_role(name: &str) -> Option<usize> {
    Some(match name {
        "x" => 0,
        "y" => 1,
        "z" => 2,
        "red" | "r" | "diffuse_red" => 3,
        "green" | "g" | "diffuse_green" => 4,
        "blue" | "b" | "diffuse_blue" => 5,
        "alpha" | "a" | "diffuse_alpha" => 6,
        "nx" | "normal_x" => 7,
        "ny" | "normal_y" => 8,
        "nz" | "normal_z" => 9,
        _ => return None,
    })
}

/// Which attributes a `vertex` element has, and how its colour values map to 0..=255: 8-bit
/// integers as they are, 16-bit ones divided by 257, floats (0 to 1) times 255.
struct VertexRoles {
    colors: bool,
    alpha: bool,
    normals: bool,
    scale: [f32; 4],
}

impl VertexRoles {
    fn of(e: &Element) -> VertexRoles {
        let mut found = [None; VALUES];
        for p in &e.properties {
            if let (Some(i), Kind::Scalar(ty)) = (vertex_role(&p.name), p.kind) {
                found[i].get_or_insert(ty);
            }
        }
        let scale = [3, 4, 5, 6].map(|i| match found[i] {
            Some(ty) if !ty.is_integer() => 255.0,
            Some(ty) if ty.size() == 2 => 1.0 / 257.0,
            _ => 1.0,
        });
        VertexRoles {
            colors: found[3..6].iter().all(Option::is_some),
            alpha: found[6].is_some(),
            normals: found[7..10].iter().all(Option::is_some),
            scale,
        }
    }

    fn color(&self, v: &VertexValues) -> [u8; 4] {
        let c = |i: usize| (v[3 + i] * self.scale[i]).round().clamp(0.0, 255.0) as u8;
        [c(0), c(1), c(2), if self.alpha { c(3) } else { 255 }]
    }
}

fn out_of_range(out: &Emitter, at: &At, vertex: u32) -> LoadError {
    err(out.path, format!("{at} uses vertex {vertex}, but the file has only {} vertices", out.positions.count()))
}

/// Faces, triangulated as `load_path` does once a record has been read.
struct Faces<'o, 'e> {
    out: &'o mut Emitter<'e>,
    keep: bool,
}

impl Sink for Faces<'_, '_> {
    fn start(&mut self, n: u64, _at: &At) -> Result<bool, LoadError> {
        self.out.corners.clear();
        self.keep = n >= 3;
        Ok(self.keep)
    }

    fn item(&mut self, index: i64, at: &At) -> Result<(), LoadError> {
        let corner = u32::try_from(index)
            .map_err(|_| err(self.out.path, format!("{at}: vertex index {index} is out of range")))?;
        self.out.corners.push(corner);
        Ok(())
    }

    fn end(&mut self, at: &At) -> Result<(), LoadError> {
        if !std::mem::take(&mut self.keep) {
            return Ok(());
        }
        if let Some(c) = self.out.missing_corner() {
            return Err(out_of_range(self.out, at, c));
        }
        self.out.polygon()
    }
}

/// Triangle strips, unrolled as load.rs's `unroll_strip` does: a negative index restarts
/// the strip, every other triangle is flipped, triangles with a repeated corner are left out.
struct Strips<'o, 'e> {
    out: &'o mut Emitter<'e>,
    /// The last two corners of the current run, and its length so far.
    last: [u32; 2],
    run: u64,
}

impl Sink for Strips<'_, '_> {
    fn start(&mut self, _n: u64, _at: &At) -> Result<bool, LoadError> {
        self.run = 0;
        Ok(true)
    }

    fn item(&mut self, index: i64, at: &At) -> Result<(), LoadError> {
        if index < 0 {
            self.run = 0;
            return Ok(());
        }
        let c = u32::try_from(index)
            .map_err(|_| err(self.out.path, format!("{at}: vertex index {index} is out of range")))?;
        let [a, b] = self.last;
        if self.run >= 2 && a != b && b != c && a != c {
            let t = if self.run & 1 == 0 { [a, b, c] } else { [b, a, c] };
            if let Some(&v) = t.iter().find(|&&v| v as usize >= self.out.positions.count()) {
                return Err(out_of_range(self.out, at, v));
            }
            self.out.triangle(t)?;
        }
        self.last = [b, c];
        self.run += 1;
        Ok(())
    }
}

/// Reads a PLY file's payload, element by element.
struct Reader<'a> {
    src: Source<'a>,
    encoding: Encoding,
    /// ASCII: the number of the last line read (header included).
    line_no: u64,
    line: Vec<u8>,
}

impl<'a> Reader<'a> {
    fn open(input: Input<'a>, progress: &'a mut dyn FnMut(u64)) -> Result<(Self, Header), LoadError> {
        let mut src = Source::open(input, progress)?;
        let header = read_header(&mut src)?;
        let reader = Reader { src, encoding: header.encoding, line_no: header.lines, line: Vec::new() };
        Ok((reader, header))
    }

    fn ascii(&self) -> bool {
        self.encoding == Encoding::Ascii
    }

    /// Reads the records of `e`, calling `after` when each has been read.
    fn records<S: Sink>(
        &mut self,
        e: &Element,
        roles: &[Role],
        sink: &mut S,
        mut after: impl FnMut(&mut S),
    ) -> Result<(), LoadError> {
        if e.properties.is_empty() && !self.ascii() {
            // Records of no bytes: nothing to read, however many the header claims.
            return Ok(());
        }
        for i in 0..e.count {
            if self.ascii() {
                if !self.ascii_record(e, i, roles, sink)? {
                    break;
                }
            } else {
                self.binary_record(e, i, roles, sink)?;
            }
            after(sink);
        }
        Ok(())
    }

    /// Reads one ASCII record (one line); false if the file has ended and the element has
    /// no properties (ply-rs reads such records from the empty "lines" after the end).
    fn ascii_record<S: Sink>(&mut self, e: &Element, i: u64, roles: &[Role], sink: &mut S) -> Result<bool, LoadError> {
        let path = self.src.path;
        self.line_no += 1;
        let at = At { line: Some(self.line_no), element: &e.name, record: i };
        if !self.src.line(&mut self.line, usize::MAX)? {
            if e.properties.is_empty() {
                return Ok(false);
            }
            return Err(truncated(path, &at, e.count));
        }
        let bad = |what: String| err(path, format!("{at}: {what}"));
        let text = ascii_fields(&self.line).ok_or_else(|| bad("not a line of numbers".into()))?;
        let mut tokens = text.split([' ', '\t']).filter(|t| !t.is_empty());
        let mut next = |p: &Property| tokens.next().ok_or_else(|| bad(format!("no value for property '{}'", p.name)));
        for (p, &role) in e.properties.iter().zip(roles) {
            let token = next(p)?;
            let invalid = |t: &str, ty: Scalar| bad(format!("'{t}' is not a valid {ty} (property '{}')", p.name));
            match p.kind {
                Kind::Scalar(ty) => {
                    let value = ty.ascii_f64(token).ok_or_else(|| invalid(token, ty))?;
                    if let Role::Axis(axis) = role {
                        sink.axis(axis, value);
                    }
                }
                Kind::List { item, .. } => {
                    let n = token.parse::<usize>().map_err(|_| bad(format!("'{token}' is not a list length")))? as u64;
                    let wanted = role == Role::Corners && sink.start(n, &at)?;
                    for _ in 0..n {
                        let token = next(p)?;
                        if wanted {
                            sink.item(item.ascii_int(token).ok_or_else(|| invalid(token, item))?, &at)?;
                        } else if item.ascii_f64(token).is_none() {
                            return Err(invalid(token, item));
                        }
                    }
                }
            }
        }
        sink.end(&at)?;
        Ok(true)
    }

    /// The next `n` bytes of the record at `at`.
    #[inline]
    fn take(&mut self, n: usize, at: &At, count: u64) -> Result<&[u8], LoadError> {
        if !self.src.ensure(n)? {
            return Err(truncated(self.src.path, at, count));
        }
        let start = self.src.pos;
        self.src.consume(n);
        Ok(&self.src.buf[start..start + n])
    }

    fn skip(&mut self, n: Option<u64>, at: &At, count: u64) -> Result<(), LoadError> {
        match n {
            Some(n) if self.src.skip(n)? => Ok(()),
            _ => Err(truncated(self.src.path, at, count)),
        }
    }

    fn binary_record<S: Sink>(&mut self, e: &Element, i: u64, roles: &[Role], sink: &mut S) -> Result<(), LoadError> {
        let big = self.encoding == Encoding::BigEndian;
        let at = At { line: None, element: &e.name, record: i };
        for (p, &role) in e.properties.iter().zip(roles) {
            match p.kind {
                Kind::Scalar(ty) => match role {
                    Role::Axis(axis) => sink.axis(axis, ty.f64_at(self.take(ty.size(), &at, e.count)?, big)),
                    _ => self.skip(Some(ty.size() as u64), &at, e.count)?,
                },
                Kind::List { count, item } => {
                    if !count.is_integer() {
                        let what = format!("{at}: the length of list '{}' has a floating-point type", p.name);
                        return Err(err(self.src.path, what));
                    }
                    let n = count.int_at(self.take(count.size(), &at, e.count)?, big);
                    let n = u64::try_from(n).map_err(|_| {
                        err(self.src.path, format!("{at}: list '{}' has a negative length, {n}", p.name))
                    })?;
                    if role == Role::Corners && sink.start(n, &at)? {
                        self.items(item, n, &at, e.count, |v| sink.item(v, &at))?;
                    } else {
                        self.skip(n.checked_mul(item.size() as u64), &at, e.count)?;
                    }
                }
            }
        }
        sink.end(&at)
    }

    /// Hands the `n` integers of a binary list to `each`, decoding them in the buffer.
    fn items(
        &mut self,
        ty: Scalar,
        mut n: u64,
        at: &At,
        count: u64,
        mut each: impl FnMut(i64) -> Result<(), LoadError>,
    ) -> Result<(), LoadError> {
        let big = self.encoding == Encoding::BigEndian;
        let size = ty.size();
        while n > 0 {
            if !self.src.ensure(size)? {
                return Err(truncated(self.src.path, at, count));
            }
            let unread = self.src.unread();
            let k = ((unread.len() / size) as u64).min(n) as usize;
            for b in unread[..k * size].chunks_exact(size) {
                each(ty.int_at(b, big))?;
            }
            self.src.consume(k * size);
            n -= k as u64;
        }
        Ok(())
    }

    /// Reads past element `e`, seeking where the records have a fixed size; with
    /// `check`, ASCII records are checked as ply-rs reads them, else only counted.
    fn skip_element(&mut self, e: &Element, check: bool) -> Result<(), LoadError> {
        match (self.ascii(), e.fixed_size()) {
            (false, Some(size)) => {
                let skipped = match e.count.checked_mul(size) {
                    Some(n) => self.src.skip(n)?,
                    None => false,
                };
                if skipped {
                    return Ok(());
                }
                let what =
                    format!("element '{}' ({} records of {size} bytes): the file ends inside it", e.name, e.count);
                Err(err(self.src.path, format!("{what}: truncated PLY")))
            }
            (true, _) if !check => {
                for i in 0..e.count {
                    self.line_no += 1;
                    if !self.src.line(&mut self.line, usize::MAX)? {
                        if e.properties.is_empty() {
                            break;
                        }
                        let at = At { line: Some(self.line_no), element: &e.name, record: i };
                        return Err(truncated(self.src.path, &at, e.count));
                    }
                }
                Ok(())
            }
            _ => self.records(e, &vec![Role::Skip; e.properties.len()], &mut Nothing, |_| {}),
        }
    }

    /// The `vertex` element's positions, and its colours and normals where it has them.
    fn vertices(&mut self, e: &Element) -> Result<Mesh, LoadError> {
        // Reserve no more than the file can hold, whatever the header claims.
        let min = e.min_record_bytes(self.ascii());
        let cap = e.count.min(self.src.size_bound() / min.max(1)).min(MAX_VERTICES) as usize;
        let roles = VertexRoles::of(e);
        let mut mesh = Mesh::new(Vec::with_capacity(cap), Vec::new());
        if roles.colors {
            mesh.colors.reserve(cap);
        }
        if roles.normals {
            mesh.normals.reserve(cap);
        }
        self.each_vertex(e, &mut |v| {
            mesh.positions.push([v[0], v[1], v[2]]);
            if roles.colors {
                mesh.colors.push(roles.color(v));
            }
            if roles.normals {
                mesh.normals.push([v[7], v[8], v[9]]);
            }
        })?;
        Ok(mesh)
    }

    /// The `vertex` element's values, one vertex after the other, in file order.
    fn each_vertex(&mut self, e: &Element, sink: &mut dyn FnMut(&VertexValues)) -> Result<(), LoadError> {
        let path = self.src.path;
        if e.count > MAX_VERTICES {
            let what = format!("element 'vertex' claims {} vertices, more than 32-bit indices address", e.count);
            return Err(err(path, what));
        }
        let min = e.min_record_bytes(self.ascii());
        if min == 0 && e.count > MAX_EMPTY_VERTICES {
            return Err(err(path, format!("element 'vertex' claims {} vertices without properties", e.count)));
        }
        let roles: Vec<Role> = e
            .properties
            .iter()
            .map(|p| match (vertex_role(&p.name), p.kind) {
                (Some(i), Kind::Scalar(_)) => Role::Axis(i),
                _ => Role::Skip,
            })
            .collect();
        let mut done = 0u64;
        match (self.ascii(), e.fixed_size()) {
            (false, Some(size)) if size > 0 => self.fixed_vertices(e, size as usize, &roles, &mut |p| {
                done += 1;
                sink(p)
            })?,
            _ => self.records(e, &roles, &mut Vertex([0.0; VALUES]), |v| {
                done += 1;
                sink(&v.0);
                v.0 = [0.0; VALUES];
            })?,
        }
        // Records without properties, which hold no bytes: ply-rs reads each as (0, 0, 0).
        for _ in done..e.count {
            sink(&[0.0; VALUES]);
        }
        Ok(())
    }

    /// Binary vertices of `size` bytes each, decoded where they lie in the buffer.
    fn fixed_vertices(
        &mut self,
        e: &Element,
        size: usize,
        roles: &[Role],
        sink: &mut dyn FnMut(&VertexValues),
    ) -> Result<(), LoadError> {
        let big = self.encoding == Encoding::BigEndian;
        // Where each value is in a record, and its type.
        let mut values: Vec<(usize, usize, Scalar)> = Vec::new();
        let mut offset = 0;
        for (p, role) in e.properties.iter().zip(roles) {
            // (Only called for elements without lists.)
            if let Kind::Scalar(ty) = p.kind {
                if let Role::Axis(i) = role {
                    values.push((*i, offset, ty));
                }
                offset += ty.size();
            }
        }
        let mut v = [0.0f32; VALUES];
        let mut i = 0;
        while i < e.count {
            if !self.src.ensure(size)? {
                let at = At { line: None, element: &e.name, record: i };
                return Err(truncated(self.src.path, &at, e.count));
            }
            let unread = self.src.unread();
            let k = ((unread.len() / size) as u64).min(e.count - i) as usize;
            for record in unread[..k * size].chunks_exact(size) {
                for &(slot, at, ty) in &values {
                    v[slot] = ty.f64_at(&record[at..], big) as f32;
                }
                sink(&v);
            }
            self.src.consume(k * size);
            i += k as u64;
        }
        Ok(())
    }

    /// Binary faces whose one property is their corner list (`property list uchar int
    /// vertex_indices`, as most writers have it), decoded record after record where they lie
    /// in the buffer. A record that is not whole in the buffer, or that is wrong, is left to
    /// [`Self::binary_record`], which reads past the buffer's end or words the error.
    fn list_only_faces(
        &mut self,
        e: &Element,
        (count, item): (Scalar, Scalar),
        roles: &[Role],
        out: &mut Emitter,
    ) -> Result<(), LoadError> {
        let big = self.encoding == Encoding::BigEndian;
        let (count_size, item_size) = (count.size(), item.size());
        let vertices = out.positions.count() as u64;
        // A corner, if it is a vertex.
        let corner = |b: &[u8]| u32::try_from(item.int_at(b, big)).ok().filter(|&c| u64::from(c) < vertices);
        let mut i = 0;
        while i < e.count {
            let unread = self.src.unread();
            let mut at = 0;
            while i < e.count && at + count_size <= unread.len() {
                let Ok(n) = usize::try_from(count.int_at(&unread[at..], big)) else { break };
                let list = at + count_size;
                let end = list.saturating_add(n.saturating_mul(item_size));
                if end > unread.len() {
                    break;
                }
                if n == 3 {
                    let c = |k: usize| corner(&unread[list + k * item_size..]);
                    let (Some(a), Some(b), Some(c)) = (c(0), c(1), c(2)) else { break };
                    out.triangle([a, b, c])?;
                } else if n > 3 {
                    out.corners.clear();
                    for b in unread[list..end].chunks_exact(item_size) {
                        let Some(c) = corner(b) else { break };
                        out.corners.push(c);
                    }
                    if out.corners.len() < n {
                        break;
                    }
                    out.polygon()?;
                }
                at = end;
                i += 1;
            }
            self.src.consume(at);
            if i < e.count {
                self.binary_record(e, i, roles, &mut Faces { out: &mut *out, keep: false })?;
                i += 1;
            }
        }
        Ok(())
    }

    /// Reads the elements of a pass for the triangles: faces (if `faces`) and strips (if
    /// `strips`) go to `out`, the others are read past. Stops after element `stop`.
    fn triangles_pass(
        &mut self,
        header: &Header,
        out: &mut Emitter,
        (faces, strips): (bool, bool),
        stop: Option<usize>,
    ) -> Result<(), LoadError> {
        for (k, e) in header.elements.iter().enumerate() {
            let corners = e.index_property();
            let roles: Vec<Role> =
                (0..e.properties.len()).map(|p| if Some(p) == corners { Role::Corners } else { Role::Skip }).collect();
            match e.name.as_str() {
                // Read in the positions pass.
                "vertex" => self.skip_element(e, false)?,
                "face" if faces && corners.is_some() => match (self.ascii(), &e.properties[..]) {
                    (false, [Property { kind: Kind::List { count, item }, .. }]) if count.is_integer() => {
                        self.list_only_faces(e, (*count, *item), &roles, out)?
                    }
                    _ => self.records(e, &roles, &mut Faces { out: &mut *out, keep: false }, |_| {})?,
                },
                "tristrips" if strips && corners.is_some() => {
                    self.records(e, &roles, &mut Strips { out: &mut *out, last: [0; 2], run: 0 }, |_| {})?
                }
                _ => self.skip_element(e, true)?,
            }
            if stop == Some(k) {
                break;
            }
        }
        Ok(())
    }
}

fn vertex_element(path: &Path, header: &Header) -> Result<usize, LoadError> {
    header.elements.iter().position(|e| e.name == "vertex").ok_or_else(|| err(path, "PLY file has no 'vertex' element"))
}

/// Pass 1 for PLY: the `vertex` element, read after the elements before it.
pub(super) fn vertices(input: Input, progress: &mut dyn FnMut(u64)) -> Result<Mesh, LoadError> {
    let path = input.path;
    let (mut reader, header) = Reader::open(input, progress)?;
    let vertex = vertex_element(path, &header)?;
    for e in &header.elements[..vertex] {
        reader.skip_element(e, true)?;
    }
    reader.vertices(&header.elements[vertex])
}

/// Pass 1 for PLY without holding the positions: each is handed to `sink`; returns how
/// many there were.
pub(super) fn each_position(
    input: Input,
    sink: &mut dyn FnMut([f32; 3]),
    progress: &mut dyn FnMut(u64),
) -> Result<u64, LoadError> {
    let path = input.path;
    let (mut reader, header) = Reader::open(input, progress)?;
    let vertex = vertex_element(path, &header)?;
    for e in &header.elements[..vertex] {
        reader.skip_element(e, true)?;
    }
    let e = &header.elements[vertex];
    reader.each_vertex(e, &mut |v| sink([v[0], v[1], v[2]]))?;
    Ok(e.count)
}

/// Pass 2 for PLY: strips, then faces, as `load_path` orders them. When the `face` element
/// comes before the `tristrips` one, the file is read twice: for the strips, then for the
/// faces.
pub(super) fn triangles(input: Input, out: &mut Emitter, progress: &mut dyn FnMut(u64)) -> Result<(), LoadError> {
    let path = input.path;
    let (mut reader, header) = Reader::open(input, &mut *progress)?;
    let vertices = header.elements[vertex_element(path, &header)?].count;
    if vertices != out.positions.count() as u64 {
        let what = format!(
            "the positions given are not this file's: {} of them for {vertices} vertices",
            out.positions.count()
        );
        return Err(err(path, what));
    }
    let find = |name: &str| header.elements.iter().position(|e| e.name == name);
    match (find("face"), find("tristrips")) {
        (Some(face), Some(strips)) if face < strips => {
            reader.triangles_pass(&header, out, (false, true), None)?;
            let read = reader.src.raw_len;
            drop(reader);
            let mut progress = |n| progress(read + n);
            let (mut reader, header) = Reader::open(input, &mut progress)?;
            reader.triangles_pass(&header, out, (true, false), Some(face))
        }
        _ => reader.triangles_pass(&header, out, (true, true), None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ply_rs_bw::parser::Parser;
    use ply_rs_bw::ply::{self as rs, DefaultElement};

    fn ours(text: &str) -> Result<Header, String> {
        let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
        let path = dir.path().join("h.ply");
        std::fs::write(&path, text).map_err(|e| e.to_string())?;
        let mut progress = |_| {};
        let mut src = Source::open(Input::file(&path), &mut progress).map_err(|e| e.to_string())?;
        read_header(&mut src).map_err(|e| e.to_string())
    }

    fn scalar(t: &rs::ScalarType) -> Scalar {
        use rs::ScalarType as S;
        match t {
            S::Char => Scalar::I8,
            S::UChar => Scalar::U8,
            S::Short => Scalar::I16,
            S::UShort => Scalar::U16,
            S::Int => Scalar::I32,
            S::UInt => Scalar::U32,
            S::Float => Scalar::F32,
            S::Double => Scalar::F64,
        }
    }

    /// ply-rs's reading of a header, in this module's types.
    fn theirs(text: &str) -> Option<(Encoding, Vec<Element>)> {
        let h = Parser::<DefaultElement>::new().read_header(&mut text.as_bytes()).ok()?;
        let encoding = match h.encoding {
            rs::Encoding::Ascii => Encoding::Ascii,
            rs::Encoding::BinaryBigEndian => Encoding::BigEndian,
            rs::Encoding::BinaryLittleEndian => Encoding::LittleEndian,
        };
        let elements = h
            .elements
            .iter()
            .map(|(name, e)| Element {
                name: name.clone(),
                count: e.count as u64,
                properties: e
                    .properties
                    .iter()
                    .map(|(name, p)| Property {
                        name: name.clone(),
                        kind: match &p.data_type {
                            rs::PropertyType::Scalar(t) => Kind::Scalar(scalar(t)),
                            rs::PropertyType::List(c, i) => Kind::List { count: scalar(c), item: scalar(i) },
                        },
                    })
                    .collect(),
            })
            .collect();
        Some((encoding, elements))
    }

    #[test]
    fn headers_read_as_ply_rs_reads_them() {
        let body = "element vertex 3\nproperty float x\nproperty float32 y\nproperty double z\n\
                    element face 1\nproperty list uchar int vertex_indices\n";
        let cases = [
            format!("ply\nformat ascii 1.0\n{body}end_header\n"),
            format!("ply\r\nformat binary_little_endian 1.0\r\n{body}end_header\r\n"),
            format!("ply \nformat\tbinary_big_endian  1.0 \ncomment made by hand\ncomment\nobj_info x\n{body}end_header\t\n"),
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty int8 x\nproperty uint8 y\nproperty int16 z\n\
             property uint16 a\nproperty int32 b\nproperty uint32 c\nproperty float64 d\nproperty char e\n\
             property uchar f\nproperty short g\nproperty ushort h\nproperty int i\nproperty uint j\n\
             property list int16 uint32 k-2\nend_header\n"
                .to_string(),
            // Elements and properties named again replace the earlier ones, at the end.
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty uchar x\n\
             element face 2\nelement vertex 4\nproperty float z\nend_header\n"
                .to_string(),
            // The version is kept as (u16, u8): 1.256 is 1.0.
            "ply\nformat ascii 1.0\nformat ascii 1.256\nelement v 0\nend_header\n".to_string(),
            // Refused by both.
            "ply\nformat ascii 1.0\nformat binary_little_endian 1.0\nend_header\n".to_string(),
            "ply\nelement vertex 1\nend_header\n".to_string(),
            "ply\nformat ascii 1.0\nproperty float x\nend_header\n".to_string(),
            "ply\nformat ascii 1.0\nelement vertex -1\nend_header\n".to_string(),
            "ply\nformat ascii 1.0\nelement 1vertex 1\nend_header\n".to_string(),
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x y\nend_header\n".to_string(),
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty floatx y\nend_header\n".to_string(),
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar x\nend_header\n".to_string(),
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x.y\nend_header\n".to_string(),
            "ply\nformat ascii 1\nend_header\n".to_string(),
            "ply\nformat ascii 1.0\ncommentary\nend_header\n".to_string(),
            "ply\nformat ascii 1.0\nend_header x\n".to_string(),
            "ply\nformat ascii 1.0\nply\nend_header\n".to_string(),
            "ply\nformat ascii 1.0\n\nend_header\n".to_string(),
            "ply\nformat ascii 1.0\ncomment a\rb\nend_header\n".to_string(),
            "ply\nformat ascii 1.0\nelement vertex 1\n".to_string(),
            "plyx\nformat ascii 1.0\nend_header\n".to_string(),
            "\nply\nformat ascii 1.0\nend_header\n".to_string(),
            "".to_string(),
        ];
        for text in &cases {
            let ours = ours(text);
            let theirs = theirs(text);
            match (&ours, &theirs) {
                (Ok(h), Some((encoding, elements))) => {
                    assert_eq!((&h.encoding, &h.elements), (encoding, elements), "{text:?}")
                }
                (Err(_), None) => {}
                _ => panic!("{text:?}: ours {ours:?}, ply-rs {theirs:?}"),
            }
        }
    }

    /// Extra spaces and tabs (before a keyword, between words, after the line) read as Draco
    /// reads them: as the same header without them.
    #[test]
    fn headers_with_extra_blanks_read_as_draco_reads_them() {
        let plain = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty list uchar int vertex_indices\nend_header\n";
        let spaced = "ply\n  format \t ascii  1.0\n element vertex 3\n\tproperty  float\tx \n property list  uchar int \t vertex_indices\n  end_header\n";
        let (a, b) = (ours(plain).unwrap(), ours(spaced).unwrap());
        assert_eq!((&a.encoding, &a.elements), (&b.encoding, &b.elements));
        // Blanks do not make a bad line good.
        for bad in
            ["ply\nformat ascii 1.0\n element vertex 1 2\nend_header\n", "ply\nformat ascii 1.0\n\t\nend_header\n"]
        {
            assert!(ours(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn ascii_numbers_follow_ply_rs_grammar() {
        for good in ["0", "-1", "+2", "1.5", "1e5", "-1.25e-3", "007"] {
            assert!(is_number(good.as_bytes()), "{good}");
        }
        for bad in ["", "-", "1.", ".5", "1e", "1E5", "nan", "inf", "1-2", "0x1", "1.5e+"] {
            assert!(!is_number(bad.as_bytes()), "{bad}");
        }
        assert_eq!(ascii_fields(b" 1\t2  3 \r\n"), Some(" 1\t2  3 "));
        assert_eq!(ascii_fields(b"\n"), Some(""));
        assert_eq!(ascii_fields(b"1,2\n"), None);
        assert_eq!(ascii_fields(b"1\r2\n"), None);
        assert_eq!(ascii_fields(b"1\r\r\n"), None);
    }
}
