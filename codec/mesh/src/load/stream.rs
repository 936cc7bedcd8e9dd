//! Streaming (out-of-core) reading of PLY and OBJ files, optionally gzip-compressed: the
//! vertex positions in one pass over the file, then the triangles in another, one by one.
//!
//! [`load_path`](super::load_path) reads the whole file and then builds the whole mesh: fine
//! for a few million triangles, not for a 4 GB binary PLY of 200M, whose bytes, parsed
//! records and triangles would each need gigabytes. The out-of-core encoder calls
//! [`read_positions`] (the one array held: 12 bytes a vertex) and then [`for_each_triangle`],
//! which hands it the triangles through a callback. Both read through one 1 MiB buffer
//! (gzip is decompressed on the fly, under the cap [`max_decompressed_bytes`] as in the
//! in-core loader), so besides the positions a pass holds a bounded buffer, one line of
//! text (ASCII PLY, OBJ), one face's corners, and for OBJ a table of 4 bytes a vertex (see
//! below).
//!
//! The result is exactly `load_path`'s, which the tests check on every shared PLY and OBJ
//! mesh: the same positions in the same order, the same triangles in the same order, made
//! by the same triangulation of polygons (`load/polygon.rs`), the same unrolling of PLY
//! triangle strips and the same dropped PLY faces of fewer than three corners, the same
//! OBJ points and lines skipped and counted ([`Counts::ignored`]), and the same error for a
//! file without triangles. A file `load_path` refuses is refused here too, with
//! a one-line message that names the file, what is wrong and where (a line number in text,
//! an element and record number in binary PLY), and the other way round (a test compares
//! both on thousands of corrupted files). A truncated file is an error. The exceptions, in
//! files no writer makes, are refused here and not by `load_path`:
//! - a PLY header line over 64 KiB (a keyword and a few words, or a comment);
//! - a PLY number beyond 64 bits in the header (on which ply-rs panics);
//! - a PLY `vertex` element of more than 2^32 vertices, or of more than 2^24 without
//!   properties (which hold no bytes of the file but 12 of memory each);
//! - an OBJ file whose objects need more than 2^32 - 1 vertices in all (tobj wraps its
//!   32-bit indices around), or with a normal index so far out of range (about -6·10^18)
//!   that tobj's bounds check wraps around and lets it through.
//!
//! * **PLY**: `positions` are the `vertex` element's `x`, `y`, `z`, all of them in file
//!   order; triangles are those of the `tristrips` element (if any) followed by those of
//!   the `face` element, whichever comes first in the file, as `load_path` orders them.
//!   The header and the records are read by this module, not by ply-rs (which `load_path`
//!   uses): ply-rs reads each element whole into a `Vec` of records before returning any,
//!   and each record holds its own `Vec` of properties and lists, some 100 bytes a face,
//!   while here a binary record is decoded in place in the buffer. The header parser
//!   accepts exactly the headers ply-rs accepts (a test compares them), so the two readers
//!   see the same elements. [`read_positions`] reads the file up to the end of the `vertex`
//!   element; [`for_each_triangle`] reads it all (seeking over fixed-size binary elements it
//!   does not need), so errors in the elements after the vertices surface there.
//! * **OBJ**: `load_path` reads OBJ through tobj, which splits the file into objects (at an
//!   `o` or `g` line that follows faces) and gives each object *only the vertices its faces
//!   use, in the order of first use*; the mesh concatenates the objects. So `positions` are
//!   in that order, not in file order, and a vertex used by two objects appears twice.
//!   Reproducing this needs, per file vertex, the slot it got in the current object: a table
//!   of 4 bytes a vertex, held by both passes. [`read_positions`] reads the file twice: once
//!   to number the slots (no positions held), once to put each `v` line's position into its
//!   slots. A face may use a vertex defined later in its object (tobj resolves indices when
//!   the object ends); such forward references are kept in a map until the object ends.
//!
//! [`max_decompressed_bytes`]: crate::input::max_decompressed_bytes

use crate::Mesh;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use flate2::read::MultiGzDecoder;

use super::polygon::Triangulator;
use super::{err, Format, LoadError};

mod obj;
mod ply;

/// Whether the streaming reader reads the file at `path`: a PLY or OBJ file (by its content,
/// or its name where that is silent, as [`Format::of_file`] tells; optionally gzipped).
pub fn can_stream(path: &Path) -> bool {
    matches!(Format::of_file(path), Ok(Format::Ply | Format::Obj))
}

/// Pass 1: the vertex positions, exactly `load_path(path)?.positions`: for PLY every
/// vertex in file order, for OBJ the vertices the faces use in tobj's order (see the
/// [module documentation](self)).
///
/// A PLY file is read up to the end of its `vertex` element (errors in the elements after it
/// are [`for_each_triangle`]'s to find); an OBJ file is read and checked whole, twice (the
/// positions are not held while the first read numbers them).
///
/// `progress` is called as the file is read with the number of bytes of the file (as stored,
/// before decompression) read so far by this call; for OBJ the count goes up to twice the
/// file's size.
pub fn read_positions(path: &Path, progress: &mut dyn FnMut(u64)) -> Result<Vec<[f32; 3]>, LoadError> {
    Ok(vertices_of(Input::file(path), streamed_format(path)?, progress)?.positions)
}

/// Pass 1 with the vertices' colours and normals where the file has them: a mesh without
/// triangles, positions as [`read_positions`] gives them.
pub fn read_vertices(path: &Path, progress: &mut dyn FnMut(u64)) -> Result<Mesh, LoadError> {
    vertices_of(Input::file(path), streamed_format(path)?, progress)
}

fn vertices_of(input: Input, format: Format, progress: &mut dyn FnMut(u64)) -> Result<Mesh, LoadError> {
    match format {
        Format::Ply => {
            let mesh = ply::vertices(input, progress)?;
            let finite = |p: &[f32; 3]| p.iter().all(|c| c.is_finite());
            if let Some(i) = mesh.positions.iter().position(|p| !finite(p)) {
                let what = format!("element 'vertex' {i}: a non-finite coordinate {:?}", mesh.positions[i]);
                return Err(err(input.path, what));
            }
            if let Some(i) = mesh.normals.iter().position(|n| !finite(n)) {
                let what = format!("element 'vertex' {i}: a non-finite normal {:?}", mesh.normals[i]);
                return Err(err(input.path, what));
            }
            Ok(mesh)
        }
        _ => obj::vertices(input, progress),
    }
}

/// Where a pass reads: a file, or bytes already in memory (plain or gzip) that stand for the
/// file at `path` (named in messages).
#[derive(Clone, Copy)]
pub struct Input<'a> {
    pub path: &'a Path,
    pub bytes: Option<&'a [u8]>,
}

impl<'a> Input<'a> {
    pub fn file(path: &'a Path) -> Self {
        Input { path, bytes: None }
    }
}

/// Both passes over bytes in memory (the in-core loader's way to read PLY and OBJ): the
/// positions, the triangles, and the count of skipped points and lines.
pub fn load_memory(path: &Path, bytes: &[u8], format: Format) -> Result<(Mesh, u64), LoadError> {
    load_input(Input { path, bytes: Some(bytes) }, format, &mut |_| {})
}

/// Both passes over the file at `path` itself: what [`load_memory`] reads from its bytes,
/// without holding them.
/// `between` is called with the vertex count between the passes.
pub fn load_file(path: &Path, format: Format, between: &mut dyn FnMut(usize)) -> Result<(Mesh, u64), LoadError> {
    load_input(Input::file(path), format, between)
}

fn load_input(input: Input, format: Format, between: &mut dyn FnMut(usize)) -> Result<(Mesh, u64), LoadError> {
    let mut mesh = vertices_of(input, format, &mut |_| {})?;
    between(mesh.positions.len());
    let mut triangles = Vec::new();
    let counts = triangles_of(
        input,
        format,
        &mesh.positions.as_slice(),
        &mut |t| {
            triangles.push(t);
            Ok(())
        },
        &mut |_| {},
    )?;
    mesh.triangles = triangles;
    Ok((mesh, counts.ignored))
}

/// Pass 2: calls `f` with every triangle, exactly the triangles of `load_path(path)?` in
/// their order, and returns how many there were. `positions` must be what
/// [`read_positions`] returned for the same file (they steer the triangulation of
/// polygons); a length that does not fit the file is an error.
///
/// A face that uses a vertex the file does not have is an error naming the face; an error
/// returned by `f` stops the pass and is returned. `progress` is as for [`read_positions`];
/// a PLY whose `face` element comes before its `tristrips` element is read twice.
pub fn for_each_triangle(
    path: &Path,
    positions: &[[f32; 3]],
    f: &mut dyn FnMut([u32; 3]) -> Result<(), LoadError>,
    progress: &mut dyn FnMut(u64),
) -> Result<Counts, LoadError> {
    for_each_triangle_from(path, &positions, f, progress)
}

/// What a triangle pass handed out, and what it skipped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    pub triangles: u64,
    /// Elements that are not triangles and were skipped: OBJ points (`p`, or `f` with one
    /// corner) and lines (`l`, or `f` with two corners).
    pub ignored: u64,
}

/// Where the triangle pass finds positions: how many vertices the file has, and the
/// positions of a few of them (the corners of a polygon to triangulate).
pub trait PositionSource {
    fn count(&self) -> usize;
    /// Appends the positions of `indices` (all below [`PositionSource::count`]) to `out`.
    fn gather(&self, indices: &[u32], out: &mut Vec<[f32; 3]>);
}

impl PositionSource for &[[f32; 3]] {
    fn count(&self) -> usize {
        self.len()
    }
    fn gather(&self, indices: &[u32], out: &mut Vec<[f32; 3]>) {
        out.extend(indices.iter().map(|&i| self[i as usize]));
    }
}

/// Pass 1 without holding the positions: calls `sink` with every vertex position in the
/// order [`read_positions`] returns them, and returns how many there were. PLY is read once;
/// OBJ's order needs its positions numbered first, so OBJ is read with [`read_positions`]
/// (holding them for the pass).
pub fn for_each_position(
    path: &Path,
    sink: &mut dyn FnMut([f32; 3]),
    progress: &mut dyn FnMut(u64),
) -> Result<u64, LoadError> {
    let input = Input::file(path);
    match streamed_format(path)? {
        Format::Ply => ply::each_position(input, sink, progress),
        _ => {
            let positions = obj::vertices(input, progress)?.positions;
            positions.iter().for_each(|&p| sink(p));
            Ok(positions.len() as u64)
        }
    }
}

/// [`for_each_triangle`] with the positions from any source (a file of them, for a model
/// whose positions are not held): they are read only to triangulate polygons.
pub fn for_each_triangle_from(
    path: &Path,
    positions: &dyn PositionSource,
    f: &mut dyn FnMut([u32; 3]) -> Result<(), LoadError>,
    progress: &mut dyn FnMut(u64),
) -> Result<Counts, LoadError> {
    triangles_of(Input::file(path), streamed_format(path)?, positions, f, progress)
}

fn triangles_of(
    input: Input,
    format: Format,
    positions: &dyn PositionSource,
    f: &mut dyn FnMut([u32; 3]) -> Result<(), LoadError>,
    progress: &mut dyn FnMut(u64),
) -> Result<Counts, LoadError> {
    let path = input.path;
    let mut out = Emitter::new(path, positions, f);
    match format {
        Format::Ply => ply::triangles(input, &mut out, progress)?,
        _ => obj::triangles(input, &mut out, progress)?,
    }
    if out.count == 0 {
        return Err(err(path, super::no_triangles(out.ignored)));
    }
    Ok(Counts { triangles: out.count, ignored: out.ignored })
}

fn streamed_format(path: &Path) -> Result<Format, LoadError> {
    match Format::of_file(path)? {
        f @ (Format::Ply | Format::Obj) => Ok(f),
        Format::Stl | Format::Gltf => {
            Err(err(path, "the streaming reader reads PLY and OBJ files (optionally gzipped) only"))
        }
    }
}

/// Hands triangles to the caller's callback, triangulating polygons as `load_path` does
/// and counting what it hands out.
struct Emitter<'e> {
    path: &'e Path,
    positions: &'e dyn PositionSource,
    f: &'e mut dyn FnMut([u32; 3]) -> Result<(), LoadError>,
    count: u64,
    /// Elements that are no triangles (OBJ points and lines), skipped.
    ignored: u64,
    triangulator: Triangulator,
    /// The current polygon's corners, filled by the format readers.
    corners: Vec<u32>,
    tris: Vec<[u32; 3]>,
    /// The polygon's corner positions.
    local: Vec<[f32; 3]>,
}

impl<'e> Emitter<'e> {
    fn new(
        path: &'e Path,
        positions: &'e dyn PositionSource,
        f: &'e mut dyn FnMut([u32; 3]) -> Result<(), LoadError>,
    ) -> Self {
        Emitter {
            path,
            positions,
            f,
            count: 0,
            ignored: 0,
            triangulator: Triangulator::default(),
            corners: Vec::new(),
            tris: Vec::new(),
            local: Vec::new(),
        }
    }

    #[inline]
    fn triangle(&mut self, t: [u32; 3]) -> Result<(), LoadError> {
        (self.f)(t)?;
        self.count += 1;
        Ok(())
    }

    /// The first corner of [`Self::corners`] that is not a vertex of `positions`.
    fn missing_corner(&self) -> Option<u32> {
        self.corners.iter().copied().find(|&c| c as usize >= self.positions.count())
    }

    /// Triangulates [`Self::corners`] (at least three, every one a vertex of `positions`).
    fn polygon(&mut self) -> Result<(), LoadError> {
        if let [a, b, c] = self.corners[..] {
            return self.triangle([a, b, c]);
        }
        let mut tris = std::mem::take(&mut self.tris);
        tris.clear();
        // Triangulated on the corners' own positions (numbered 0..n), then renumbered: the
        // triangulation reads nothing else, and the positions need not all be held.
        let mut local = std::mem::take(&mut self.local);
        local.clear();
        self.positions.gather(&self.corners, &mut local);
        let numbered: Vec<u32> = (0..self.corners.len() as u32).collect();
        self.triangulator.polygon(&local, &numbered, &mut tris);
        for t in tris.iter_mut() {
            *t = t.map(|i| self.corners[i as usize]);
        }
        self.local = local;
        let result = tris.iter().try_for_each(|&t| self.triangle(t));
        self.tris = tris;
        result
    }
}

/// The bytes the file holds: read no further than its length when opened (a file that grows
/// while read cannot make a reader go on without end), reporting progress.
struct RawFile<'p> {
    file: Box<dyn ReadSeek + 'p>,
    pos: u64,
    len: u64,
    progress: &'p mut dyn FnMut(u64),
}

impl RawFile<'_> {
    /// Moves `n` bytes forward; false if that is past the end (then left at the end).
    fn seek_forward(&mut self, n: u64) -> std::io::Result<bool> {
        let room = self.len - self.pos;
        let ok = n <= room;
        self.pos += n.min(room);
        self.file.seek(SeekFrom::Start(self.pos))?;
        (self.progress)(self.pos);
        Ok(ok)
    }
}

impl Read for RawFile<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let room = (self.len - self.pos).min(buf.len() as u64) as usize;
        if room == 0 {
            return Ok(0);
        }
        let n = self.file.read(&mut buf[..room])?;
        self.pos += n as u64;
        (self.progress)(self.pos);
        Ok(n)
    }
}

enum Inner<'p> {
    Plain(RawFile<'p>),
    Gzip {
        decoder: Box<MultiGzDecoder<BufReader<RawFile<'p>>>>,
        /// Decompressed bytes so far, and the most allowed.
        total: u64,
        limit: u64,
    },
}

/// What a [`RawFile`] reads: a file, or bytes in memory.
trait ReadSeek: Read + Seek {}

impl<T: Read + Seek> ReadSeek for T {}

/// Buffer size of a [`Source`]: the bound on what a pass holds of the file.
const BUFFER: usize = 1 << 20;

/// A buffered reader over a mesh file, plain or gzip, whose errors are [`LoadError`]s
/// worded as the in-core loader words them.
struct Source<'a> {
    path: &'a Path,
    inner: Inner<'a>,
    /// The file's length as stored (compressed, for gzip).
    raw_len: u64,
    buf: Vec<u8>,
    /// Unread bytes are `buf[pos..end]`.
    pos: usize,
    end: usize,
    /// Whether [`Source::line`] ends lines at a carriage return instead of a line feed (a PLY
    /// file whose lines end in bare carriage returns, see [`Source::detect_cr_lines`]).
    cr_lines: bool,
}

impl<'a> Source<'a> {
    /// Opens `path` (a regular file), decompressing it if it starts with gzip's magic bytes,
    /// and reporting the bytes of the file read to `progress`.
    fn open(input: Input<'a>, progress: &'a mut dyn FnMut(u64)) -> Result<Self, LoadError> {
        let path = input.path;
        let (mut file, len): (Box<dyn ReadSeek + 'a>, u64) = match input.bytes {
            Some(bytes) => (Box::new(std::io::Cursor::new(bytes)), bytes.len() as u64),
            None => {
                let (file, len) = crate::input::open_regular(path).map_err(|e| err(path, e))?;
                (Box::new(file), len)
            }
        };
        let cannot = |e: std::io::Error| err(path, format!("cannot read: {e}"));
        let mut magic = Vec::with_capacity(2);
        (&mut file).take(2).read_to_end(&mut magic).map_err(cannot)?;
        file.seek(SeekFrom::Start(0)).map_err(cannot)?;
        let raw = RawFile { file, pos: 0, len, progress };
        let inner = if magic == [0x1f, 0x8b] {
            Inner::Gzip {
                decoder: Box::new(MultiGzDecoder::new(BufReader::with_capacity(256 << 10, raw))),
                total: 0,
                limit: crate::input::max_decompressed_bytes(),
            }
        } else {
            Inner::Plain(raw)
        };
        Ok(Source { path, inner, raw_len: len, buf: vec![0; BUFFER], pos: 0, end: 0, cr_lines: false })
    }

    /// An upper bound on the bytes this source yields: the file's length, or the cap on
    /// decompressed bytes. Bounds what a header's counts may make a reader reserve.
    fn size_bound(&self) -> u64 {
        match &self.inner {
            Inner::Plain(raw) => raw.len,
            Inner::Gzip { limit, .. } => *limit,
        }
    }

    /// One read into `buf[at..]`, its errors worded as `load_bytes` words them.
    fn read_inner(&mut self, at: usize) -> Result<usize, LoadError> {
        let buf = &mut self.buf[at..];
        let result = loop {
            let r = match &mut self.inner {
                Inner::Plain(raw) => raw.read(buf),
                Inner::Gzip { decoder, .. } => decoder.read(buf),
            };
            match r {
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                r => break r,
            }
        };
        let message = match (&mut self.inner, result) {
            (Inner::Plain(_), Ok(n)) => return Ok(n),
            (Inner::Plain(_), Err(e)) => format!("cannot read: {e}"),
            (Inner::Gzip { total, limit, .. }, Ok(n)) => {
                *total += n as u64;
                if *total <= *limit {
                    return Ok(n);
                }
                format!("decompresses to more than {limit} bytes, the limit (raise it with --max-decompressed BYTES)")
            }
            (Inner::Gzip { .. }, Err(e)) => format!("corrupt gzip data: {e}"),
        };
        Err(err(self.path, message))
    }

    /// Reads more bytes after the unread ones (moving those to the front); false at the end.
    fn fill(&mut self) -> Result<bool, LoadError> {
        if self.pos > 0 {
            self.buf.copy_within(self.pos..self.end, 0);
            self.end -= self.pos;
            self.pos = 0;
        }
        if self.end == self.buf.len() {
            return Ok(true);
        }
        let n = self.read_inner(self.end)?;
        self.end += n;
        Ok(n > 0)
    }

    /// Makes at least `n` unread bytes available in [`Self::unread`]; false if the file
    /// ends first.
    #[inline]
    fn ensure(&mut self, n: usize) -> Result<bool, LoadError> {
        if n > self.buf.len() {
            self.buf.resize(n, 0);
        }
        while self.end - self.pos < n {
            if !self.fill()? {
                return Ok(false);
            }
        }
        Ok(true)
    }

    #[inline]
    fn unread(&self) -> &[u8] {
        &self.buf[self.pos..self.end]
    }

    #[inline]
    fn consume(&mut self, n: usize) {
        self.pos += n;
    }

    /// Skips `n` bytes, seeking in a plain file; false if the file ends first.
    fn skip(&mut self, n: u64) -> Result<bool, LoadError> {
        let buffered = (self.end - self.pos) as u64;
        if n <= buffered {
            self.pos += n as usize;
            return Ok(true);
        }
        let mut left = n - buffered;
        (self.pos, self.end) = (0, 0);
        if let Inner::Plain(raw) = &mut self.inner {
            return raw.seek_forward(left).map_err(|e| err(self.path, format!("cannot read: {e}")));
        }
        while left > 0 {
            if !self.fill()? {
                return Ok(false);
            }
            let k = (self.end as u64).min(left);
            left -= k;
            self.pos = k as usize;
        }
        Ok(true)
    }

    /// Whether the unread bytes start with `magic` followed by a bare carriage return (not
    /// `\r\n`): then lines end at carriage returns from here on, as some CAD exporters write
    /// PLY headers. Looks no further than the first `magic.len() + 2` bytes.
    fn detect_cr_lines(&mut self, magic: &[u8]) -> Result<bool, LoadError> {
        while self.end - self.pos < magic.len() + 2 && self.fill()? {}
        let head = &self.buf[self.pos..self.end];
        let n = magic.len();
        self.cr_lines = head.starts_with(magic) && head.get(n) == Some(&b'\r') && head.get(n + 1) != Some(&b'\n');
        Ok(self.cr_lines)
    }

    /// Reads the next line, with its line break (`\n`, or `\r` after
    /// [`Source::detect_cr_lines`] found bare carriage returns), into `line` (cleared first);
    /// false at the end of the file. Refuses a line longer than `max` bytes.
    fn line(&mut self, line: &mut Vec<u8>, max: usize) -> Result<bool, LoadError> {
        line.clear();
        let end = if self.cr_lines { b'\r' } else { b'\n' };
        loop {
            let unread = &self.buf[self.pos..self.end];
            let (take, done) = match unread.iter().position(|&b| b == end) {
                Some(i) => (i + 1, true),
                None => (unread.len(), false),
            };
            line.extend_from_slice(&unread[..take]);
            self.pos += take;
            if line.len() > max {
                return Err(err(self.path, format!("a line longer than {max} bytes")));
            }
            if done || !self.fill()? {
                return Ok(done || !line.is_empty());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::{max_decompressed_bytes, set_max_decompressed_bytes};

    #[test]
    fn gzip_is_capped_and_checked_as_in_core() {
        let dir = tempfile::tempdir().unwrap();
        let text = "v 0 0 0\n".repeat(5000) + "f 1 2 3\n";
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut gz, text.as_bytes()).unwrap();
        let gz = gz.finish().unwrap();
        let path = dir.path().join("a.obj.gz");
        std::fs::write(&path, &gz).unwrap();
        assert_eq!(read_positions(&path, &mut |_| {}).unwrap().len(), 3, "the vertices the face uses");
        // No other test in this binary decompresses more than 10 kB.
        let limit = max_decompressed_bytes();
        set_max_decompressed_bytes(10_000);
        let (e, in_core) = (read_positions(&path, &mut |_| {}), super::super::load_path(&path));
        set_max_decompressed_bytes(limit);
        let (e, in_core) = (e.unwrap_err().to_string(), in_core.unwrap_err().to_string());
        assert!(e.contains("decompresses to more than 10000 bytes") && e.contains("--max-decompressed"), "{e}");
        assert_eq!(e, in_core);

        std::fs::write(&path, &gz[..gz.len() / 2]).unwrap();
        let e = read_positions(&path, &mut |_| {}).unwrap_err().to_string();
        assert!(e.starts_with(&path.display().to_string()) && e.contains("corrupt gzip data"), "{e}");
    }

    #[test]
    fn only_regular_files_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("f.ply");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let e = read_positions(&fifo, &mut |_| {}).unwrap_err().to_string();
        assert!(e.contains("not a regular file (a FIFO)"), "{e}");
        let e = read_positions(&dir.path().join("missing.obj"), &mut |_| {}).unwrap_err().to_string();
        assert!(e.contains("cannot read"), "{e}");
    }
}
