//! STL, ASCII and binary, read here rather than with `stl_io`, which refuses ASCII files that
//! other tools read and write: a `solid` line without a name, keywords in upper case
//! (`SOLID`, `FACET NORMAL`), several `solid` blocks in one file. The format is small (a
//! keyword grammar, or 50-byte records), so the reader is too.
//!
//! * **Binary or ASCII** is told by size, not by the first word: a file of exactly
//!   `84 + 50 n` bytes, `n` being the count at byte 80, is binary even when its 80-byte
//!   header starts with `solid` (as some CAD exporters write it); any other file that starts
//!   with `solid` (any case, after optional whitespace) and holds no NUL byte is ASCII;
//!   anything else is a binary
//!   file of the wrong size, an error that gives both sizes.
//! * **ASCII**: words separated by any whitespace, keywords in any case; `solid` takes the
//!   rest of its line as a name (possibly none), `endsolid` too; a facet is `facet normal
//!   nx ny nz`, `outer loop`, three or more `vertex x y z`, `endloop`, `endfacet` (a facet of
//!   more than three vertices is fanned from its first). The facet normal is not used. The
//!   file may end without `endsolid`, not inside a facet.
//! * **Welding**: STL lists each triangle's corners; corners with the same coordinates (bit
//!   for bit) become one vertex, numbered in order of first appearance, so that the mesh has
//!   connectivity.
//! * A non-finite coordinate is an error naming the facet and its corner.

use std::collections::HashMap;
use std::path::Path;

use super::error::{err, LoadError};
use crate::mesh::Mesh;

/// Reads an STL file's bytes (already decompressed).
pub(super) fn load(path: &Path, bytes: &[u8]) -> Result<Mesh, LoadError> {
    // The triangle count of a binary file.
    let count = bytes.get(80..84).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as u64);
    if let Some(n) = count.filter(|&n| 84 + 50 * n == bytes.len() as u64) {
        return binary(path, bytes, n as usize);
    }
    let text = bytes.trim_ascii_start();
    // A truncated binary file whose header starts with `solid` holds NUL bytes; text does not.
    if text.len() >= 5 && text[..5].eq_ignore_ascii_case(b"solid") && !bytes.contains(&0) {
        return ascii(path, bytes);
    }
    let Some(n) = count else {
        return Err(err(path, format!("malformed STL: {} bytes, neither ASCII (no 'solid') nor binary", bytes.len())));
    };
    Err(err(
        path,
        format!(
            "malformed STL: binary with {n} triangles should be {} bytes, the file has {} (truncated?)",
            84 + 50 * n,
            bytes.len()
        ),
    ))
}

/// Numbers corners by their coordinates' bits, in order of first appearance.
#[derive(Default)]
struct Welder {
    mesh: Mesh,
    ids: HashMap<[u32; 3], u32>,
}

impl Welder {
    fn vertex(&mut self, p: [f32; 3]) -> u32 {
        let next = self.mesh.positions.len() as u32;
        let id = *self.ids.entry(p.map(f32::to_bits)).or_insert(next);
        if id == next {
            self.mesh.positions.push(p);
        }
        id
    }
}

fn finite(path: &Path, facet: usize, corner: usize, p: [f32; 3]) -> Result<[f32; 3], LoadError> {
    if p.iter().all(|c| c.is_finite()) {
        return Ok(p);
    }
    Err(err(path, format!("facet {facet}, corner {corner}: a non-finite coordinate {p:?}")))
}

fn binary(path: &Path, bytes: &[u8], n: usize) -> Result<Mesh, LoadError> {
    let mut w = Welder::default();
    w.mesh.triangles.reserve(n);
    for (facet, record) in bytes[84..].chunks_exact(50).enumerate() {
        let f = |k: usize| f32::from_le_bytes([record[k], record[k + 1], record[k + 2], record[k + 3]]);
        let mut t = [0u32; 3];
        for (corner, id) in t.iter_mut().enumerate() {
            let at = 12 + 12 * corner;
            *id = w.vertex(finite(path, facet, corner, [f(at), f(at + 4), f(at + 8)])?);
        }
        w.mesh.triangles.push(t);
    }
    Ok(w.mesh)
}

fn ascii(path: &Path, bytes: &[u8]) -> Result<Mesh, LoadError> {
    let text = std::str::from_utf8(bytes).map_err(|e| err(path, format!("malformed STL: not text ({e})")))?;
    let mut w = Welder::default();
    let mut corners: Vec<u32> = Vec::new();
    let mut facet = 0usize;
    // Where the grammar stands: outside a solid, inside one between facets, or inside a
    // facet (after `facet`, with its corners so far).
    #[derive(PartialEq)]
    enum At {
        Outside,
        Solid,
        Facet,
    }
    let mut at = At::Outside;
    for (n, line) in text.lines().enumerate() {
        let bad = |what: String| err(path, format!("malformed STL, line {}: {what}", n + 1));
        let mut words = line.split_whitespace();
        let Some(first) = words.next() else { continue };
        let key = first.to_ascii_lowercase();
        match (key.as_str(), &at) {
            // The rest of the line is the name, whatever it holds.
            ("solid", At::Outside) => at = At::Solid,
            ("endsolid", At::Solid) => at = At::Outside,
            ("facet", At::Solid) => {
                let normal = words.next().map(str::to_ascii_lowercase);
                if normal.as_deref() != Some("normal") {
                    return Err(bad("'facet' without 'normal'".into()));
                }
                corners.clear();
                at = At::Facet;
            }
            ("outer", At::Facet) => {
                if words.next().map(str::to_ascii_lowercase).as_deref() != Some("loop") {
                    return Err(bad("'outer' without 'loop'".into()));
                }
            }
            ("vertex", At::Facet) => {
                let mut p = [0f32; 3];
                for c in &mut p {
                    let word = words.next().ok_or_else(|| bad("a vertex needs three numbers".into()))?;
                    *c = word.parse().map_err(|_| bad(format!("'{word}' is not a number")))?;
                }
                let p = finite(path, facet, corners.len(), p).map_err(|e| bad(e.message))?;
                corners.push(w.vertex(p));
            }
            ("endloop", At::Facet) => {}
            ("endfacet", At::Facet) => {
                if corners.len() < 3 {
                    return Err(bad(format!("a facet with {} vertices", corners.len())));
                }
                for k in 1..corners.len() - 1 {
                    w.mesh.triangles.push([corners[0], corners[k], corners[k + 1]]);
                }
                facet += 1;
                at = At::Solid;
            }
            _ => {
                let place = match at {
                    At::Outside => "outside a solid",
                    At::Solid => "between facets",
                    At::Facet => "inside a facet",
                };
                return Err(bad(format!("unexpected '{first}' {place}")));
            }
        }
    }
    if at == At::Facet {
        return Err(err(path, "malformed STL: the file ends inside a facet"));
    }
    Ok(w.mesh)
}
