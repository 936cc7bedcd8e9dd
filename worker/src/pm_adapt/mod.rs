//! View-dependent adaptation of a dependency-free progressive mesh on the GPU, straight from
//! the `.dpm`'s compressed operations: the stages of Algorithms 1 to 5 of E. Derzapf and M. Guthe,
//! "Dependency-Free Parallel Progressive Meshes", Computer Graphics Forum 31(8), 2012, as
//! WGSL compute pipelines (`worker/src/pm_adapt/shaders/*.wgsl`, one file per stage, `common.wgsl` prepended to
//! each but the generic scan, the operation decoder `decode.wgsl` to the reorganisation),
//! driven pass by pass from here. It keeps the state of [`codec::pm::DpmAdapter`] and reaches
//! the states of the CPU reference [`codec::pm::Adapter`]: same decisions, same triangle set
//! after every pass (tested in `worker/tests/pm_gpu.rs`).
//!
//! It runs on a [`Gpu`](crate::gpu::Gpu) and hands the renderer the adapted mesh as an
//! [`AdaptedMesh`](crate::render::AdaptedMesh) ([`GpuAdapter::mesh`]); it knows nothing else
//! of the renderer. `adapter` holds the [`GpuAdapter`] and its frame-level calls, `buffers`
//! the records it shares with the WGSL (the structs' twins) and its `n_alloc`-sized buffers,
//! `pipelines` the stages (each laid out from its WGSL's own bindings), `decoder` the
//! operation decoder's tables, `pass` one adaptation pass, `budget` and `tuning` the
//! adapter's memory arithmetic and setters over its `settings`, `limits` the fixed limits and
//! defaults, and `error` the [`AdaptError`].
//!
//! What stays in graphics memory for a model is its compressed operations (the OPER section
//! as it is in the file), the distinct Huffman tables, 326 values and a few parameters: 1.01x
//! the dragon's `.dpm` (4.34 MB for 4.29 MB; it was 45.4 MB of decoded records, faces and
//! points, 10.6x). Everything else follows the adapted mesh.
//!
//! One [`GpuAdapter::adapt`] pass is two submissions:
//!
//! 1. state update (Algorithm 1), collapses (Algorithm 2, in place), and the work-efficient
//!    scans of the vertex and face counts; the totals, the collapse counters and the first
//!    decoding error of the pass before are then read back (48 bytes): the host needs them to
//!    size the buffers (the paper's `n_alloc` policy) and to size the remaining dispatches;
//! 2. vertex reorganisation (Algorithm 3) into the other of two vertex buffer sets, in which a
//!    splitting vertex decodes its operation (children, `v_u`'s position and normal, faces)
//!    and its children's operations up to their face counts (their split caches), split
//!    compaction, splits with binary search (Algorithm 4), index update (Algorithm 5) and the
//!    in-place face compaction (section 5.6).
//!
//! An all-levels pass ([`Levels::All`](codec::pm::Levels::All), the default on hardware; see `codec::pm::Adapter::pass_all_levels`)
//! replaces the state update and collapses by `mark` (the undone splits' ranges, the
//! vertices that split, listed), a read-back of their number, `count` (each listed vertex's
//! leaves and faces down its subtree, `descent.wgsl`), the scan of the ranges and `regions`
//! (the collapsing regions and the vertices carrying their operations); and the split
//! decoding and splits by `descend` (the same descents, writing the leaves and faces) and
//! `index_new` (the new faces' indices by binary search). Reorganisation gives a region's
//! first vertex the region's operation.
//!
//! The adapted mesh stays on the GPU between passes (temporal coherence). It is drawn straight
//! from these buffers: the face index buffer is the draw's index buffer, and the vertex shader
//! pulls each active vertex's position and normal (see `vs_pulled` in `worker/src/render.wgsl`),
//! so rendering reads nothing back.
//!
//! Where this differs from the paper:
//!
//! * A vertex carries its creator's operation (the split whose `v_u` is its FVID) with that
//!   operation's context, so that a collapse knows the operation it becomes without a static
//!   tree or a decode from the root; see [`codec::pm::DpmAdapter`] for why this covers every
//!   collapse. The split cache holds the vertex's operation's criteria and face count, decoded
//!   when the vertex is made; the collapse cache is the creator's criteria.
//! * Operations are decoded on demand per split, in the reorganisation: a pass splits a vertex
//!   once, and its children's criteria are all the next pass needs, so a split costs one full
//!   decode and two up to the face count, and a pass decodes nothing where nothing splits. A
//!   wavefront over tree depths (decoding from the roots down each pass, contexts flowing
//!   down) would redo every active vertex's ancestors each pass, 15.6 levels on average for
//!   the dragon (29 at most); it was not built.
//! * Splits write `v` and `v_u` during reorganisation, so that the new FVID buffer is complete
//!   before the split stage binary-searches it; the split stage gives the faces their indices.
//! * Faces carry the address of the split that created them (4 bytes per face): the collapse
//!   removes exactly those, as in the CPU reference (inputs may hold faces that are degenerate
//!   at every level).
//! * The split compaction and the face compaction use atomic cursors instead of scans: the
//!   order they produce does not matter (face slots come from the face prefix sum, and the
//!   face order of the adapted mesh is free), so the triangle *set*, not the face order, is
//!   what equals the CPU reference.

mod adapter;
mod budget;
pub(crate) mod buffers;
pub mod decoder;
mod error;
pub(crate) mod limits;
mod nodes;
pub mod occlusion;
mod pass;
pub(crate) mod pipelines;
mod settings;
mod tuning;

pub use adapter::{GpuAdapter, OutOfCore};
pub use error::AdaptError;
pub use limits::{
    pool_bytes, DEEP_DESCENT, DEEP_PASSES, DEFAULT_N_ALLOC, DEFAULT_POOL_SHARE, MAX_SCRATCH_BYTES, MAX_STACK_BYTES,
    SOFTWARE_DESCENT_SLOTS, SOFTWARE_ROUND_STEPS,
};
