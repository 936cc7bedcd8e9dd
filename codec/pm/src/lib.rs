//! Dependency-free progressive meshes, after E. Derzapf and M. Guthe, "Dependency-Free
//! Parallel Progressive Meshes", Computer Graphics Forum 31(8), 2012 (the text is in
//! `../shared/papers/dependency-free-progressive-meshes.txt`): the builder with its refinement criteria (section 4, [`Criteria`]),
//! a sequential reference refinement ([`refine`]) and the CPU reference of the parallel
//! view-dependent adaptation of section 5 ([`adapt`]), and the `.dpm` file ([`mod@format`]): every
//! operation coded on its own with shared static Huffman tables per context (field, byte
//! significance and classes from what the decoder already knows, section 4.2), in tree order
//! with pointers, so that any operation decodes from its address alone. The binary tree
//! pointers of Table 1 are derived from the splits by [`SplitTree::new`]. The v_l/v_u swap of
//! section 4.2.4 is a per-operation choice of which child's operation is stored first, made by
//! coded size (the FVIDs stay as built; see [`mod@format`] for why).
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
//! Decisions where the paper is silent (details in [`build`](mod@build)):
//!
//! * collapses are half-edge collapses ordered by quadric error, so positions need no solving
//!   and [`ProgressiveMesh::positions`] are simply the input positions;
//! * a collapse removes exactly the faces that contain both of its vertices; faces that were
//!   degenerate in the input (a repeated index) go with the collapse that joins two of their
//!   distinct vertices, and faces with one vertex repeated three times are never removed and
//!   end up in the base mesh;
//! * faces that become duplicates stay, each is removed by its own collapse;
//! * unused input vertices get no FVID ([`ProgressiveMesh::fvid_of_input`] is `u32::MAX`).

// The paths the modules were written with when they were one crate (`crate::mesh`,
// `crate::pm::...`), kept for the crate's own files.
pub(crate) use crate as pm;
#[allow(unused_imports)]
pub(crate) use tessera_entropy::{container, huffman, rangecoder, Format, FormatError};
#[allow(unused_imports)]
pub(crate) use tessera_mesh::{csr, input, kind, load, mesh, view, LoadError, Mesh, MeshError, Quantization};

pub mod adapt;
mod all_levels;
pub mod build;
pub mod dpm_adapt;
pub mod format;
mod one_level;
pub mod ooc;
mod order;
mod pass_stats;
mod progressive;
pub mod refine;
mod trace;

pub use adapt::{Adapter, Levels, Viewpoint, DESCENT_BUDGET, LEVELS_PER_PASS};
pub use build::{
    build, build_owned, build_with_options, build_with_progress, build_with_stats, BuildOptions, BuildStats, PmError,
    CHUNK_FACES, HUB_FACES,
};
pub use dpm_adapt::DpmAdapter;
pub use format::{DpmError, EncodeOptions as DpmOptions};
pub use ooc::{CacheStats, NodeCache};
pub use pass_stats::PassStats;
pub use progressive::{Criteria, ProgressiveMesh, Split, SplitFaces, SplitTree, NONE};
pub use refine::{refine_all, Refiner};
pub use trace::trace;
