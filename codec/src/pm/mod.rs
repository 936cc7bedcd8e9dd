//! Dependency-free progressive meshes (Derzapf & Guthe, "Dependency-Free Parallel
//! Progressive Meshes"): the builder and a reference refinement. This is the first slice of
//! the PM work; refinement criteria (normal cone, errors), attribute deltas, the binary tree
//! pointers of Table 1 and the arithmetic coding of section 4.2 are later slices.
//!
//! The mesh is simplified by edge collapses until no edge is left (section 3); the original
//! mesh comes back by applying the inverse vertex splits in reverse order. What makes the
//! splits free of neighbourhood dependencies (section 3.2) is that every split stores the
//! faces it creates with their vertex ids at the *finest* level, the FVIDs, and that the FVIDs
//! are numbered so that the vertex currently standing for any finest-level vertex is cheap to
//! find (Figure 4):
//!
//! * the collapse history is a forest of binary trees: a collapse of `v_u` into `v_t` makes a
//!   node whose left child is `v_t` and whose right child is `v_u`;
//! * the leaves (input vertices) are numbered left to right, and an inner node takes the FVID
//!   of its left child.
//!
//! Every active vertex then stands for a contiguous FVID range starting at its own FVID, so the
//! active vertex for a finest-level FVID `f` is the active vertex with the greatest FVID `<= f`.
//! [`refine::Refiner`] applies exactly this rule.
//!
//! Decisions where the paper is silent (details in [`build`]):
//!
//! * collapses are half-edge collapses ordered by quadric error, so positions need no solving
//!   and [`ProgressiveMesh::positions`] are simply the input positions;
//! * a collapse removes exactly the faces that contain both of its vertices; faces that were
//!   degenerate in the input (a repeated index) go with the collapse that joins two of their
//!   distinct vertices, and faces with one vertex repeated three times are never removed and
//!   end up in the base mesh;
//! * faces that become duplicates stay, each is removed by its own collapse;
//! * unused input vertices get no FVID ([`ProgressiveMesh::fvid_of_input`] is `u32::MAX`).

pub mod build;
pub mod refine;

pub use build::{build, PmError};
pub use refine::{refine_all, Refiner};

/// A progressive mesh: the base mesh and the splits that refine it back to the input.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ProgressiveMesh {
    /// FVIDs of the base (coarsest) vertices, ascending. Collapses run until no edge is left,
    /// and the last faces of a component vanish together with their edges, so a component
    /// ends as a handful of vertices (a tetrahedron as two).
    pub base_vertices: Vec<u32>,
    /// Faces of the base mesh as finest-level FVID triples (not base vertex ids), like the
    /// faces of a split: the active vertices they stand for follow from the FVID rule at any
    /// level. They are the input faces that never contain two distinct vertices.
    pub base_faces: Vec<[u32; 3]>,
    /// Splits in refinement order, coarse to fine.
    pub splits: Vec<Split>,
    /// Per FVID: the vertex position at the finest level.
    pub positions: Vec<[f32; 3]>,
    /// Per input vertex: its FVID, or `u32::MAX` if no triangle uses it.
    pub fvid_of_input: Vec<u32>,
}

/// One vertex split, the inverse of one half-edge collapse.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Split {
    /// FVID of the vertex that splits; it becomes `v_t` and keeps this FVID.
    pub v: u32,
    /// FVID of the new vertex `v_u`; always greater than `v` (it is in `v`'s right subtree).
    pub v_u: u32,
    /// The faces this split creates (the faces the collapse removed), as finest-level FVID
    /// triples in input orientation: at least one (an edge exists only while a face holds
    /// both vertices), two on a manifold interior edge, any number on non-manifold ones.
    pub faces: Vec<[u32; 3]>,
}
