//! Large test models from a shared mesh: `L` levels of midpoint subdivision (every triangle
//! becomes `4^L`), written as binary PLY while they are generated, so the memory used follows
//! the input mesh, not the output (the dragon at `L = 4` gives 223M triangles from about
//! 0.1 GB). Scale benchmarks write their models with it into a temporary folder; none is
//! ever committed.
//!
//! Each input triangle `(A, B, C)` is cut by an `n x n` barycentric grid, `n = 2^L`, into `n²`
//! triangles oriented like it. The grid points are numbered so that neighbours share them:
//! first every input vertex (its own index), then the `n - 1` inner points of every input edge
//! (edges numbered in order of first use, points from the edge's lower-numbered end), then the
//! inner points of every triangle. A closed, consistently oriented input stays closed and
//! consistently oriented; boundaries, non-manifold edges and degenerate triangles stay what
//! they were, `n` times finer.
//!
//! New points move by a small deterministic offset, a hash of their index times `displace`
//! times the input's mean edge length over `n`, so the surface does not stay piecewise flat
//! (flat patches would make the codec's parallelogram prediction unrealistically good).
//! Input vertices do not move.

use std::collections::HashMap;
use std::io::Write;

use anyhow::{bail, Result};
use rayon::prelude::*;

/// Counts of a subdivided mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Counts {
    pub vertices: u64,
    pub triangles: u64,
}

/// The input mesh's edges, the only table the generator keeps: memory follows the input.
pub struct Subdivision<'a> {
    mesh: &'a codec::Mesh,
    /// Segments per input edge, `2^levels`.
    n: u32,
    /// Endpoints of each edge, the lower index first.
    edges: Vec<[u32; 2]>,
    /// Each triangle's three edges, AB, BC, CA.
    face_edges: Vec<[u32; 3]>,
    /// The offset scale: `displace` times the mean edge length over `n`.
    offset: f32,
}

impl<'a> Subdivision<'a> {
    pub fn new(mesh: &'a codec::Mesh, levels: u32, displace: f32) -> Result<Subdivision<'a>> {
        if levels > 10 {
            bail!("{levels} levels of subdivision make 4^{levels} triangles of each one; at most 10");
        }
        let n = 1u32 << levels;
        let mut ids: HashMap<[u32; 2], u32> = HashMap::with_capacity(mesh.triangles.len() * 3 / 2);
        let mut edges = Vec::with_capacity(mesh.triangles.len() * 3 / 2);
        let mut face_edges = Vec::with_capacity(mesh.triangles.len());
        let mut length = 0.0f64;
        for t in &mesh.triangles {
            let mut fe = [0; 3];
            for (k, slot) in fe.iter_mut().enumerate() {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let key = [a.min(b), a.max(b)];
                *slot = *ids.entry(key).or_insert_with(|| {
                    let p = |v: u32| glam::Vec3::from(mesh.positions[v as usize]);
                    length += f64::from(p(key[0]).distance(p(key[1])));
                    edges.push(key);
                    edges.len() as u32 - 1
                });
            }
            face_edges.push(fe);
        }
        let mean = if edges.is_empty() { 0.0 } else { (length / edges.len() as f64) as f32 };
        let s = Subdivision { mesh, n, edges, face_edges, offset: displace * mean / n as f32 };
        let c = s.counts();
        // PLY `int` indices: every vertex index must fit an i32.
        if c.vertices > i32::MAX as u64 {
            bail!("{} vertices do not fit the PLY's 32-bit signed indices; use fewer levels", c.vertices);
        }
        Ok(s)
    }

    /// Inner points of one triangle's grid.
    fn inner(&self) -> u64 {
        let n = self.n as u64;
        (n - 1) * n.saturating_sub(2) / 2
    }

    pub fn counts(&self) -> Counts {
        let (v, e, f, n) = (
            self.mesh.positions.len() as u64,
            self.edges.len() as u64,
            self.mesh.triangles.len() as u64,
            self.n as u64,
        );
        Counts { vertices: v + e * (n - 1) + f * self.inner(), triangles: f * n * n }
    }

    fn edge_base(&self) -> u64 {
        self.mesh.positions.len() as u64
    }

    fn face_base(&self) -> u64 {
        self.edge_base() + self.edges.len() as u64 * (self.n as u64 - 1)
    }

    /// Index of the inner point `(i, j)` (`i, j >= 1`, `i + j <= n - 1`) within its triangle:
    /// rows of `j`, each from `i = 1`.
    fn inner_index(&self, i: u32, j: u32) -> u64 {
        let (i, j, n) = (i as u64, j as u64, self.n as u64);
        // Rows before j: row r (from 1) holds n - 1 - r points.
        let before: u64 = (j - 1) * (n - 1) - (j - 1) * j / 2;
        before + (i - 1)
    }

    /// The index of grid point `(i, j)` of triangle `f`: `A (n-i-j)/n + B i/n + C j/n`.
    fn point(&self, f: usize, i: u32, j: u32) -> u64 {
        let n = self.n;
        let t = self.mesh.triangles[f];
        let fe = self.face_edges[f];
        // On an edge from `from` at parameter k (of n): the edge's point counted from its lower end.
        let on_edge = |e: u32, from: u32, k: u32| -> u64 {
            let k = if self.edges[e as usize][0] == from { k } else { n - k };
            self.edge_base() + e as u64 * (n as u64 - 1) + (k as u64 - 1)
        };
        match (i, j) {
            (0, 0) => t[0] as u64,
            (i, 0) if i == n => t[1] as u64,
            (0, j) if j == n => t[2] as u64,
            (i, 0) => on_edge(fe[0], t[0], i),
            (0, j) => on_edge(fe[2], t[0], j),
            (i, j) if i + j == n => on_edge(fe[1], t[1], j),
            (i, j) => self.face_base() + f as u64 * self.inner() + self.inner_index(i, j),
        }
    }

    /// A deterministic offset in `[-offset, offset]^3` for vertex `id`.
    fn jitter(&self, id: u64) -> glam::Vec3 {
        let mut h = id.wrapping_add(0x9E37_79B9_7F4A_7C15);
        h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        h ^= h >> 31;
        let c = |s: u32| ((h >> s) & 0xFFFF) as f32 / 32767.5 - 1.0;
        glam::Vec3::new(c(0), c(16), c(32)) * self.offset
    }

    fn p(&self, v: u32) -> glam::Vec3 {
        glam::Vec3::from(self.mesh.positions[v as usize])
    }

    /// Writes the binary little-endian PLY; `progress` gets the triangles written so far.
    pub fn write_ply(&self, w: &mut dyn Write, progress: &(dyn Fn(u64) + Sync)) -> std::io::Result<()> {
        let c = self.counts();
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment tessera-bench subdivide: {} levels\n\
             element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
             element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            self.n.trailing_zeros(),
            c.vertices,
            c.triangles
        )?;
        let put = |out: &mut Vec<u8>, p: glam::Vec3| {
            for x in p.to_array() {
                out.extend_from_slice(&x.to_le_bytes());
            }
        };
        let n = self.n;
        // Input vertices, as they are.
        for chunk in self.mesh.positions.chunks(1 << 16) {
            let mut out = Vec::with_capacity(chunk.len() * 12);
            chunk.iter().for_each(|&p| put(&mut out, p.into()));
            w.write_all(&out)?;
        }
        // Edge points, from each edge's lower end.
        let base = self.edge_base();
        for (block, edges) in self.edges.chunks(1 << 14).enumerate() {
            let out: Vec<u8> = edges
                .par_iter()
                .enumerate()
                .flat_map_iter(|(k, &[a, b])| {
                    let e = (block << 14) + k;
                    let mut out = Vec::with_capacity(12 * (n as usize - 1));
                    for s in 1..n {
                        let id = base + e as u64 * (n as u64 - 1) + (s as u64 - 1);
                        put(&mut out, self.p(a).lerp(self.p(b), s as f32 / n as f32) + self.jitter(id));
                    }
                    out
                })
                .collect();
            w.write_all(&out)?;
        }
        // Triangle points, in inner_index order.
        const BLOCK: usize = 1 << 12;
        let faces = self.mesh.triangles.len();
        for start in (0..faces).step_by(BLOCK) {
            let out: Vec<u8> = (start..faces.min(start + BLOCK))
                .into_par_iter()
                .flat_map_iter(|f| {
                    let [a, b, c] = self.mesh.triangles[f].map(|v| self.p(v));
                    let mut out = Vec::with_capacity(12 * self.inner() as usize);
                    for j in 1..n {
                        for i in 1..n - j {
                            let id = self.point(f, i, j);
                            let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
                            put(&mut out, a * (1.0 - u - v) + b * u + c * v + self.jitter(id));
                        }
                    }
                    out
                })
                .collect();
            w.write_all(&out)?;
        }
        // Triangles: per input triangle its n² pieces, upward then downward in each row.
        let mut done = 0u64;
        for start in (0..faces).step_by(BLOCK) {
            let out: Vec<u8> = (start..faces.min(start + BLOCK))
                .into_par_iter()
                .flat_map_iter(|f| {
                    let mut out = Vec::with_capacity(13 * (n * n) as usize);
                    let mut tri = |a: u64, b: u64, c: u64| {
                        out.push(3u8);
                        for v in [a, b, c] {
                            out.extend_from_slice(&(v as i32).to_le_bytes());
                        }
                    };
                    for j in 0..n {
                        for i in 0..n - j {
                            tri(self.point(f, i, j), self.point(f, i + 1, j), self.point(f, i, j + 1));
                            if i + j + 2 <= n {
                                tri(self.point(f, i + 1, j), self.point(f, i + 1, j + 1), self.point(f, i, j + 1));
                            }
                        }
                    }
                    out
                })
                .collect();
            w.write_all(&out)?;
            done += (faces.min(start + BLOCK) - start) as u64 * (n * n) as u64;
            progress(done);
        }
        Ok(())
    }
}

/// The fewest levels that give at least `triangles` from `input` triangles.
pub fn levels_for(input: u64, triangles: u64) -> u32 {
    let mut l = 0;
    while input.max(1) << (2 * l) < triangles && l < 10 {
        l += 1;
    }
    l
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetrahedron() -> codec::Mesh {
        codec::Mesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
            ..Default::default()
        }
    }

    fn subdivided(mesh: &codec::Mesh, levels: u32) -> codec::Mesh {
        let s = Subdivision::new(mesh, levels, 0.1).unwrap();
        let mut bytes = Vec::new();
        s.write_ply(&mut bytes, &|_| {}).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.ply");
        std::fs::write(&path, &bytes).unwrap();
        let out = codec::load_path(&path).unwrap();
        assert_eq!(out.triangles.len() as u64, s.counts().triangles);
        assert_eq!(out.positions.len() as u64, s.counts().vertices);
        out
    }

    /// Each directed edge's count, keyed (from, to).
    fn directed(m: &codec::Mesh) -> HashMap<(u32, u32), u32> {
        let mut d = HashMap::new();
        for t in &m.triangles {
            for k in 0..3 {
                *d.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        d
    }

    #[test]
    fn a_closed_oriented_mesh_stays_closed_and_oriented() {
        for levels in 0..4 {
            let out = subdivided(&tetrahedron(), levels);
            let n = 1u64 << levels;
            assert_eq!(out.triangles.len() as u64, 4 * n * n);
            // V + E (n-1) + F (n-1)(n-2)/2: Euler's V - E + F = 2 holds at every level.
            assert_eq!(out.positions.len() as u64, 4 + 6 * (n - 1) + 4 * (n - 1) * n.saturating_sub(2) / 2);
            let d = directed(&out);
            for (&(a, b), &c) in &d {
                assert_eq!(c, 1, "edge {a}-{b} used twice in one direction");
                assert_eq!(d.get(&(b, a)), Some(&1), "edge {a}-{b} has no opposite: a crack");
            }
        }
    }

    #[test]
    fn boundaries_get_finer_and_corners_stay() {
        let mesh = codec::load_path(&testkit::mesh_path("odedstein/cube_no_bottom.obj")).unwrap();
        let boundary = |m: &codec::Mesh| {
            let d = directed(m);
            d.keys().filter(|&&(a, b)| !d.contains_key(&(b, a))).count()
        };
        let out = subdivided(&mesh, 2);
        assert_eq!(boundary(&out), 4 * boundary(&mesh));
        assert_eq!(&out.positions[..mesh.positions.len()], &mesh.positions[..]);
        // New points stay near the surface: within the offset of the input's box.
        let (lo, hi) = codec::mesh::bounding_box(&mesh.positions).unwrap();
        let slack = 0.1 * 2.0;
        assert!(out.positions.iter().all(|p| (0..3).all(|a| p[a] >= lo[a] - slack && p[a] <= hi[a] + slack)));
    }

    #[test]
    fn levels_reach_the_target() {
        assert_eq!(levels_for(871_414, 200_000_000), 4);
        assert_eq!(levels_for(100, 100), 0);
        assert_eq!(levels_for(100, 101), 1);
    }
}
