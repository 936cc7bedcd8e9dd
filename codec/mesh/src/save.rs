//! Mesh writers: binary little-endian PLY and OBJ.
//!
//! Written by hand because both formats are a few lines to emit, and `ply-rs-bw`'s writer
//! wants one `DefaultElement` map per vertex and per face, an allocation each.

use std::io::{self, Write};
use std::path::Path;

use crate::mesh::Mesh;

/// Writes `mesh` as binary little-endian PLY with float positions, and where the mesh has
/// them 8-bit `red green blue` colours (`alpha` too when some alpha is not 255) and float
/// `nx ny nz` normals.
pub fn write_ply<W: Write + ?Sized>(mesh: &Mesh, out: &mut W) -> io::Result<()> {
    let colors = !mesh.colors.is_empty();
    let alpha = mesh.colors.iter().any(|c| c[3] != 255);
    let normals = !mesh.normals.is_empty();
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by tessera\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n",
        mesh.positions.len()
    );
    if colors {
        header += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    }
    if alpha {
        header += "property uchar alpha\n";
    }
    if normals {
        header += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    header += &format!("element face {}\nproperty list uchar uint vertex_indices\nend_header\n", mesh.triangles.len());
    out.write_all(header.as_bytes())?;
    let vertex = 12 + if alpha { 4 } else { 3 * colors as usize } + 12 * normals as usize;
    let mut buf = Vec::with_capacity(mesh.positions.len() * vertex + mesh.triangles.len() * 13);
    for (i, p) in mesh.positions.iter().enumerate() {
        for c in p {
            buf.extend_from_slice(&c.to_le_bytes());
        }
        if colors {
            buf.extend_from_slice(&mesh.colors[i][..if alpha { 4 } else { 3 }]);
        }
        if normals {
            for c in mesh.normals[i] {
                buf.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    for t in &mesh.triangles {
        buf.push(3);
        for i in t {
            buf.extend_from_slice(&i.to_le_bytes());
        }
    }
    out.write_all(&buf)
}

/// Writes `mesh` as OBJ (`v` and 1-based `f` lines). Rust's float formatting prints the
/// shortest string that reads back to the same `f32`, so positions survive exactly.
pub fn write_obj<W: Write + ?Sized>(mesh: &Mesh, out: &mut W) -> io::Result<()> {
    let mut w = io::BufWriter::new(out);
    writeln!(w, "# written by tessera: {} vertices, {} triangles", mesh.positions.len(), mesh.triangles.len())?;
    for p in &mesh.positions {
        writeln!(w, "v {} {} {}", p[0], p[1], p[2])?;
    }
    for t in &mesh.triangles {
        writeln!(w, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
    }
    w.flush()
}

/// A mesh writer: [`write_ply`] or [`write_obj`].
pub type WriteMesh = fn(&Mesh, &mut dyn Write) -> io::Result<()>;

/// The writer for a path's extension (`.ply` or `.obj`), or `None`.
pub fn writer_for(path: &Path) -> Option<WriteMesh> {
    match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
        "ply" => Some(|m, w| write_ply(m, w)),
        "obj" => Some(|m, w| write_obj(m, w)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::load::{load_bytes, Format};

    fn sample() -> Mesh {
        Mesh {
            positions: vec![[0.0, 0.0, 0.0], [1.5, -2.25, 1e-7], [0.1, 0.2, 0.3], [3.0, 1.0, -1.0]],
            triangles: vec![[0, 1, 2], [2, 1, 3]],
            ..Default::default()
        }
    }

    #[test]
    fn ply_keeps_colours_and_normals() {
        for alpha in [255u8, 7] {
            let mut m = sample();
            m.colors = vec![[1, 2, 3, 255], [250, 0, 128, alpha], [9, 9, 9, 255], [0, 255, 0, 255]];
            m.normals = vec![[0.0, 0.0, 1.0], [0.6, 0.8, 0.0], [-1.0, 0.0, 0.0], [0.0, -0.5, 0.5]];
            let mut ply = vec![];
            write_ply(&m, &mut ply).unwrap();
            assert_eq!(load_bytes(Path::new("m.ply"), &ply, Format::Ply).unwrap(), m);
            let header = String::from_utf8_lossy(&ply[..300]).into_owned();
            assert_eq!(header.contains("property uchar alpha"), alpha != 255);
        }
    }

    #[test]
    fn ply_and_obj_read_back_exactly() {
        let m = sample();
        let mut ply = vec![];
        write_ply(&m, &mut ply).unwrap();
        assert_eq!(load_bytes(Path::new("m.ply"), &ply, Format::Ply).unwrap(), m);
        let mut obj = vec![];
        write_obj(&m, &mut obj).unwrap();
        assert_eq!(load_bytes(Path::new("m.obj"), &obj, Format::Obj).unwrap(), m);
    }
}
