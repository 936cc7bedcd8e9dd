//! The progressive mesh a build makes and the adapters refine: vertices and faces in the
//! order of their FVIDs, the split tree over them, and each split's refinement criteria.

/// "None" in the index buffers of this module (no split, no parent node).
pub const NONE: u32 = u32::MAX;

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
    /// Per FVID: the unit vertex normal at the finest level (area-weighted face normals),
    /// zero where the faces have no area. A vertex keeps its normal at every level (half-edge
    /// collapses), so this is the normal an active vertex carries at runtime.
    pub normals: Vec<[f32; 3]>,
    /// Per split (parallel to [`Self::splits`]): the refinement criteria of the vertex the split
    /// refines, monotone over the split tree (see [`Criteria`]).
    pub criteria: Vec<Criteria>,
}

/// The refinement criteria of one split (section 4, Table 1, and section 4.2.3), describing
/// the *region* of the vertex `v` that the split refines: the finest vertices that `v` stands
/// for before the split (its subtree in the collapse forest), and their faces.
///
/// The sphere's centre and the cone's axis are the position and normal of `v` (the split's
/// FVID), which the adaptation has at hand. All values are monotone: a split's values are at
/// least those of the splits of its two children (the left child keeps `v`'s FVID, the right
/// one is `v_u`), with the nesting made explicit (a parent sphere contains its children's
/// spheres, a parent cone its children's cones), so a view-dependent test built from them
/// never asks to split a vertex whose parent it judged fine (section 3.2, local monotonicity).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Criteria {
    /// `sin(alpha)` of the normal cone around `v`'s normal that contains the normals of every
    /// finest face incident to the region (section 4, \[Hop97\]); `alpha` is capped at 90 degrees
    /// (then 1.0: never back-facing), also where a normal is undefined (zero area).
    pub sin_alpha: f32,
    /// Geometric error: the greatest distance of a finest vertex of the region from `v`'s
    /// position, a Hausdorff-type bound (every finest vertex lies within it of the vertex that
    /// stands for it). The quadric error is not used: it is zero for the collapses of planar
    /// regions, also for the last ones that remove the faces altogether.
    pub geometric_error: f32,
    /// Attribute (normal) error: a bound on the chord `|n_w - n_v|` between the unit normal of
    /// any finest vertex `w` of the region and `v`'s normal (0 to 2, dimensionless; a view
    /// converts it into a length, see [`Viewpoint::attribute_scale`](crate::adapt::Viewpoint::attribute_scale)).
    pub attribute_error: f32,
    /// Radius of the bounding sphere around `v`'s position containing the region's finest
    /// vertices and the children's spheres (for frustum, back-face and screen-space tests).
    pub radius: f32,
}

/// The split tree (the binary tree pointers of Table 1 and section 4.2.1), derived from the
/// split order: splitting `v` replaces the node of `v` by a left child (FVID `v`) and a right
/// child (FVID `v_u`). A *node* is coded `2 * s + side` for child `side` (0 left, 1 right) of
/// split `s`, or [`NONE`] for a root (a base vertex).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SplitTree {
    /// Per split: the splits of its left and right child ([`NONE`] where that child is a leaf).
    pub children: Vec<[u32; 2]>,
    /// Per split: the node it splits.
    pub parent: Vec<u32>,
    /// Per base vertex (parallel to [`ProgressiveMesh::base_vertices`]): its first split.
    pub roots: Vec<u32>,
}

impl SplitTree {
    /// Derives the tree from the splits and base vertices (linear time, a scratch buffer per FVID,
    /// sized by the FVIDs they name, so that it needs no positions).
    pub fn new(pm: &ProgressiveMesh) -> Self {
        let n = pm.positions.len().max(
            pm.base_vertices
                .iter()
                .chain(pm.splits.iter().flat_map(|s| [&s.v, &s.v_u]))
                .map(|&f| f as usize + 1)
                .max()
                .unwrap_or(0),
        );
        // The node each FVID's vertex currently is; roots are coded as `NONE - 1 - base index`.
        let mut node_of = vec![NONE; n];
        for (b, &f) in pm.base_vertices.iter().enumerate() {
            node_of[f as usize] = NONE - 1 - b as u32;
        }
        let mut t = SplitTree {
            children: vec![[NONE; 2]; pm.splits.len()],
            parent: vec![NONE; pm.splits.len()],
            roots: vec![NONE; pm.base_vertices.len()],
        };
        let root_limit = NONE - 1 - pm.base_vertices.len() as u32;
        for (s, split) in pm.splits.iter().enumerate() {
            let node = node_of[split.v as usize];
            if node == NONE {
                continue; // malformed: the vertex does not exist yet
            }
            if node > root_limit {
                t.roots[(NONE - 1 - node) as usize] = s as u32;
            } else {
                t.children[(node >> 1) as usize][(node & 1) as usize] = s as u32;
                t.parent[s] = node;
            }
            node_of[split.v as usize] = 2 * s as u32;
            node_of[split.v_u as usize] = 2 * s as u32 + 1;
        }
        t
    }
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
    /// Up to two are held inline: a heap block per split cost a large model's builder 24
    /// bytes an operation more (10% of its peak) and an allocation each.
    pub faces: SplitFaces,
}

/// The faces of a [`Split`]: two inline, more on the heap.
pub type SplitFaces = smallvec::SmallVec<[[u32; 3]; 2]>;
