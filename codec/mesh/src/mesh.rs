//! The indexed triangle mesh every part of Tessera passes around, and its quantization.

use thiserror::Error;

/// An indexed triangle mesh: positions and counter-clockwise triangles, and optionally a
/// colour and a normal per vertex.
///
/// Nothing is assumed about the topology: triangles may share vertices in non-manifold
/// ways, repeat, or be degenerate, and vertices may be unused.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// RGBA per vertex (alpha 255 where the file has none), or empty.
    pub colors: Vec<[u8; 4]>,
    /// A normal per vertex (of any length; it is a direction), or empty.
    pub normals: Vec<[f32; 3]>,
}

/// Why a mesh cannot be encoded.
#[derive(Debug, Error, PartialEq)]
pub enum MeshError {
    #[error("triangle {triangle} uses vertex {index}, but the mesh has only {vertices} vertices")]
    IndexOutOfRange { triangle: usize, index: u32, vertices: usize },
    #[error("vertex {vertex} has a non-finite coordinate {value:?}")]
    NonFinite { vertex: usize, value: [f32; 3] },
    #[error("the mesh has {0} vertices; at most 2^31 are supported")]
    TooManyVertices(usize),
    #[error("the mesh has {0} triangles; at most 2^31 are supported")]
    TooManyTriangles(usize),
    #[error("quantization must be 8 to 24 bits per coordinate, not {0}")]
    QuantBits(u8),
    #[error("normal quantization must be 4 to 16 bits per octahedral coordinate, not {0}")]
    NormalBits(u8),
    #[error("the mesh has {found} {what} for {vertices} vertices")]
    AttributeCount { what: &'static str, found: usize, vertices: usize },
    #[error("vertex {vertex} has a non-finite normal {value:?}")]
    NonFiniteNormal { vertex: usize, value: [f32; 3] },
}

impl Mesh {
    /// A mesh without colours or normals.
    pub fn new(positions: Vec<[f32; 3]>, triangles: Vec<[u32; 3]>) -> Mesh {
        Mesh { positions, triangles, colors: Vec::new(), normals: Vec::new() }
    }

    /// Checks that indices are in range, that every vertex a triangle uses is finite (its
    /// normal too), and that each attribute has a value per vertex. Unused vertices may hold
    /// anything: they are not encoded.
    pub fn validate(&self) -> Result<(), MeshError> {
        for (what, found) in [("colours", self.colors.len()), ("normals", self.normals.len())] {
            if found != 0 && found != self.positions.len() {
                return Err(MeshError::AttributeCount { what, found, vertices: self.positions.len() });
            }
        }
        if self.positions.len() > (1 << 31) {
            return Err(MeshError::TooManyVertices(self.positions.len()));
        }
        if self.triangles.len() > (1 << 31) {
            return Err(MeshError::TooManyTriangles(self.triangles.len()));
        }
        let n = self.positions.len();
        for (t, tri) in self.triangles.iter().enumerate() {
            for &i in tri {
                let Some(p) = self.positions.get(i as usize) else {
                    return Err(MeshError::IndexOutOfRange { triangle: t, index: i, vertices: n });
                };
                if !p.iter().all(|c| c.is_finite()) {
                    return Err(MeshError::NonFinite { vertex: i as usize, value: *p });
                }
                if let Some(n) = self.normals.get(i as usize).filter(|n| !n.iter().all(|c| c.is_finite())) {
                    return Err(MeshError::NonFiniteNormal { vertex: i as usize, value: *n });
                }
            }
        }
        Ok(())
    }

    /// Marks the vertices some triangle uses.
    pub fn used_vertices(&self) -> Vec<bool> {
        let mut used = vec![false; self.positions.len()];
        for tri in &self.triangles {
            for &i in tri {
                used[i as usize] = true;
            }
        }
        used
    }

    /// Connected components of the used vertices, vertices being joined by sharing a
    /// triangle. Indices must be in range.
    pub fn components(&self) -> usize {
        let mut sets = Sets::new(self.positions.len());
        for t in &self.triangles {
            sets.join(t[0], t[1]);
            sets.join(t[0], t[2]);
        }
        sets.count(&self.used_vertices())
    }
}

/// Disjoint sets of `0..n` (union-find with path halving): a mesh's components, and a chunked
/// file's, whose slots are joined chunk by chunk.
pub struct Sets {
    parent: Vec<u32>,
}

impl Sets {
    pub fn new(n: usize) -> Sets {
        Sets { parent: (0..n as u32).collect() }
    }

    fn root(&mut self, mut v: u32) -> u32 {
        while self.parent[v as usize] != v {
            self.parent[v as usize] = self.parent[self.parent[v as usize] as usize];
            v = self.parent[v as usize];
        }
        v
    }

    /// Puts `a` and `b` in one set.
    pub fn join(&mut self, a: u32, b: u32) {
        let (a, b) = (self.root(a), self.root(b));
        if a != b {
            self.parent[a.max(b) as usize] = a.min(b);
        }
    }

    /// The sets holding an element whose `used` is true.
    pub fn count(&mut self, used: &[bool]) -> usize {
        let mut counted = vec![false; self.parent.len()];
        let mut sets = 0;
        for v in 0..self.parent.len() as u32 {
            if used[v as usize] {
                let r = self.root(v) as usize;
                sets += !counted[r] as usize;
                counted[r] = true;
            }
        }
        sets
    }
}

/// The axis-aligned bounding box of `points`, as (min, max) corners; `None` when there are
/// none (or when every x is NaN). NaN coordinates are skipped (`f32::min` ignores them):
/// callers that must refuse them check first.
pub fn bounding_box<'a>(points: impl IntoIterator<Item = &'a [f32; 3]>) -> Option<([f32; 3], [f32; 3])> {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo[0] <= hi[0]).then_some((lo, hi))
}

/// Uniform quantization of positions over the bounding box of the used vertices.
///
/// One step size serves all three axes (the largest extent over `2^bits - 1` steps), as in
/// Draco, so the error is isotropic: at most half a step per coordinate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quantization {
    pub bits: u8,
    pub min: [f32; 3],
    pub step: f32,
}

impl Quantization {
    pub const DEFAULT_BITS: u8 = 16;

    /// Fits a quantization to the vertices flagged in `used` (all vertices if `None`).
    pub fn fit(positions: &[[f32; 3]], used: Option<&[bool]>, bits: u8) -> Result<Self, MeshError> {
        if !(8..=24).contains(&bits) {
            return Err(MeshError::QuantBits(bits));
        }
        let used = positions.iter().enumerate().filter(|(i, _)| used.is_none_or(|u| u[*i])).map(|(_, p)| p);
        let Some((lo, hi)) = bounding_box(used) else {
            return Ok(Quantization { bits, min: [0.0; 3], step: 1.0 });
        };
        let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0f32, f32::max);
        let levels = ((1u32 << bits) - 1) as f32;
        let step = if extent > 0.0 { extent / levels } else { 1.0 };
        Ok(Quantization { bits, min: lo, step })
    }

    pub fn max_level(&self) -> u32 {
        (1u32 << self.bits) - 1
    }

    #[inline]
    pub fn quantize(&self, p: [f32; 3]) -> [u32; 3] {
        let max = self.max_level() as f32;
        let q = |a: usize| (((p[a] - self.min[a]) / self.step).round().clamp(0.0, max)) as u32;
        [q(0), q(1), q(2)]
    }

    #[inline]
    pub fn dequantize(&self, q: [u32; 3]) -> [f32; 3] {
        [
            self.min[0] + q[0] as f32 * self.step,
            self.min[1] + q[1] as f32 * self.step,
            self.min[2] + q[2] as f32 * self.step,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_names_the_problem() {
        let mut m = Mesh::new(vec![[0.0; 3]; 3], vec![[0, 1, 3]]);
        assert_eq!(m.validate(), Err(MeshError::IndexOutOfRange { triangle: 0, index: 3, vertices: 3 }));
        m.triangles[0] = [0, 1, 2];
        m.positions[1][2] = f32::NAN;
        assert!(matches!(m.validate(), Err(MeshError::NonFinite { vertex: 1, .. })));
        // An unused NaN vertex is fine.
        m.positions.push([f32::NAN; 3]);
        m.positions[1][2] = 0.0;
        assert_eq!(m.validate(), Ok(()));
    }

    #[test]
    fn quantization_error_is_half_a_step() {
        let pts: Vec<[f32; 3]> = (0..1000)
            .map(|i| {
                let f = i as f32;
                [f.sin() * 3.0, f.cos() * 0.5, (f * 0.37).sin() - 2.0]
            })
            .collect();
        for bits in [8u8, 14, 16, 24] {
            let q = Quantization::fit(&pts, None, bits).unwrap();
            for p in &pts {
                let r = q.dequantize(q.quantize(*p));
                for a in 0..3 {
                    assert!((r[a] - p[a]).abs() <= q.step * 0.5 + 1e-5 * (1.0 + p[a].abs()));
                }
            }
        }
        assert!(Quantization::fit(&pts, None, 7).is_err());
        assert!(Quantization::fit(&pts, None, 25).is_err());
    }
}
