//! Reference refinement of a progressive mesh (sections 3.2 and 5.5): a sequential,
//! CPU-side model of the paper's GPU adaptation, used to check the builder.
//!
//! Faces are kept as finest-level FVID triples, as the paper's face buffer keeps them next to
//! the index buffer (Table 2), and mapped to active vertices when asked for, which is the
//! paper's index update: the active vertex for FVID `f` is the active vertex with the greatest
//! FVID `<= f`. Splits need nothing from their neighbourhood; they only add `v_u` to the active
//! set and append their faces.

use std::collections::BTreeSet;

use crate::progressive::ProgressiveMesh;

/// Applies the splits of a progressive mesh one at a time, from the base mesh up.
///
/// It trusts the mesh to come from [`super::build`](fn@super::build): a malformed one gives meaningless faces
/// (an FVID below every active vertex maps to `u32::MAX`) but never panics.
#[derive(Clone, Debug)]
pub struct Refiner<'a> {
    pm: &'a ProgressiveMesh,
    /// Active vertices by FVID; ordered so the FVID rule is a predecessor search.
    active: BTreeSet<u32>,
    /// Current faces as finest-level FVID triples.
    faces: Vec<[u32; 3]>,
    applied: usize,
}

impl<'a> Refiner<'a> {
    /// Starts at the base mesh.
    pub fn new(pm: &'a ProgressiveMesh) -> Self {
        Self { pm, active: pm.base_vertices.iter().copied().collect(), faces: pm.base_faces.clone(), applied: 0 }
    }

    /// How many splits have been applied.
    pub fn applied(&self) -> usize {
        self.applied
    }

    /// Applies the next split; `false` once all are applied.
    pub fn split_next(&mut self) -> bool {
        let Some(split) = self.pm.splits.get(self.applied) else {
            return false;
        };
        self.active.insert(split.v_u);
        self.faces.extend_from_slice(&split.faces);
        self.applied += 1;
        true
    }

    /// Whether the vertex with this FVID is active at the current level.
    pub fn is_active(&self, fvid: u32) -> bool {
        self.active.contains(&fvid)
    }

    /// The active vertex that finest-level vertex `fvid` is collapsed into at the current
    /// level: the active vertex with the greatest FVID `<= fvid`.
    pub fn active_vertex(&self, fvid: u32) -> u32 {
        self.active.range(..=fvid).next_back().copied().unwrap_or(u32::MAX)
    }

    /// The current faces over the active vertices, as FVIDs.
    pub fn current_faces(&self) -> Vec<[u32; 3]> {
        self.faces.iter().map(|t| t.map(|f| self.active_vertex(f))).collect()
    }
}

/// Refines from the base mesh through every split and returns the faces as FVID triples:
/// for a mesh from [`super::build`](fn@super::build), the input triangles renumbered by
/// [`ProgressiveMesh::fvid_of_input`].
pub fn refine_all(pm: &ProgressiveMesh) -> Vec<[u32; 3]> {
    let mut r = Refiner::new(pm);
    while r.split_next() {}
    r.current_faces()
}
