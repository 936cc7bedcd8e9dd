//! [`Emitter`]: hands triangles to the caller, triangulating polygons and counting, with
//! positions from a [`PositionSource`].

use std::path::Path;

use crate::load::error::LoadError;
use crate::load::polygon::Triangulator;

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

/// Hands triangles to the caller's callback, triangulating polygons as `load_path` does
/// and counting what it hands out.
pub(super) struct Emitter<'e> {
    pub(super) path: &'e Path,
    pub(super) positions: &'e dyn PositionSource,
    pub(super) f: &'e mut dyn FnMut([u32; 3]) -> Result<(), LoadError>,
    pub(super) count: u64,
    /// Elements that are no triangles (OBJ points and lines), skipped.
    pub(super) ignored: u64,
    pub(super) triangulator: Triangulator,
    /// The current polygon's corners, filled by the format readers.
    pub(super) corners: Vec<u32>,
    pub(super) tris: Vec<[u32; 3]>,
    /// The polygon's corner positions.
    pub(super) local: Vec<[f32; 3]>,
}

impl<'e> Emitter<'e> {
    pub(super) fn new(
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
    pub(super) fn triangle(&mut self, t: [u32; 3]) -> Result<(), LoadError> {
        (self.f)(t)?;
        self.count += 1;
        Ok(())
    }

    /// The first corner of [`Self::corners`] that is not a vertex of `positions`.
    pub(super) fn missing_corner(&self) -> Option<u32> {
        self.corners.iter().copied().find(|&c| c as usize >= self.positions.count())
    }

    /// Triangulates [`Self::corners`] (at least three, every one a vertex of `positions`).
    pub(super) fn polygon(&mut self) -> Result<(), LoadError> {
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
