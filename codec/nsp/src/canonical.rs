//! Quantization over a cubic box and the canonical complex an `.nsp` file stores (the
//! lossless contract of the module docs).

use rustc_hash::FxHashMap as HashMap;

use crate::mesh::Mesh;

use super::error::NspError;

/// The axes' names, for messages.
pub const AXES: [&str; 3] = ["x", "y", "z"];

/// The cubic box: origin at the minimum corner of the points' bounding box, side the largest
/// extent (NSP.md 1.3: the minimum corner, not the centre, reproduces Table 1's cell counts).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cube {
    pub origin: [f64; 3],
    pub side: f64,
    /// Bits per coordinate.
    pub bits: u8,
}

impl Cube {
    /// The cube around `points`; `None` when there are none.
    pub fn fit<'a>(points: impl IntoIterator<Item = &'a [f32; 3]>, bits: u8) -> Option<Cube> {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        // Non-finite points are left out: they are unused vertices (a used one is refused).
        for p in points.into_iter().filter(|p| p.iter().all(|c| c.is_finite())) {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a] as f64);
                hi[a] = hi[a].max(p[a] as f64);
            }
        }
        if lo[0] > hi[0] {
            return None;
        }
        let side = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
        Some(Cube { origin: lo, side: if side > 0.0 { side } else { 1.0 }, bits })
    }

    /// Whether every point of the cube is a finite `f32` (what a decoder draws is inside it):
    /// its side is positive and its origin and far corner on each axis convert to finite
    /// `f32`s; otherwise which does not.
    pub fn check_f32(&self) -> Result<(), String> {
        let fits = |x: f64| x.is_finite() && (x as f32).is_finite();
        if !(self.side.is_finite() && self.side > 0.0) {
            return Err(format!("the cube's side is {}, not a positive number", num(self.side)));
        }
        for (origin, axis) in self.origin.iter().zip(AXES) {
            let (lo, hi) = (*origin, origin + self.side);
            if !(fits(lo) && fits(hi)) {
                return Err(format!(
                    "the cube's origin {} and side {} on {axis} do not fit f32",
                    num(lo),
                    num(self.side)
                ));
            }
        }
        Ok(())
    }

    /// `floor((x - origin) / side * 2^bits)`, clamped to the grid.
    #[inline]
    pub fn quantize(&self, p: [f32; 3]) -> [u32; 3] {
        let scale = (1u64 << self.bits) as f64 / self.side;
        let max = ((1u64 << self.bits) - 1) as f64;
        let q = |a: usize| ((p[a] as f64 - self.origin[a]) * scale).floor().clamp(0.0, max) as u32;
        [q(0), q(1), q(2)]
    }

    /// The world position of a point of the grid at `bits` precision given in grid units of
    /// the full precision (may be fractional: a cell centre).
    #[inline]
    pub fn world(&self, grid: [f64; 3]) -> [f32; 3] {
        let step = self.side / (1u64 << self.bits) as f64;
        [
            (self.origin[0] + grid[0] * step) as f32,
            (self.origin[1] + grid[1] * step) as f32,
            (self.origin[2] + grid[2] * step) as f32,
        ]
    }

    /// The canonical position of a full-precision grid point: the centre of its grid cell.
    pub fn position(&self, q: [u32; 3]) -> [f32; 3] {
        self.world([q[0] as f64 + 0.5, q[1] as f64 + 0.5, q[2] as f64 + 0.5])
    }
}

/// A number for a message: with an exponent where plain digits would run long.
pub fn num(x: f64) -> String {
    if x != 0.0 && x.is_finite() && !(1e-5..1e15).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// A top-simplex of the canonical complex: a triangle (oriented), an edge or a point, on
/// indices of [`Canonical::points`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Simplex {
    pub v: [u32; 3],
    /// 0 point, 1 edge, 2 triangle; `v[dim+1..]` are unused (zero).
    pub dim: u8,
}

impl Simplex {
    pub fn verts(&self) -> &[u32] {
        &self.v[..self.dim as usize + 1]
    }

    /// The vertex set, sorted, as a key (orientation forgotten).
    pub fn key(&self) -> [u32; 3] {
        let mut k = [u32::MAX; 3];
        k[..self.dim as usize + 1].copy_from_slice(self.verts());
        k[..self.dim as usize + 1].sort_unstable();
        k
    }
}

/// The canonical complex of a mesh at `bits` precision: distinct quantized positions, and the
/// top-simplices of the images of the input triangles (and of the unreferenced vertices) once
/// coincident positions are merged. A triangle keeps the orientation of its first occurrence
/// in the input; triangles are listed in order of first occurrence, then edges, then points.
#[derive(Clone, Debug, PartialEq)]
pub struct Canonical {
    pub cube: Cube,
    pub points: Vec<[u32; 3]>,
    pub simplices: Vec<Simplex>,
    /// Input triangles and vertices, before merging.
    pub input_triangles: u64,
    pub input_vertices: u64,
    /// The bounding box's extent per axis (the cube's side is the largest).
    pub cube_extent: [f64; 3],
}

impl Canonical {
    pub fn triangles(&self) -> usize {
        self.simplices.iter().filter(|s| s.dim == 2).count()
    }

    /// The canonical complex of `mesh` (every vertex, used or not, is a point of the model).
    pub fn of_mesh(mesh: &Mesh, bits: u8) -> Result<Canonical, NspError> {
        mesh.validate().map_err(|e| NspError::Input(e.to_string()))?;
        let cube = Cube::fit(&mesh.positions, bits).ok_or(NspError::Empty)?;
        cube.check_f32().map_err(|e| NspError::Input(format!("its positions do not fit an .nsp cube: {e}")))?;
        let mut cube_extent = [0f64; 3];
        for p in mesh.positions.iter().filter(|p| p.iter().all(|c| c.is_finite())) {
            for a in 0..3 {
                cube_extent[a] = cube_extent[a].max(p[a] as f64 - cube.origin[a]);
            }
        }
        let mut ids: HashMap<[u32; 3], u32> =
            HashMap::with_capacity_and_hasher(mesh.positions.len(), Default::default());
        let mut points = Vec::new();
        let remap: Vec<u32> = mesh
            .positions
            .iter()
            .map(|&p| {
                let q = cube.quantize(p);
                *ids.entry(q).or_insert_with(|| {
                    points.push(q);
                    points.len() as u32 - 1
                })
            })
            .collect();
        let tris = mesh
            .triangles
            .iter()
            .map(|t| Simplex { v: [remap[t[0] as usize], remap[t[1] as usize], remap[t[2] as usize]], dim: 2 });
        let simplices = top_simplices(points.len(), tris);
        Ok(Canonical {
            cube,
            points,
            simplices,
            input_triangles: mesh.triangles.len() as u64,
            input_vertices: mesh.positions.len() as u64,
            cube_extent,
        })
    }

    /// The canonical mesh: triangles only, at the grid cells' centres (edges and points,
    /// which a triangle mesh cannot hold, are counted by [`Canonical::simplices`]).
    pub fn to_mesh(&self) -> Mesh {
        Mesh {
            positions: self.points.iter().map(|&q| self.cube.position(q)).collect(),
            triangles: self.simplices.iter().filter(|s| s.dim == 2).map(|s| s.v).collect(),
            ..Default::default()
        }
    }
}

/// The top-simplices of the images of `simplices` (on point ids below `points`, every one of
/// which is a vertex of the complex): duplicates merged, the first occurrence's orientation
/// kept, degenerate images reduced to edges or points, faces of other simplices dropped.
/// Triangles come first in order of first occurrence, then edges, then points, both sorted.
pub(crate) fn top_simplices(points: usize, simplices: impl Iterator<Item = Simplex>) -> Vec<Simplex> {
    let mut seen_tri: rustc_hash::FxHashSet<[u32; 3]> = rustc_hash::FxHashSet::default();
    let mut out = Vec::new();
    let mut edges = Vec::new();
    for s in simplices {
        let s = reduce(s);
        match s.dim {
            2 if seen_tri.insert(s.key()) => out.push(s),
            2 => {}
            1 => edges.push([s.v[0], s.v[1]]),
            _ => {}
        }
    }
    let mut covered_edge: rustc_hash::FxHashSet<[u32; 2]> = rustc_hash::FxHashSet::default();
    let mut used = vec![false; points];
    for s in &out {
        let k = s.key();
        for (a, b) in [(0, 1), (0, 2), (1, 2)] {
            covered_edge.insert([k[a], k[b]]);
        }
        for &v in s.verts() {
            used[v as usize] = true;
        }
    }
    edges.sort_unstable();
    edges.dedup();
    for e in edges {
        if !covered_edge.contains(&e) {
            out.push(Simplex { v: [e[0], e[1], 0], dim: 1 });
            used[e[0] as usize] = true;
            used[e[1] as usize] = true;
        }
    }
    for (v, u) in used.iter().enumerate() {
        if !u {
            out.push(Simplex { v: [v as u32, 0, 0], dim: 0 });
        }
    }
    out
}

/// A simplex whose vertices may coincide, reduced to its image: a triangle (orientation
/// kept), an edge (sorted) or a point.
pub(crate) fn reduce(s: Simplex) -> Simplex {
    let t = s.v;
    match s.dim {
        2 if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] => s,
        2 => {
            let (a, b) = if t[0] != t[1] { (t[0], t[1]) } else { (t[1], t[2]) };
            edge_or_point(a, b)
        }
        1 => edge_or_point(t[0], t[1]),
        _ => Simplex { v: [t[0], 0, 0], dim: 0 },
    }
}

fn edge_or_point(a: u32, b: u32) -> Simplex {
    if a == b {
        Simplex { v: [a, 0, 0], dim: 0 }
    } else {
        Simplex { v: [a.min(b), a.max(b), 0], dim: 1 }
    }
}
