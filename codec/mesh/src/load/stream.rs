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
use std::path::Path;

use super::error::{err, LoadError};
use super::format::Format;

mod emitter;
mod obj;
mod ply;
mod source;

use emitter::Emitter;
pub use emitter::PositionSource;
pub use source::Input;

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
