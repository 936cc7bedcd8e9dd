//! CPU reference of the parallel view-dependent adaptation (section 5, Algorithms 1 to 5), over
//! flat buffers as the GPU version will keep them (Table 2), rayon-parallel where the work is
//! independent.
//!
//! State (Table 2): the active vertices sorted by FVID, and per active vertex its *next split*
//! (the split that refines it, [`NONE`] at the finest level), its *node* in the split tree
//! (coded as in [`SplitTree`]; a right child `2 s + 1` can collapse, split `s` being its
//! collapse, with target `splits[s].v`), and the split/collapse cache: the criteria, centre and
//! normal of both operations, refreshed only when the vertex changes. Faces are kept twice, as
//! current vertex indices (the index buffer) and as finest FVIDs (the FVID buffer).
//!
//! One [`Adapter::adapt`] pass:
//!
//! 1. **Vertex state update** (Algorithm 1): each vertex asks for 2 (split), 1 (keep) or 0
//!    (collapse). A split if its next split's criteria ask for it; a collapse if it is a right
//!    child whose collapse's criteria do not ask for a split, its predecessor in the sorted
//!    buffer is its target `v_t` (else `v_t` split further) and its successor's target is not
//!    itself (else it split further).
//! 2. **Collapses** (Algorithm 2): a collapse whose target is marked for splitting is
//!    cancelled; otherwise the target takes the collapse's node and copies the collapsed
//!    vertex's collapse cache into its split cache. (A target never collapses in the same pass:
//!    its successor is the collapsing vertex, whose target it is.)
//! 3. **Memory management** (Algorithm 3): exclusive prefix sums of the vertex counts and the
//!    new face counts; the vertex buffers are rebuilt in FVID order, collapsed vertices dropped
//!    and each `v_u` placed right after its split vertex (its FVID follows `v`'s left range).
//! 4. **Splits** (Algorithm 4): the split vertices are compacted, each writes `v` and `v_u`, and
//!    each new face gets its indices: corners in `[v, v_u)` are `v`, corners in `v_u`'s range
//!    are `v_u`, any other one is found by binary search in the new sorted buffer (the active
//!    vertex with the greatest FVID `<=` the corner's).
//! 5. **Index update and compaction** (Algorithm 5, section 5.6): every old index moves to its
//!    vertex's new position, a collapsed vertex's to its target (the previous one), a split
//!    vertex's to `v_u` (the next one) when the corner's FVID reaches `v_u`; the faces created
//!    by a performed collapse are dropped, order kept, and the new faces appended.
//!
//! Every vertex the criteria ask to split is split in the pass it asks (no split waits for a
//! neighbour, section 3.2); a collapse joins two vertices only, so coarsening a region takes
//! one pass per level.
//!
//! Decisions where the paper is silent or that differ from it:
//!
//! * **Which faces a collapse removes.** The faces of the collapsed split, known by an owner
//!   buffer (split index per face) rather than by degeneracy: inputs may hold degenerate faces
//!   (`[a, a, b]`), which are degenerate at every level yet belong to the mesh once their split
//!   is done. For inputs without them the two rules agree.
//! * **View tests on the region's bounding sphere** (centre `v`, radius from [`Criteria`]), so
//!   that they are monotone over the split tree: with nested spheres and cones a child is
//!   never asked to split when its parent is not, and adaptation from any state converges to the
//!   same mesh, the cut just below the splits whose ancestors all ask to be split.
//!   - Frustum (section 5.1): nothing is culled; a sphere outside the frustum by a world
//!     distance `t` (greatest over the six planes, `0` inside) gets the distance
//!     `d' = d + c_LOD t`. The paper's `(c_LOD (max(|x|,|y|,|z|)/w - 1) + 1) d` is the same up
//!     to a factor of about `1 / tan(fovy / 2)` in `t`.
//!   - Back faces (section 5.1, `n . d > sin(alpha)`): culled if every direction from the eye
//!     into the sphere is within 90 degrees of every normal of the cone, i.e.
//!     `angle(n, c - eye) + alpha + beta < 90 degrees`, `beta = asin(r / |c - eye|)`.
//!   - Screen-space error (section 4.2.3): `max(e_g, attribute_scale * e_a)` divided by the
//!     distance `d'` from the eye to the sphere, in pixels (`height / (2 tan(fovy / 2))` per
//!     unit at unit distance); split if above `error_px`. The paper's view-direction factor on
//!     `e_g` is left out (taken as 1, conservative) because it is not monotone.
//! * **Convergence.** A state is *converged* for a view when a pass performs no split and no
//!   collapse; a further pass then changes nothing. From any state, repeated passes reach it.
//! * Prefix sums are chunked parallel scans; the scatters of Algorithms 3 and 4 are
//!   order-preserving parallel collects whose positions equal those prefix sums.

use std::borrow::Cow;
use std::convert::Infallible;

use glam::{Mat4, Vec3, Vec4};
use rayon::prelude::*;

use super::all_levels;
use super::one_level::{self, active_of, Cached};
use crate::pass_stats::PassStats;
use crate::progressive::{Criteria, ProgressiveMesh, SplitTree, NONE};
use crate::view::Camera;

/// A view for [`Adapter::adapt`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Viewpoint {
    /// Projection times view matrix (the conventions of [`crate::view`], depth 0..1).
    pub view_proj: Mat4,
    pub eye: Vec3,
    pub width: u32,
    pub height: u32,
    /// The screen-space error threshold in pixels (the paper uses 0.5 at 1920x1080).
    pub error_px: f32,
    /// Pixels per world unit at unit distance: `height / (2 tan(fovy / 2))`.
    pub pixels_per_unit: f32,
    /// The LOD falloff outside the frustum (the paper's `c_LOD`, 100 there).
    pub c_lod: f32,
    /// World length per unit of attribute error (normal chord); 0 ignores normals.
    pub attribute_scale: f32,
}

impl Viewpoint {
    /// The view of `camera` on a `width x height` screen, `c_lod` 100, normals ignored.
    pub fn new(camera: &Camera, width: u32, height: u32, error_px: f32) -> Self {
        let h = height.max(1) as f32;
        Viewpoint {
            view_proj: camera.view_proj(width.max(1) as f32 / h),
            eye: camera.eye,
            width,
            height,
            error_px,
            pixels_per_unit: h / (2.0 * (camera.fovy.to_radians() * 0.5).tan()),
            c_lod: 100.0,
            attribute_scale: 0.0,
        }
    }

    /// The view of the part `rect = [x0, y0, x1, y1]` (pixels, half-open, origin top-left, not
    /// empty) of this view's screen: the sub-frustum through the rect, with the same eye, error
    /// threshold and pixels per unit. Adapted for it, a mesh meets this view's error bound
    /// inside the rect and coarsens outside with the `c_lod` falloff, so a tile renderer pays
    /// only for its own tile.
    pub fn for_tile(&self, rect: [u32; 4]) -> Viewpoint {
        let (w, h) = (self.width.max(1) as f32, self.height.max(1) as f32);
        let [x0, y0, x1, y1] = rect.map(|v| v as f32);
        let (l, r) = (2.0 * x0 / w - 1.0, 2.0 * x1 / w - 1.0);
        let (t, b) = (1.0 - 2.0 * y0 / h, 1.0 - 2.0 * y1 / h);
        // Clip-space scale and offset mapping [l, r] x [b, t] onto [-1, 1]^2.
        let crop = Mat4::from_cols(
            Vec4::new(2.0 / (r - l), 0.0, 0.0, 0.0),
            Vec4::new(0.0, 2.0 / (t - b), 0.0, 0.0),
            Vec4::Z,
            Vec4::new(-(r + l) / (r - l), -(t + b) / (t - b), 0.0, 1.0),
        );
        Viewpoint { view_proj: crop * self.view_proj, width: rect[2] - rect[0], height: rect[3] - rect[1], ..*self }
    }

    /// The frustum planes (left, right, bottom, top, near, far), normalised to world distances,
    /// positive inside.
    pub fn planes(&self) -> [Vec4; 6] {
        let m = self.view_proj;
        let (r0, r1, r2, r3) = (m.row(0), m.row(1), m.row(2), m.row(3));
        [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r2, r3 - r2].map(|p| {
            let l = p.truncate().length();
            if l > 0.0 {
                p / l
            } else {
                p
            }
        })
    }

    /// Whether the view asks for split `s` of `pm` (the criteria of section 5.1).
    pub fn needs_split(&self, pm: &ProgressiveMesh, s: usize) -> bool {
        Eval::new(self).needs(&Cached::of(pm, s as u32))
    }
}

/// A view prepared for evaluation.
pub(super) struct Eval {
    view: Viewpoint,
    planes: [Vec4; 6],
}

impl Eval {
    pub(super) fn new(view: &Viewpoint) -> Self {
        Eval { view: *view, planes: view.planes() }
    }

    /// The test, written as plain scalar arithmetic in a fixed order (no transcendental
    /// functions, no fused multiply-adds, no SIMD dot products) so that `worker/src/pm_adapt/shaders/common.wgsl`,
    /// which repeats it operation for operation, reaches the same decision.
    pub(super) fn needs(&self, c: &Cached) -> bool {
        needs_split(&self.view, &self.planes, c.center.to_array(), c.normal.to_array(), &c.crit)
    }
}

/// The refinement test of [`Viewpoint::needs_split`] (see the module docs) for a split whose vertex
/// lies at `center` with unit normal `normal` (or zero).
///
/// Back faces: with `a = angle(n, c - eye)`, `alpha = asin(sin_alpha)` and
/// `beta = asin(r / |c - eye|)`, all in `[0, 90]` degrees once `n . (c - eye) > 0`, the test
/// `a + alpha + beta < 90` degrees is decided by the signs of `cos(a + alpha)` and
/// `cos(a + alpha + beta)`, computed from the sines and cosines by the addition theorems.
pub fn needs_split(view: &Viewpoint, planes: &[Vec4; 6], center: [f32; 3], normal: [f32; 3], crit: &Criteria) -> bool {
    let r = crit.radius;
    let (tx, ty, tz) = (center[0] - view.eye.x, center[1] - view.eye.y, center[2] - view.eye.z);
    let dist2 = tx * tx + ty * ty + tz * tz;
    let dist = dist2.sqrt();
    let [nx, ny, nz] = normal;
    let has_normal = nx != 0.0 || ny != 0.0 || nz != 0.0;
    if dist > r && crit.sin_alpha < 1.0 && has_normal {
        let nt = nx * tx + ny * ty + nz * tz;
        if nt > 0.0 {
            let (cx, cy, cz) = (ny * tz - nz * ty, nz * tx - nx * tz, nx * ty - ny * tx);
            let cos_a = nt / dist;
            let sin_a = (cx * cx + cy * cy + cz * cz).sqrt() / dist;
            let sin_al = crit.sin_alpha;
            let cos_al = (1.0 - sin_al * sin_al).max(0.0).sqrt();
            let sin_b = r / dist;
            let cos_b = (dist2 - r * r).max(0.0).sqrt() / dist;
            let cos1 = cos_a * cos_al - sin_a * sin_al;
            let sin1 = sin_a * cos_al + cos_a * sin_al;
            if cos1 > 0.0 && cos1 * cos_b - sin1 * sin_b > 0.0 {
                return false; // back-facing
            }
        }
    }
    let err = crit.geometric_error.max(view.attribute_scale * crit.attribute_error);
    if err.is_nan() || err <= 0.0 {
        return false;
    }
    let mut outside = 0.0f32;
    for p in planes {
        let o = -(p.x * center[0] + p.y * center[1] + p.z * center[2] + p.w) - r;
        outside = outside.max(o);
    }
    let d = (dist - r).max(0.0) + view.c_lod * outside;
    err * view.pixels_per_unit > view.error_px * d
}

/// The most levels an all-levels pass splits below one vertex ([`Levels::All`]): the depth of
/// the GPU's descent stack. A deeper subtree goes on in the next pass.
pub const LEVELS_PER_PASS: u32 = 32;

/// The default of the most splits one vertex's descent performs in an all-levels pass (the
/// *descent budget*): one thread's serial work on the GPU. The vertices a descent has reached
/// when its budget is spent stay until the next pass. On the dragon's 22.5-degree orbit at
/// 1920x1080 and 0.5 px, 256 brings every frame in one changing pass (64: 1 or 2, 16: 2 to
/// 5; `orbit_steps` in `tests/pm_adapt.rs`).
pub const DESCENT_BUDGET: u32 = 256;

/// How far one [`Adapter::adapt`] pass moves a vertex in the split tree.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Levels {
    /// One level: the paper's passes (Algorithms 1 to 5), which the GPU adapter runs in
    /// lockstep; a view change of `k` levels takes `k` passes.
    #[default]
    One,
    /// Every level the view asks for: a pass collapses whole subtrees and splits down the
    /// subtree (at most [`LEVELS_PER_PASS`] levels and a budget of splits per vertex), so one
    /// pass reaches the converged state where the budget suffices (see
    /// `Adapter::pass_all_levels`).
    All,
}

/// View-dependent adaptation of a progressive mesh (see the module docs).
#[derive(Clone, Debug)]
pub struct Adapter<'a> {
    pm: &'a ProgressiveMesh,
    tree: SplitTree,
    /// Active vertices, sorted.
    fvid: Vec<u32>,
    next: Vec<u32>,
    node: Vec<u32>,
    split_cache: Vec<Cached>,
    /// The cache of the vertex's *creator*: the done split whose right child's subtree this
    /// vertex is the leftmost leaf of ([`NONE`] for a base vertex's FVID). For a right child
    /// the creator is its collapse (Algorithm 1 reads only those); every done split is the
    /// creator of exactly one active vertex, which is what [`Levels::All`] evaluates.
    collapse_cache: Vec<Cached>,
    creator: Vec<u32>,
    /// Per split: the end of its vertex's FVID range (the range starts at the split's `v`).
    end: Vec<u32>,
    levels: Levels,
    descent_budget: u32,
    /// Faces: current vertex indices, finest FVIDs, and the split that created them.
    face_idx: Vec<[u32; 3]>,
    face_fvid: Vec<[u32; 3]>,
    face_owner: Vec<u32>,
}

impl<'a> Adapter<'a> {
    /// Starts at the base mesh.
    pub fn new(pm: &'a ProgressiveMesh) -> Self {
        let tree = SplitTree::new(pm);
        let n = pm.base_vertices.len();
        let next = tree.roots.clone();
        let split_cache = next.iter().map(|&s| Cached::of(pm, s)).collect();
        let fvid = pm.base_vertices.clone();
        let face_idx = pm.base_faces.iter().map(|t| t.map(|f| active_of(&fvid, f))).collect();
        let end = split_ends(pm, &tree);
        Adapter {
            pm,
            tree,
            fvid,
            next,
            node: vec![NONE; n],
            split_cache,
            collapse_cache: vec![Cached::default(); n],
            creator: vec![NONE; n],
            end,
            levels: Levels::One,
            descent_budget: DESCENT_BUDGET,
            face_idx,
            face_fvid: pm.base_faces.clone(),
            face_owner: vec![NONE; pm.base_faces.len()],
        }
    }

    /// Sets how far one [`Self::adapt`] pass moves a vertex in the split tree (see [`Levels`]).
    pub fn with_levels(mut self, levels: Levels) -> Self {
        self.set_levels(levels);
        self
    }

    /// As [`Self::with_levels`], in place (the state is valid for either).
    pub fn set_levels(&mut self, levels: Levels) {
        self.levels = levels;
    }

    /// Sets the most splits one vertex's descent performs in an all-levels pass (at least 1;
    /// [`DESCENT_BUDGET`] by default).
    pub fn set_descent_budget(&mut self, splits: u32) {
        self.descent_budget = splits.max(1);
    }

    /// One adaptation pass for `view` (Algorithms 1 to 5, or their all-levels form).
    pub fn adapt(&mut self, view: &Viewpoint) -> PassStats {
        let eval = Eval::new(view);
        match self.levels {
            Levels::One => self.pass(&|c| eval.needs(c)),
            Levels::All => self.pass_all_levels(&|c| eval.needs(c)),
        }
    }

    /// Passes until converged ([`PassStats::converged`]), at most `max_passes`; returns the number of
    /// passes that changed something, or `None` if still not converged.
    pub fn adapt_until_converged(&mut self, view: &Viewpoint, max_passes: usize) -> Option<usize> {
        (0..max_passes).find(|_| self.adapt(view).converged())
    }

    /// One pass that splits every active vertex that has a split (and collapses nothing).
    pub fn refine_step(&mut self) -> PassStats {
        self.pass(&|_| true)
    }

    /// Applies every split: [`Self::refine_step`] until no vertex can split; returns the number
    /// of passes that split (the depth of the split forest).
    pub fn refine_fully(&mut self) -> usize {
        let mut passes = 0;
        while self.refine_step().splits > 0 {
            passes += 1;
        }
        passes
    }

    /// Active vertex FVIDs, ascending.
    pub fn active(&self) -> &[u32] {
        &self.fvid
    }

    /// Per active vertex: the split that would refine it next, or [`NONE`].
    pub fn next_splits(&self) -> &[u32] {
        &self.next
    }

    /// Per active vertex: its node in the split tree (coded as in [`SplitTree`]).
    pub fn nodes(&self) -> &[u32] {
        &self.node
    }

    /// The current faces as indices into [`Self::active`] (the index buffer).
    pub fn faces(&self) -> &[[u32; 3]] {
        &self.face_idx
    }

    /// The current faces as finest-level FVIDs (the FVID buffer).
    pub fn finest_faces(&self) -> &[[u32; 3]] {
        &self.face_fvid
    }

    /// Per current face: the split that created it ([`NONE`] for base faces).
    pub fn face_owners(&self) -> &[u32] {
        &self.face_owner
    }

    /// The current faces as FVID triples of active vertices.
    pub fn face_fvids(&self) -> Vec<[u32; 3]> {
        self.face_idx.par_iter().map(|t| t.map(|i| self.fvid[i as usize])).collect()
    }

    /// The state as a [`one_level::Form`] (and an [`all_levels::Form`]), and the face buffers
    /// a pass rebuilds.
    fn parts(&mut self) -> (Decoded<'_>, one_level::Faces<'_>) {
        let form = Decoded {
            pm: self.pm,
            tree: &self.tree,
            fvid: &self.fvid,
            next: &self.next,
            node: &self.node,
            split_cache: &self.split_cache,
            collapse_cache: &self.collapse_cache,
            creator: &self.creator,
            end: &self.end,
            descent_budget: self.descent_budget,
        };
        let faces =
            one_level::Faces { idx: &mut self.face_idx, fvid: &mut self.face_fvid, owner: &mut self.face_owner };
        (form, faces)
    }

    /// One pass of one level ([`one_level::pass`] over the decoded mesh).
    fn pass(&mut self, need: &(dyn Fn(&Cached) -> bool + Sync)) -> PassStats {
        let (form, faces) = self.parts();
        let done = match one_level::pass(&form, faces, need) {
            Ok(done) => done,
            Err(never) => match never {},
        };
        if let Some(m) = done.moved {
            self.store(m.fvid, &m.vertices);
        }
        done.stats
    }

    /// Replaces the vertex state by `vertices` (sorted by FVID, `new_fvid` their FVIDs).
    fn store(&mut self, new_fvid: Vec<u32>, vertices: &[Slot]) {
        self.fvid = new_fvid;
        self.next = vertices.par_iter().map(|v| v.next).collect();
        self.node = vertices.par_iter().map(|v| v.node).collect();
        self.split_cache = vertices.par_iter().map(|v| v.split_cache).collect();
        self.collapse_cache = vertices.par_iter().map(|v| v.collapse_cache).collect();
        self.creator = vertices.par_iter().map(|v| v.creator).collect();
    }

    /// One pass of [`Levels::All`]: reaches the converged state of the view in one pass.
    ///
    /// 1. Every done split is the creator of exactly one active vertex, which evaluates it: the
    ///    done splits the view no longer asks for are *undone*. Their FVID ranges are nested or
    ///    disjoint; each outermost one is a *region*, whose active vertices (contiguous in the
    ///    sorted buffer) collapse into one: the first, which keeps its FVID and creator and
    ///    becomes the region's split's vertex again.
    /// 2. Every other vertex whose next split is asked for splits, and so on down its subtree
    ///    while the view asks, at most [`LEVELS_PER_PASS`] levels and the descent budget's
    ///    splits: its leaves replace it, in FVID order (depth first, left before right, as the
    ///    GPU's stack goes).
    /// 3. Old faces move as in Algorithm 5: a corner in a region to the region's vertex, a
    ///    corner of a split vertex to the leaf whose range holds its FVID (binary search among
    ///    that vertex's leaves). A face is dropped when its creating split is undone: when a
    ///    region holds a corner and the split's FVID range lies inside the region's. The
    ///    faces of every split done are appended, indexed by binary search.
    ///
    /// The result is the cut below the splits whose done ancestors are all asked for, which is
    /// what repeated one-level passes converge to where the criteria are monotone over the
    /// tree (the builder makes them so): an undone region's descendants are not asked for
    /// either, so no split of a vertex in a region is lost, and a collapse never waits for one.
    fn pass_all_levels(&mut self, need: &(dyn Fn(&Cached) -> bool + Sync)) -> PassStats {
        let (form, faces) = self.parts();
        let done = match all_levels::pass(&form, faces, need) {
            Ok(done) => done,
            Err(never) => match never {},
        };
        if let Some(m) = done.moved {
            self.store(m.fvid, &m.vertices);
        }
        done.stats
    }
}

/// One active vertex's state in [`Adapter`].
#[derive(Clone, Copy, Debug)]
struct Slot {
    fvid: u32,
    next: u32,
    node: u32,
    split_cache: Cached,
    collapse_cache: Cached,
    creator: u32,
}

/// The two children of a vertex whose next split is done: `v` keeps the FVID and the
/// creator, `v_u` gets the split as its creator (and collapse).
fn split_children(pm: &ProgressiveMesh, tree: &SplitTree, old: &Slot) -> [Slot; 2] {
    let s = old.next;
    let [l, r] = tree.children[s as usize];
    let v = Slot { next: l, node: 2 * s, split_cache: Cached::of(pm, l), ..*old };
    let u = Slot {
        fvid: pm.splits[s as usize].v_u,
        next: r,
        node: 2 * s + 1,
        split_cache: Cached::of(pm, r),
        collapse_cache: old.split_cache,
        creator: s,
    };
    [v, u]
}

/// The decoded mesh's state, borrowed for a pass of one level ([`one_level::Form`]): a
/// splitting vertex's operation is its next split's record, and a face's owner is the split
/// that made it.
struct Decoded<'s> {
    pm: &'s ProgressiveMesh,
    tree: &'s SplitTree,
    fvid: &'s [u32],
    next: &'s [u32],
    node: &'s [u32],
    split_cache: &'s [Cached],
    collapse_cache: &'s [Cached],
    creator: &'s [u32],
    end: &'s [u32],
    descent_budget: u32,
}

impl Decoded<'_> {
    /// The collapse target FVID of a node, if it is a right child.
    fn target_of(&self, node: u32) -> u32 {
        if node != NONE && node & 1 == 1 {
            self.pm.splits[(node >> 1) as usize].v
        } else {
            NONE
        }
    }

    fn slot(&self, i: usize) -> Slot {
        Slot {
            fvid: self.fvid[i],
            next: self.next[i],
            node: self.node[i],
            split_cache: self.split_cache[i],
            collapse_cache: self.collapse_cache[i],
            creator: self.creator[i],
        }
    }
}

impl one_level::Form for Decoded<'_> {
    type Vertex = Slot;
    /// The split's index.
    type Op = u32;
    type Error = Infallible;

    fn len(&self) -> usize {
        self.fvid.len()
    }

    fn fvid(&self, i: usize) -> u32 {
        self.fvid[i]
    }

    fn target(&self, i: usize) -> u32 {
        self.target_of(self.node[i])
    }

    fn splits(&self, i: usize, need: one_level::Need) -> bool {
        self.next[i] != NONE && need(&self.split_cache[i])
    }

    fn collapse_cache(&self, i: usize) -> &Cached {
        &self.collapse_cache[i]
    }

    fn op(&self, v: &Slot) -> Result<u32, Self::Error> {
        Ok(v.next)
    }

    fn split<'a>(&'a self, op: &'a u32) -> (&'a [[u32; 3]], u32, u32, u32) {
        let split = &self.pm.splits[*op as usize];
        (&split.faces[..], split.v, split.v_u, *op)
    }

    fn owner(&self, i: usize) -> u32 {
        self.node[i] >> 1
    }

    fn kept(&self, i: usize) -> Slot {
        self.slot(i)
    }

    fn collapsed_into(&self, i: usize) -> Slot {
        // The target takes the collapse's node and keeps its creator.
        let p = self.node[i + 1] >> 1;
        let node = self.tree.parent[p as usize];
        Slot { next: p, node, split_cache: self.collapse_cache[i + 1], ..self.slot(i) }
    }

    fn children(&self, v: &Slot, _op: &u32) -> Result<[Slot; 2], Self::Error> {
        Ok(split_children(self.pm, self.tree, v))
    }

    fn fvid_of(v: &Slot) -> u32 {
        v.fvid
    }
}

impl all_levels::Form for Decoded<'_> {
    fn fvids(&self) -> Cow<'_, [u32]> {
        Cow::Borrowed(self.fvid)
    }

    fn descent_budget(&self) -> u32 {
        self.descent_budget
    }

    /// Tagged by the split's index.
    fn undone(&self, i: usize, need: one_level::Need) -> Option<(u32, u32, u32)> {
        let c = self.creator[i];
        if c == NONE || need(&self.collapse_cache[i]) {
            return None;
        }
        Some((self.pm.splits[c as usize].v, self.end[c as usize], c))
    }

    fn region_vertex(&self, i: usize, s: u32) -> Slot {
        let node = self.tree.parent[s as usize];
        Slot { next: s, node, split_cache: Cached::of(self.pm, s), ..self.slot(i) }
    }

    fn descends(&self, v: &Slot, need: one_level::Need) -> bool {
        v.next != NONE && need(&v.split_cache)
    }

    /// A face owned by split `owner` goes when that split's FVID range lies inside the
    /// region's.
    fn undoes(&self, owner: u32, start: u32, s: u32) -> bool {
        let o = owner as usize;
        owner != NONE && self.pm.splits[o].v >= start && self.end[o] <= self.end[s as usize]
    }
}

/// Per split: the end of its vertex's FVID range (roots end at the next base vertex, a left
/// child at its parent's `v_u`, a right child where its parent ends). Splits come coarse to
/// fine, so a parent is done before its children.
fn split_ends(pm: &ProgressiveMesh, tree: &SplitTree) -> Vec<u32> {
    let mut end = vec![NONE; pm.splits.len()];
    let total = pm.positions.len() as u32;
    for (b, &r) in tree.roots.iter().enumerate() {
        if r != NONE {
            end[r as usize] = pm.base_vertices.get(b + 1).copied().unwrap_or(total);
        }
    }
    for (s, split) in pm.splits.iter().enumerate() {
        let [l, r] = tree.children[s];
        if l != NONE {
            end[l as usize] = split.v_u;
        }
        if r != NONE {
            end[r as usize] = end[s];
        }
    }
    end
}
