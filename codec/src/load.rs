//! Mesh loaders: OBJ (`tobj`), PLY (`ply-rs-bw`: ASCII and binary, face lists and
//! triangle strips) and STL (`stl_io`), each optionally gzip-compressed (`flate2`).
//!
//! The format comes from the file name (`.obj`, `.ply`, `.stl`, each optionally followed by
//! `.gz`); gzip is recognised by its magic bytes, whatever the name says. Polygons of PLY
//! and OBJ faces are triangulated by one function (in `load/polygon.rs`): convex ones are
//! fanned from their first corner, `(v0, v1, v2), (v0, v2, v3), ...`, concave ones ear-clipped in the
//! plane of their Newell normal, every triangle oriented like the polygon; degenerate ones
//! (no area) are fanned. OBJ points and lines (`p`, `l`, and `f` with one or two
//! corners) are no triangles: they are skipped and counted ([`Loaded::ignored`]), never made
//! into triangles without area; PLY faces of fewer than three corners are dropped. A file
//! that gives no triangle at all (a point cloud, an empty file) is an error, not an empty
//! mesh. Strips are unrolled with alternating orientation and their
//! zero-area stitching triangles (a repeated index) dropped, as strip writers intend.
//! An OBJ file with several objects or groups is merged into one mesh by concatenation.
//! Every error names the file and what is wrong; no input makes a loader panic.
//!
//! For files too large to hold, [`stream`] reads PLY and OBJ in two passes (the positions,
//! then the triangles one by one), with exactly this module's result.

use std::io::{BufRead, BufReader, Cursor, Read};
use std::path::{Path, PathBuf};

use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Property, PropertyAccess};
use thiserror::Error;

use crate::mesh::Mesh;

mod polygon;
pub mod stream;

/// A file that could not be read as a mesh.
#[derive(Debug, Error)]
#[error("{}: {message}", path.display())]
pub struct LoadError {
    pub path: PathBuf,
    pub message: String,
}

fn err(path: &Path, message: impl Into<String>) -> LoadError {
    LoadError { path: path.to_path_buf(), message: message.into() }
}

/// Mesh file formats Tessera reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Obj,
    Ply,
    Stl,
}

impl Format {
    /// The format named by a file's extension, looking through a trailing `.gz`.
    pub fn from_path(path: &Path) -> Option<Format> {
        let name = path.file_name()?.to_str()?.to_ascii_lowercase();
        let name = name.strip_suffix(".gz").unwrap_or(&name);
        match Path::new(name).extension()?.to_str()? {
            "obj" => Some(Format::Obj),
            "ply" => Some(Format::Ply),
            "stl" => Some(Format::Stl),
            _ => None,
        }
    }
}

/// A loaded mesh, and what the file held that is not a triangle.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Loaded {
    pub mesh: Mesh,
    /// Elements skipped because they are not triangles: OBJ points (`p`, `f` of one corner)
    /// and lines (`l`, `f` of two corners).
    pub ignored: u64,
}

/// The message for a file that gives no triangle.
pub(crate) fn no_triangles(ignored: u64) -> String {
    if ignored > 0 {
        format!("no triangles, only points or lines ({ignored} elements; Tessera renders triangle meshes)")
    } else {
        "no triangles (an empty file or a point cloud is not a mesh)".to_string()
    }
}

/// Reads a mesh file, decompressing gzip if the bytes start with its magic number.
pub fn load_path(path: &Path) -> Result<Mesh, LoadError> {
    load_path_counted(path).map(|l| l.mesh)
}

/// [`load_path`], with the count of elements skipped.
pub fn load_path_counted(path: &Path) -> Result<Loaded, LoadError> {
    let format = Format::from_path(path)
        .ok_or_else(|| err(path, "unknown mesh format: expected .obj, .ply or .stl, optionally .gz"))?;
    let raw = crate::input::read_file(path).map_err(|e| err(path, e))?;
    load_bytes_counted(path, &raw, format)
}

/// Parses mesh bytes (gzip or plain) in the given format; `path` is used in error messages.
pub fn load_bytes(path: &Path, raw: &[u8], format: Format) -> Result<Mesh, LoadError> {
    load_bytes_counted(path, raw, format).map(|l| l.mesh)
}

/// [`load_bytes`], with the count of elements skipped.
pub fn load_bytes_counted(path: &Path, raw: &[u8], format: Format) -> Result<Loaded, LoadError> {
    let bytes = if raw.starts_with(&[0x1f, 0x8b]) {
        let mut out =
            Vec::with_capacity(raw.len().saturating_mul(4).min(crate::input::max_decompressed_bytes() as usize));
        crate::input::read_capped(
            flate2::read::MultiGzDecoder::new(raw),
            crate::input::max_decompressed_bytes(),
            &mut out,
        )
        .map_err(|e| err(path, if e.starts_with("decompresses") { e } else { format!("corrupt gzip data: {e}") }))?;
        out
    } else {
        raw.to_vec()
    };
    let (mesh, ignored) = match format {
        Format::Obj => load_obj(path, &bytes)?,
        Format::Ply => (load_ply(path, &bytes)?, 0),
        Format::Stl => (load_stl(path, &bytes)?, 0),
    };
    if let Some(bad) = mesh.triangles.iter().flatten().find(|&&i| i as usize >= mesh.positions.len()) {
        return Err(err(
            path,
            format!("a face uses vertex {bad}, but the file has only {} vertices", mesh.positions.len()),
        ));
    }
    if mesh.triangles.is_empty() {
        return Err(err(path, no_triangles(ignored)));
    }
    Ok(Loaded { mesh, ignored })
}

/// The mesh and the number of points and lines skipped.
fn load_obj(path: &Path, bytes: &[u8]) -> Result<(Mesh, u64), LoadError> {
    // Points (`p`) and polylines (`l`) are no faces, but tobj gives an `l` of three corners
    // as a triangle: such lines are counted and turned into comments (same length) before
    // tobj reads the file.
    let mut owned = None;
    let mut ignored = 0u64;
    let mut start = 0;
    for line in bytes.split_inclusive(|&b| b == b'\n') {
        let first = std::str::from_utf8(line).ok().and_then(|t| t.split_whitespace().next());
        if matches!(first, Some("p" | "l")) {
            ignored += 1;
            let at = start + line.iter().position(|b| !b.is_ascii_whitespace()).unwrap_or(0);
            owned.get_or_insert_with(|| bytes.to_vec())[at] = b'#';
        }
        start += line.len();
    }
    let bytes = owned.as_deref().unwrap_or(bytes);
    // Faces come as polygons (`face_arities`, empty when all are triangles) and are
    // triangulated here, as PLY faces are: tobj's own triangulation fans every polygon.
    let options = tobj::LoadOptions { triangulate: false, single_index: false, ..Default::default() };
    let mut reader = BufReader::new(Cursor::new(bytes));
    // Materials are irrelevant to geometry; a missing .mtl must not fail the load.
    let (models, _materials) = tobj::load_obj_buf(&mut reader, &options, |_| Err(tobj::LoadError::OpenFileFailed))
        .map_err(|e| err(path, format!("malformed OBJ: {e}")))?;
    let mut mesh = Mesh::default();
    let mut triangulator = polygon::Triangulator::default();
    let mut corners = Vec::new();
    for model in models {
        let m = model.mesh;
        let arities_sum: u64 = m.face_arities.iter().map(|&a| u64::from(a)).sum();
        if m.positions.len() % 3 != 0
            || (m.face_arities.is_empty() && m.indices.len() % 3 != 0)
            || (!m.face_arities.is_empty() && arities_sum != m.indices.len() as u64)
        {
            return Err(err(path, "malformed OBJ: ragged position or index arrays"));
        }
        let base = mesh.positions.len() as u32;
        let count = m.positions.len() / 3;
        if m.indices.iter().any(|&i| i as usize >= count) {
            return Err(err(path, format!("object '{}' has a face index out of range", model.name)));
        }
        mesh.positions.extend(m.positions.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        if m.face_arities.is_empty() {
            mesh.triangles.extend(m.indices.chunks_exact(3).map(|t| [base + t[0], base + t[1], base + t[2]]));
            continue;
        }
        let mut next = 0usize;
        for &arity in &m.face_arities {
            let face = &m.indices[next..next + arity as usize];
            next += arity as usize;
            match *face {
                // Faces of one or two corners are points and lines: skipped, counted.
                [] => return Err(err(path, "malformed OBJ: a face without vertices")),
                [_] | [_, _] => ignored += 1,
                _ => {
                    corners.clear();
                    corners.extend(face.iter().map(|&i| base + i));
                    triangulator.polygon(&mesh.positions, &corners, &mut mesh.triangles);
                }
            }
        }
    }
    Ok((mesh, ignored))
}

/// A PLY vertex: `x`, `y`, `z` of any numeric type; other properties are ignored.
#[derive(Default)]
struct PlyVertex([f32; 3]);

/// A PLY face or strip: its index list, whatever the integer type.
#[derive(Default)]
struct PlyIndices(Vec<i64>);

fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v as f64,
        Property::UChar(v) => v as f64,
        Property::Short(v) => v as f64,
        Property::UShort(v) => v as f64,
        Property::Int(v) => v as f64,
        Property::UInt(v) => v as f64,
        Property::Float(v) => v as f64,
        Property::Double(v) => v,
        _ => return None,
    })
}

impl PropertyAccess for PlyVertex {
    fn new() -> Self {
        PlyVertex::default()
    }
    fn set_property(&mut self, name: String, property: Property) {
        let axis = match name.as_str() {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => return,
        };
        if let Some(v) = scalar(&property) {
            self.0[axis] = v as f32;
        }
    }
}

impl PropertyAccess for PlyIndices {
    fn new() -> Self {
        PlyIndices::default()
    }
    fn set_property(&mut self, name: String, property: Property) {
        if name != "vertex_indices" && name != "vertex_index" {
            return;
        }
        self.0 = match property {
            Property::ListChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
            _ => return,
        };
    }
}

/// A PLY file whose lines end in bare carriage returns (as some CAD exporters write them),
/// with its line breaks made line feeds for ply-rs, which reads `\n` and `\r\n` only: in the
/// header, and in the whole file if it is ASCII (same length, so binary records stay where
/// they are). `None` for other files. A line feed inside such a file's lines is an error, as
/// in the streaming reader, which splits these files' lines at carriage returns.
fn cr_lines_to_lf(path: &Path, bytes: &[u8]) -> Result<Option<Vec<u8>>, LoadError> {
    if !(bytes.starts_with(b"ply\r") && bytes.get(4) != Some(&b'\n')) {
        return Ok(None);
    }
    let marker = b"end_header\r";
    let header_end = bytes.windows(marker.len()).position(|w| w == marker).map_or(bytes.len(), |i| i + marker.len());
    let ascii = bytes[..header_end].split(|&b| b == b'\r').any(|l| l.starts_with(b"format ascii"));
    let upto = if ascii { bytes.len() } else { header_end };
    if bytes[..header_end].contains(&b'\n') {
        return Err(err(path, "malformed PLY header: a line feed inside a line (its lines end in carriage returns)"));
    }
    let mut out = bytes.to_vec();
    for b in &mut out[..upto] {
        if *b == b'\r' {
            *b = b'\n';
        }
    }
    Ok(Some(out))
}

fn load_ply(path: &Path, bytes: &[u8]) -> Result<Mesh, LoadError> {
    let converted = cr_lines_to_lf(path, bytes)?;
    let bytes = converted.as_deref().unwrap_or(bytes);
    let mut reader = BufReader::new(Cursor::new(bytes));
    let header = Parser::<DefaultElement>::new()
        .read_header(&mut reader)
        .map_err(|e| err(path, format!("malformed PLY header: {e}")))?;
    let vertex_parser = Parser::<PlyVertex>::new();
    let index_parser = Parser::<PlyIndices>::new();
    let skip_parser = Parser::<DefaultElement>::new();
    let mut mesh = Mesh::default();
    let mut saw_vertices = false;
    // Faces are triangulated once the positions are known (a file may list them first):
    // their corners in one list, and where each face ends.
    let (mut corners, mut face_ends) = (Vec::new(), Vec::new());
    for (name, def) in &header.elements {
        let bad = |e: std::io::Error| err(path, format!("malformed PLY element '{name}': {e}"));
        match name.as_str() {
            "vertex" => {
                let verts = vertex_parser.read_payload_for_element(&mut reader, def, &header).map_err(bad)?;
                mesh.positions = verts.into_iter().map(|v| v.0).collect();
                saw_vertices = true;
            }
            "face" => {
                let faces = index_parser.read_payload_for_element(&mut reader, def, &header).map_err(bad)?;
                for f in faces.iter().filter(|f| f.0.len() >= 3) {
                    for &i in &f.0 {
                        corners.push(index(path, i)?);
                    }
                    face_ends.push(corners.len());
                }
            }
            "tristrips" => {
                let strips = index_parser.read_payload_for_element(&mut reader, def, &header).map_err(bad)?;
                for s in strips {
                    unroll_strip(path, &s.0, &mut mesh.triangles)?;
                }
            }
            _ => {
                skip_parser.read_payload_for_element(&mut reader, def, &header).map_err(bad)?;
            }
        }
    }
    if !saw_vertices {
        return Err(err(path, "PLY file has no 'vertex' element"));
    }
    let mut triangulator = polygon::Triangulator::default();
    let mut start = 0;
    for end in face_ends {
        triangulator.polygon(&mesh.positions, &corners[start..end], &mut mesh.triangles);
        start = end;
    }
    let mut rest = [0u8; 1];
    let _ = reader.fill_buf();
    let _ = reader.read(&mut rest);
    Ok(mesh)
}

fn index(path: &Path, i: i64) -> Result<u32, LoadError> {
    u32::try_from(i).map_err(|_| err(path, format!("vertex index {i} is out of range")))
}

/// Unrolls a triangle strip; a negative index restarts the strip.
fn unroll_strip(path: &Path, strip: &[i64], out: &mut Vec<[u32; 3]>) -> Result<(), LoadError> {
    for run in strip.split(|&i| i < 0) {
        for (k, w) in run.windows(3).enumerate() {
            let (a, b, c) = (index(path, w[0])?, index(path, w[1])?, index(path, w[2])?);
            if a == b || b == c || a == c {
                continue;
            }
            out.push(if k % 2 == 0 { [a, b, c] } else { [b, a, c] });
        }
    }
    Ok(())
}

fn load_stl(path: &Path, bytes: &[u8]) -> Result<Mesh, LoadError> {
    let indexed = stl_io::read_stl(&mut Cursor::new(bytes)).map_err(|e| err(path, format!("malformed STL: {e}")))?;
    let positions = indexed.vertices.iter().map(|v| [v[0], v[1], v[2]]).collect();
    let mut triangles = Vec::with_capacity(indexed.faces.len());
    for f in &indexed.faces {
        let [a, b, c] = f.vertices;
        let conv = |i: usize| u32::try_from(i).map_err(|_| err(path, "too many STL vertices"));
        triangles.push([conv(a)?, conv(b)?, conv(c)?]);
    }
    Ok(Mesh { positions, triangles })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_from_name() {
        assert_eq!(Format::from_path(Path::new("a/b.OBJ")), Some(Format::Obj));
        assert_eq!(Format::from_path(Path::new("dragon.ply.gz")), Some(Format::Ply));
        assert_eq!(Format::from_path(Path::new("x.stl")), Some(Format::Stl));
        assert_eq!(Format::from_path(Path::new("x.gz")), None);
        assert_eq!(Format::from_path(Path::new("x.off")), None);
    }

    #[test]
    fn strips_alternate_and_skip_stitches() {
        let mut out = vec![];
        unroll_strip(Path::new("s"), &[0, 1, 2, 3, 3, 4, -1, 5, 6, 7], &mut out).unwrap();
        assert_eq!(out, vec![[0, 1, 2], [2, 1, 3], [5, 6, 7]]);
        assert!(out.iter().all(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2]));
    }

    #[test]
    fn ascii_ply_polygons_are_fanned() {
        let ply = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
        let m = load_bytes(Path::new("q.ply"), ply, Format::Ply).unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.positions[2], [1.0, 1.0, 0.0]);
    }

    #[test]
    fn concave_polygons_load_alike_from_obj_and_ply() {
        // An L (reflex corner 3: the fan from corner 0 would leave it) and a convex quad.
        let verts = "0 0 0\n3 0 0\n3 1 0\n1 1 0\n1 2 0\n0 2 0\n5 0 0\n6 0 0\n6 1 0\n5 1 0\n";
        let obj =
            format!("{}f 1 2 3 4 5 6\nf 7 8 9 10\n", verts.lines().map(|l| format!("v {l}\n")).collect::<String>());
        let ply = format!(
            "ply\nformat ascii 1.0\nelement vertex 10\nproperty float x\nproperty float y\nproperty float z\n\
element face 2\nproperty list uchar int vertex_indices\nend_header\n{verts}6 0 1 2 3 4 5\n4 6 7 8 9\n"
        );
        let o = load_bytes(Path::new("l.obj"), obj.as_bytes(), Format::Obj).unwrap();
        let p = load_bytes(Path::new("l.ply"), ply.as_bytes(), Format::Ply).unwrap();
        assert_eq!(o, p);
        assert_eq!(&o.triangles[4..], &[[6, 7, 8], [6, 8, 9]], "the convex quad is fanned");
        let l = &o.triangles[..4];
        let area = |t: &[u32; 3]| {
            let [a, b, c] = t.map(|i| o.positions[i as usize]);
            ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])) / 2.0
        };
        assert!(l.iter().all(|t| area(t) > 0.0), "every triangle keeps the counter-clockwise winding: {l:?}");
        assert_eq!(l.iter().map(area).sum::<f32>(), 4.0, "the triangles cover the L");
    }

    #[test]
    fn obj_points_and_lines_are_skipped_and_counted() {
        // `l 1 2 3` is a polyline of three vertices, not a triangle.
        let obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1\nf 1 2\nl 2 3\n  l 1 2 3\np 1\nf 1 2 3\n";
        let l = load_bytes_counted(Path::new("p.obj"), obj, Format::Obj).unwrap();
        assert_eq!(l.mesh.triangles, vec![[0, 1, 2]]);
        assert_eq!(l.ignored, 5);
        let only_lines = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2 3\nl 3 1\n";
        let e = load_bytes(Path::new("l.obj"), only_lines, Format::Obj).unwrap_err();
        assert_eq!(
            e.to_string(),
            "l.obj: no triangles, only points or lines (2 elements; Tessera renders triangle meshes)"
        );
        for (name, bytes) in [("e.obj", &b""[..]), ("c.obj", b"v 0 0 0\nv 1 0 0\n")] {
            let e = load_bytes(Path::new(name), bytes, Format::Obj).unwrap_err();
            assert!(e.to_string().ends_with("no triangles (an empty file or a point cloud is not a mesh)"), "{e}");
        }
        let cloud = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 1 1\n";
        let e = load_bytes(Path::new("c.ply"), cloud, Format::Ply).unwrap_err();
        assert!(e.to_string().contains("no triangles"), "{e}");
    }

    #[test]
    fn stl_ascii_binary_and_gzip_load_alike() {
        let ascii =
            b"solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n\
facet normal 0 0 1\nouter loop\nvertex 1 0 0\nvertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n";
        let m = load_bytes(Path::new("t.stl"), ascii, Format::Stl).unwrap();
        assert_eq!(m.triangles.len(), 2);
        assert_eq!(m.positions.len(), 4, "stl_io welds the shared corners");

        let tris: Vec<stl_io::Triangle> = m
            .triangles
            .iter()
            .map(|t| stl_io::Triangle {
                normal: stl_io::Normal::new([0.0, 0.0, 1.0]),
                vertices: t.map(|i| stl_io::Vertex::new(m.positions[i as usize])),
            })
            .collect();
        let mut binary = Vec::new();
        stl_io::write_stl(&mut binary, tris.iter()).unwrap();
        let b = load_bytes(Path::new("t.stl"), &binary, Format::Stl).unwrap();
        assert_eq!(b, m);

        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut gz, &binary).unwrap();
        let g = load_bytes(Path::new("t.stl.gz"), &gz.finish().unwrap(), Format::Stl).unwrap();
        assert_eq!(g, m);
    }

    #[test]
    fn malformed_files_name_the_file() {
        let bad_ply = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n0\n";
        let e = load_bytes(Path::new("broken.ply"), bad_ply, Format::Ply).unwrap_err();
        assert!(e.to_string().starts_with("broken.ply: "), "{e}");
        let out_of_range = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n";
        let e = load_bytes(Path::new("o.obj"), out_of_range, Format::Obj).unwrap_err();
        assert!(e.to_string().contains("o.obj"), "{e}");
        let e = load_bytes(Path::new("t.stl"), b"solid x\nfacet", Format::Stl).unwrap_err();
        assert!(e.to_string().contains("t.stl"), "{e}");
        let e = load_bytes(Path::new("g.obj"), &[0x1f, 0x8b, 0, 1, 2], Format::Obj).unwrap_err();
        assert!(e.to_string().contains("gzip"), "{e}");
    }
}
