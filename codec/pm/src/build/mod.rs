//! The progressive mesh builder: quadric-error edge collapses down to the base mesh, then the
//! FVID numbering of section 3.2 (Figure 4) and the splits of section 4 (connectivity only).
//!
//! Decisions where the paper is silent:
//!
//! * **Half-edge collapses.** `v_u` collapses into `v_t`, which keeps its position, so no
//!   position has to be solved for and the per-FVID positions are the input's. Position and
//!   normal deltas are coded by [`super::format`], which also makes the `v_t`/`v_u` swap of
//!   section 4.2.4 a per-operation coding choice (why it cannot renumber here: see there).
//! * **Cost.** Garland-Heckbert quadrics: every face adds its plane weighted by its area to its
//!   vertices; the cost of collapsing `u` into `t` is `(Q_u + Q_t)(p_t)`, and an edge offers
//!   the cheaper of its two directions. Edges are taken greedily, cheapest first, from a
//!   4-ary heap with lazy invalidation: an entry records when its vertices last changed (absorbed
//!   another vertex) and is stale once either changed again or died. The local
//!   error monotonicity of section 3.2 is made explicit in the refinement criteria
//!   ([`super::Criteria`]).
//! * **No collapse is refused.** The paper simplifies "until no faces are left", so there are
//!   no link-condition or fold-over checks: whatever the topology, collapses run until no
//!   face holds two distinct vertices. Vertices left without a common face are not merged
//!   (that split would create no face), so a component ends as a handful of base vertices.
//! * **Which faces a collapse removes.** Exactly the live faces holding both `u` and `t`;
//!   they are the faces the split creates. Every other face of `u` is moved to `t`. So a
//!   face that was not degenerate in the input never becomes degenerate while alive, an input
//!   face like `[a, a, b]` goes with the collapse joining `a` and `b`, and `[a, a, a]` is
//!   never removed: it ends in the base mesh.
//! * **Faces per operation.** A `.dpm` operation adds at most [`MAX_OP_FACES`](super::format::MAX_OP_FACES) faces, and a
//!   collapse removes every face of its edge at once: a mesh with an edge of more faces is
//!   refused before simplifying ([`check_op_faces`], naming the edge's vertices and the
//!   count), and a collapse whose edge gathered more during the simplification is refused
//!   right after it, before the numbering and the encoding. A vertex of any number of faces
//!   builds (a fan's edges have two each).
//! * **Duplicates are kept.** Faces that become equal (or opposite) stay separate faces;
//!   each is removed by the collapse that degenerates it, so the splits recreate the input
//!   multiset exactly, with orientation.
//! * **Tree order.** A vertex's children in the forest are the vertices it absorbed, in
//!   chronological order (the latest collapse is the root, its right child the last absorbed
//!   vertex), so numbering leaves left to right is a pre-order walk of that tree. Roots are
//!   numbered in ascending input index.
//!
//! * **Chunks.** A model of more than [`BuildOptions::chunk_faces`] faces is simplified in
//!   spatial chunks with their borders locked (`simplify_chunked`), so the simplifier's
//!   memory follows the chunk: greedy within a chunk, one valid collapse sequence in all.
//!   Sibling chunks run in parallel; a vertex is locked when it has an input face outside
//!   the chunk, which no thread changes, so the result does not depend on the threads.
//!
//! The refinement criteria ([`Criteria`](super::Criteria), section 4 and 4.2.3) are computed after the
//! numbering, bottom-up over the split tree ([`SplitTree`](super::SplitTree), in the reverse of
//! its pre-order), in `f64`:
//!
//! * a leaf (a finest vertex) has radius and errors zero and the normal cone of its incident
//!   faces around its own normal; faces without area have no normal and are left out;
//! * a split's region is the union of its children's: the left child has the same centre and
//!   normal, the right child (`v_u`) is at distance `d` with normal `n_u`, so the cone angle
//!   is `max(a_l, angle(n, n_u) + a_u)` and the attribute error `max(e_l, |n - n_u| + e_u)`.
//!   These are nesting bounds, so monotone by construction.
//! * the geometric error is computed during the simplification: the farthest finest vertex
//!   of the region from `v` (the same nesting bound), raised to the maximum of the tracked
//!   errors of all vertices around the collapse, as section 3.2 prescribes against
//!   fold-overs; so it can exceed the region's radius, and is still at least both
//!   children's (`v_t` and `v_u` are among those vertices). Being at least the region's
//!   farthest vertex from `v`, it is also the region's bounding radius.
//!   It is raised, where needed, to `d + r_u` (and the left child's radius), so that the
//!   children's bounding spheres nest in the parent's: a child's error may exceed its region
//!   (raised to its neighbours'), and the runtime tests spheres (found on a random soup whose
//!   frame-to-frame and from-base adaptations differed).
//! * the cone angle and the nesting radius get a relative slack of `1e-5` (plus `1e-5` rad
//!   for the angle) per level, so the runtime tests, which recompute the nesting in `f32`,
//!   stay monotone.
//!
//! **Hubs: linear time whatever the valence.** A collapse costs time in the number of faces
//! around `u` and `t`: it moves `u`'s faces, reads the errors around both, and offers every
//! edge of `t` again. Around a vertex of very high valence (a fan of 200k triangles, a large
//! polygon fan-triangulated) that is quadratic. A vertex with more than [`HUB_FACES`] live
//! faces becomes a *hub* (for good): an edge between a hub and another vertex always
//! collapses the other vertex into the hub (between two hubs, the one with fewer faces into
//! the other), so a hub's faces never move; when a hub absorbs a vertex only the edges to its
//! new neighbours are offered, and its other edges keep their costs (computed with the hub's
//! quadric of when they were offered: an approximation of the greedy order, only around
//! hubs); the errors around a hub are not read but bounded, by the greatest error of any
//! vertex that was ever its neighbour and of any hub (`Simplifier::hub_bound`), which
//! keeps the errors monotone bounds; and its list of faces is compacted when most of it is
//! dead. Then every collapse costs time in the faces of its non-hub vertices, at most
//! `HUB_FACES` each ([`BuildStats::work`] counts it). No mesh in `../shared/meshes` has a hub
//! (the most faces a vertex reaches there is 352, on the planar `alligator.obj`, whose zero
//! quadrics tie every cost), so their progressive meshes are the ones of the plain greedy
//! order.
//!
//! One algorithm a file:
//!
//! | file | what |
//! |---|---|
//! | `pipeline.rs` | the entry points, the input checks, and the steps below in order |
//! | `options.rs` | what the steps share: options, statistics, the error, hub and chunk sizes |
//! | `simplify.rs` | the quadric simplifier: quadrics, the heap of candidate collapses, hubs, the collapse loop and its log |
//! | `chunks.rs` | the kd-tree of chunks, simplified with locked borders, siblings in parallel |
//! | `numbering.rs` | the FVID numbering and the splits |
//! | `criteria.rs` | the refinement criteria, bottom-up over the split tree |
//! | `vec3.rs` | the `f64` 3-vector operations the others share |

mod chunks;
mod criteria;
mod numbering;
mod options;
mod pipeline;
mod simplify;
mod vec3;

pub use options::{BuildOptions, BuildStats, PmError, CHUNK_FACES, HUB_FACES};
pub use pipeline::{build, build_owned, build_with_options, build_with_progress, build_with_stats, check_op_faces};
