//! Mesh loaders: OBJ, PLY (ASCII and binary, face lists and triangle strips), STL (ASCII
//! and binary) and glTF 2.0 (`.gltf`, `.glb`, Draco- or meshopt-compressed; `load/gltf.rs`),
//! each optionally gzip-compressed (`flate2`).
//!
//! All three readers are ours. PLY and OBJ are read by [`stream`]'s readers, here over the
//! bytes in memory, in a file's two passes; STL by `load/stl.rs`. The crates we used before
//! (ply-rs, tobj, stl_io, still the peers of the tests and the loading benchmark) refuse
//! files other tools read and write: PLY headers whose lines end in bare carriage returns,
//! OBJ comments after a line's values and texture or normal indices out of range, ASCII STL
//! with a bare `solid` line or upper-case keywords; and tobj turns `l` polylines into faces.
//!
//! The format comes from the content ([`Format::of_file`]: PLY's first line, STL's size or
//! `solid`, OBJ's first keyword), and from the name (`.obj`, `.ply`, `.stl`, optionally
//! `.gz`) only where the content is silent; gzip is recognised by its magic bytes. Polygons
//! of PLY and OBJ faces are triangulated by one function (in `load/polygon.rs`): convex ones
//! are fanned from their first corner, `(v0, v1, v2), (v0, v2, v3), ...`, concave ones
//! ear-clipped in the plane of their Newell normal, every triangle oriented like the
//! polygon; degenerate ones (no area) are fanned. OBJ points and lines (`p`, `l`, and `f`
//! with one or two corners) are no triangles: they are skipped and counted
//! ([`Loaded::ignored`]), never made into triangles without area; PLY faces of fewer than
//! three corners are dropped. A file that gives no triangle at all (a point cloud, an empty
//! file) is an error, not an empty mesh. Strips are unrolled with alternating orientation
//! and their zero-area stitching triangles (a repeated index) dropped, as strip writers
//! intend. An OBJ file with several objects or groups is merged into one mesh by
//! concatenation. Every error is one line that names the file, what is wrong and where; no
//! input makes a loader panic.
//!
//! For files too large to hold, [`stream`] reads PLY and OBJ from the file in the same two
//! passes (the positions, then the triangles one by one), so with exactly this module's
//! result.

use std::path::Path;

use crate::mesh::Mesh;

mod error;
mod format;
mod gltf;
mod loaded;
mod polygon;
mod stl;
pub mod stream;

pub(crate) use error::err;
pub use error::{no_triangles, LoadError};
pub use format::Format;
use loaded::checked;
pub use loaded::Loaded;

/// Reads a mesh file, decompressing gzip if the bytes start with its magic number.
pub fn load_path(path: &Path) -> Result<Mesh, LoadError> {
    load_path_counted(path).map(|l| l.mesh)
}

/// [`load_path`], with the count of elements skipped.
pub fn load_path_counted(path: &Path) -> Result<Loaded, LoadError> {
    let format = Format::of_file(path)?;
    let raw = crate::input::read_file(path).map_err(|e| err(path, e))?;
    load_bytes_counted(path, &raw, format)
}

/// Parses mesh bytes (gzip or plain) in the given format; `path` is used in error messages.
pub fn load_bytes(path: &Path, raw: &[u8], format: Format) -> Result<Mesh, LoadError> {
    load_bytes_counted(path, raw, format).map(|l| l.mesh)
}

/// [`load_bytes`], with the count of elements skipped.
pub fn load_bytes_counted(path: &Path, raw: &[u8], format: Format) -> Result<Loaded, LoadError> {
    let bytes: std::borrow::Cow<[u8]> = if raw.starts_with(&[0x1f, 0x8b]) {
        let mut out =
            Vec::with_capacity(raw.len().saturating_mul(4).min(crate::input::max_decompressed_bytes() as usize));
        crate::input::read_capped(
            flate2::read::MultiGzDecoder::new(raw),
            crate::input::max_decompressed_bytes(),
            &mut out,
        )
        .map_err(|e| err(path, if e.starts_with("decompresses") { e } else { format!("corrupt gzip data: {e}") }))?;
        out.into()
    } else {
        raw.into()
    };
    let (mesh, ignored) = match format {
        Format::Obj | Format::Ply => stream::load_memory(path, &bytes, format)?,
        Format::Stl => (stl::load(path, &bytes)?, 0),
        Format::Gltf => {
            let l = gltf::load(path, &bytes)?;
            (l.mesh, l.ignored)
        }
    };
    checked(path, mesh, ignored)
}

/// As [`load_path_counted`], but a PLY or OBJ file is read in the streaming reader's two
/// passes ([`stream`]) instead of whole into memory, so that the memory follows the mesh, not
/// the file: a binary PLY of 102M triangles was held twice (3.9 GB) beside its 1.84 GB mesh.
/// The same mesh, or the same refusal; a gzipped file is decompressed once per pass.
pub fn load_path_streamed_counted(path: &Path) -> Result<Loaded, LoadError> {
    load_path_streamed_between(path, &mut |_| {})
}

/// As [`load_path_streamed_counted`], calling `between` with the vertex count once the
/// positions are read and before the triangles are (for PLY and OBJ; after loading for the
/// others): where the caller can decide how to hold what follows (`pm build` spills).
pub fn load_path_streamed_between(path: &Path, between: &mut dyn FnMut(usize)) -> Result<Loaded, LoadError> {
    let format = Format::of_file(path)?;
    if !matches!(format, Format::Ply | Format::Obj) {
        let loaded = load_path_counted(path)?;
        between(loaded.mesh.positions.len());
        return Ok(loaded);
    }
    let (mesh, ignored) = stream::load_file(path, format, between)?;
    checked(path, mesh, ignored)
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
        let verts = "0 0 0\n1 0 0\n0 1 0\n1 1 0\n2 0 0\n5 0 0\n6 0 0\n5 1 0\n";
        let ply = format!(
            "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n\
element tristrips 1\nproperty list int int vertex_indices\nend_header\n{verts}10 0 1 2 3 3 4 -1 5 6 7\n"
        );
        let out = load_bytes(Path::new("s.ply"), ply.as_bytes(), Format::Ply).unwrap().triangles;
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
