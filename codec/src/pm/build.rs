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
//! * **Faces per operation.** A `.dpm` operation adds at most [`MAX_OP_FACES`] faces, and a
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
//! The refinement criteria ([`Criteria`], section 4 and 4.2.3) are computed after the
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

use std::borrow::Cow;
use std::collections::hash_map::Entry;
use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};

use rustc_hash::FxHashMap;

use thiserror::Error;

use super::format::MAX_OP_FACES;
use super::order::{permute_in_place, place, preorder, sort_in_place_by_key};
use super::{Criteria, ProgressiveMesh, Split};
use crate::mesh::{Mesh, MeshError};

/// A vertex with more live faces than this becomes a hub (see the module docs).
pub const HUB_FACES: usize = 512;

/// What [`build_with_stats`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BuildStats {
    pub collapses: usize,
    /// Vertices that became hubs (see the module docs); none on ordinary meshes.
    pub hubs: usize,
    /// Steps of the simplification's inner loops: face-list entries read and heap entries
    /// pushed or popped. Linear in the face count whatever the valence (a test bounds it).
    pub work: u64,
    /// Chunks simplified (see [`BuildOptions::chunk_faces`]); 1 for a whole-model build.
    pub chunks: usize,
}

/// Why a progressive mesh cannot be built.
#[derive(Debug, Error, PartialEq)]
pub enum PmError {
    #[error("invalid input mesh: {0}")]
    Mesh(#[from] MeshError),
    /// A collapse would remove more faces than one operation of a `.dpm` file adds
    /// ([`MAX_OP_FACES`]): the faces of the edge between input vertices `a` and `b`
    /// (counted from 0).
    #[error(
        "vertices {a} and {b} share {faces} faces; a .dpm operation adds at most {MAX_OP_FACES} \
         (the collapse of their edge would remove them all)"
    )]
    OpFaces { a: u32, b: u32, faces: usize },
}

/// Refuses, before any work, a mesh with an edge of more than [`MAX_OP_FACES`] faces: the
/// collapse of such an edge (unless its faces went with other collapses first) makes an
/// operation the format cannot hold. A face counts once per pair of its distinct corners
/// (`[a, a, b]` holds the edge `a b`). Counts faces per vertex first (two bytes a vertex,
/// saturating) and pairs only among the vertices of that many faces, so a mesh without such
/// a vertex costs one pass.
pub fn check_op_faces(mesh: &Mesh) -> Result<(), PmError> {
    let max = MAX_OP_FACES as usize;
    let mut per_vertex = vec![0u16; mesh.positions.len()];
    for &t in &mesh.triangles {
        for v in distinct_corners(t) {
            if let Some(c) = per_vertex.get_mut(v as usize) {
                *c = c.saturating_add(1);
            }
        }
    }
    // Both ends of such an edge have more than `max` faces, so a saturated count.
    let hub = |v: u32| per_vertex.get(v as usize).is_some_and(|&c| c as usize >= max.min(u16::MAX as usize));
    let mut pairs: rustc_hash::FxHashMap<(u32, u32), usize> = Default::default();
    for &t in &mesh.triangles {
        let corners: smallvec::SmallVec<[u32; 3]> = distinct_corners(t).filter(|&v| hub(v)).collect();
        for i in 0..corners.len() {
            for j in i + 1..corners.len() {
                let (a, b) = (corners[i].min(corners[j]), corners[i].max(corners[j]));
                *pairs.entry((a, b)).or_default() += 1;
            }
        }
    }
    match pairs.into_iter().filter(|&(_, n)| n > max).max_by_key(|&((a, b), n)| (n, std::cmp::Reverse((a, b)))) {
        Some(((a, b), faces)) => Err(PmError::OpFaces { a, b, faces }),
        None => Ok(()),
    }
}

/// The corners of `tri`, each vertex once, in corner order (a face like `[a, a, b]` is one
/// face of `a`, not two).
fn distinct_corners(tri: [u32; 3]) -> impl Iterator<Item = u32> {
    (0..3).filter(move |&k| !tri[..k].contains(&tri[k])).map(move |k| tri[k])
}

/// A symmetric 4x4 error quadric, upper triangle row by row.
#[derive(Clone, Copy, Default)]
struct Quadric([f64; 10]);

impl Quadric {
    /// The area-weighted plane quadric of a triangle; zero for a degenerate one, which has no
    /// plane and so no error to measure.
    fn of_triangle(p: [[f64; 3]; 3]) -> Self {
        let e1 = sub(p[1], p[0]);
        let e2 = sub(p[2], p[0]);
        let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if !(len > 0.0 && len.is_finite()) {
            return Self::default();
        }
        let [a, b, c] = n.map(|x| x / len);
        let d = -(a * p[0][0] + b * p[0][1] + c * p[0][2]);
        let w = 0.5 * len;
        Self([a * a, a * b, a * c, a * d, b * b, b * c, b * d, c * c, c * d, d * d].map(|x| x * w))
    }

    fn add(&mut self, o: &Self) {
        for (a, b) in self.0.iter_mut().zip(o.0) {
            *a += b;
        }
    }

    /// `[p 1] Q [p 1]^T`.
    fn eval(&self, [x, y, z]: [f64; 3]) -> f64 {
        let [a00, a01, a02, a03, a11, a12, a13, a22, a23, a33] = self.0;
        x * (a00 * x + 2.0 * (a01 * y + a02 * z + a03))
            + y * (a11 * y + 2.0 * (a12 * z + a13))
            + z * (a22 * z + 2.0 * a23)
            + a33
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// A heap entry, packed so that integer order is the heap order: from the top, the cost (bits
/// of a non-negative `f32`, which order like the number; the precision only affects the order
/// of near-ties), `u` and `t` (collapse `u` into `t`), and the stamp: the later of the two
/// vertices' last changes when it was pushed. The entry is stale once either vertex died or
/// changed again, which raises that maximum.
type Candidate = u128;

fn pack(cost: u32, u: u32, t: u32, stamp: u32) -> Candidate {
    (u128::from(cost) << 96) | (u128::from(u) << 64) | (u128::from(t) << 32) | u128::from(stamp)
}

fn unpack(c: Candidate) -> (u32, u32, u32) {
    ((c >> 64) as u32, (c >> 32) as u32, c as u32)
}

/// A 4-ary min-heap. Popping the candidates costs most of the build time, in cache misses;
/// four children per node halve the depth of a binary heap, and the four 16-byte children
/// share one or two cache lines. (`std`'s `BinaryHeap` was about 1.5 times slower here.)
struct QuadHeap(Vec<Candidate>);

impl QuadHeap {
    fn from_vec(v: Vec<Candidate>) -> Self {
        let mut h = Self(v);
        for i in (0..h.0.len().div_ceil(4)).rev() {
            h.sift_down(i);
        }
        h
    }

    fn push(&mut self, x: Candidate) {
        let mut i = self.0.len();
        if i == self.0.capacity() {
            // Grow by a quarter, not double: the heap outgrows its edges by about a third.
            self.0.reserve_exact(i / 4 + 64);
        }
        self.0.push(x);
        while i > 0 {
            let p = (i - 1) / 4;
            if self.0[p] <= x {
                break;
            }
            self.0[i] = self.0[p];
            i = p;
        }
        self.0[i] = x;
    }

    fn pop(&mut self) -> Option<Candidate> {
        let last = self.0.pop()?;
        if self.0.is_empty() {
            return Some(last);
        }
        let top = std::mem::replace(&mut self.0[0], last);
        self.sift_down(0);
        Some(top)
    }

    fn sift_down(&mut self, mut i: usize) {
        let v = &mut self.0;
        let x = v[i];
        loop {
            let first = 4 * i + 1;
            if first >= v.len() {
                break;
            }
            let end = (first + 4).min(v.len());
            let mut m = first;
            for c in first + 1..end {
                if v[c] < v[m] {
                    m = c;
                }
            }
            if v[m] >= x {
                break;
            }
            v[i] = v[m];
            i = m;
        }
        v[i] = x;
    }
}

/// The simplification state: the live faces, each vertex's faces, quadrics and change stamps.
struct Simplifier {
    /// Positions in `f64`, relative to the centre of the used vertices' bounding box, so the
    /// quadrics of a model far from the origin keep their precision.
    pos: Vec<[f64; 3]>,
    quadric: Vec<Quadric>,
    /// Per vertex, the number of collapses done when it last absorbed a vertex.
    changed: Vec<u32>,
    alive: Vec<bool>,
    /// Vertices that are never removed (see [`Self::new`]).
    locked: Vec<bool>,
    /// Current vertex ids of every face (input order, so orientation is kept).
    faces: Vec<[u32; 3]>,
    face_alive: Vec<bool>,
    /// The number of live faces.
    live: usize,
    /// The faces of each vertex, each listed once; removed faces linger until compacted.
    vertex_faces: Vec<Vec<u32>>,
    /// Per vertex: its live faces (the entries of `vertex_faces` whose face is alive).
    live_faces: Vec<u32>,
    /// Per vertex: whether it is a hub (see the module docs).
    hub: Vec<bool>,
    /// Per hub: at least the error of every vertex that has been its neighbour since it
    /// became a hub, and of its neighbours then.
    hub_neighbour_error: HashMap<u32, f64>,
    /// At least the error of every hub.
    hub_error: f64,
    hubs: usize,
    heap: QuadHeap,
    /// See [`BuildStats::work`].
    work: u64,
}

impl Simplifier {
    /// The state for `faces` over vertices at `pos` (relative to the model's centre). Each
    /// face adds its plane to its vertices' quadrics when `quadric` is `None`; a chunk of a
    /// chunked build passes the quadrics its vertices gathered in earlier chunks instead.
    /// `locked` vertices are never removed (their faces reach outside the chunk): an edge
    /// collapses into them, and an edge between two of them is not offered.
    fn new(pos: Vec<[f64; 3]>, faces: Vec<[u32; 3]>, quadric: Option<Vec<Quadric>>, locked: Vec<bool>) -> Self {
        let n = pos.len();
        let mut alive = vec![false; n];
        // Each list allocated once at its size (pushing into empty lists reallocated them
        // on the way: a sixth of this function's time on the dragon).
        let mut count = vec![0u32; n];
        for &tri in &faces {
            for v in distinct_corners(tri) {
                count[v as usize] += 1;
            }
        }
        let mut vertex_faces: Vec<Vec<u32>> = count.iter().map(|&c| Vec::with_capacity(c as usize)).collect();
        drop(count);
        for (f, &tri) in faces.iter().enumerate() {
            for v in distinct_corners(tri) {
                vertex_faces[v as usize].push(f as u32);
                alive[v as usize] = true;
            }
        }
        let quadric = quadric.unwrap_or_else(|| {
            let mut quadric = vec![Quadric::default(); n];
            for tri in &faces {
                let q = Quadric::of_triangle(tri.map(|v| pos[v as usize]));
                for &v in tri {
                    quadric[v as usize].add(&q);
                }
            }
            quadric
        });
        let live_faces: Vec<u32> = vertex_faces.iter().map(|f| f.len() as u32).collect();
        let hub: Vec<bool> = live_faces.iter().map(|&f| f as usize > HUB_FACES).collect();
        let hubs = hub.iter().filter(|&&h| h).count();
        let mut s = Self {
            pos,
            quadric,
            changed: vec![0; n],
            alive,
            live: faces.len(),
            face_alive: vec![true; faces.len()],
            work: 3 * faces.len() as u64,
            faces,
            locked,
            vertex_faces,
            live_faces,
            hub,
            hub_neighbour_error: HashMap::new(),
            hub_error: 0.0,
            hubs,
            heap: QuadHeap(Vec::new()),
        };
        // One entry per edge, found from its lower vertex (`last` marks the upper ones seen),
        // counted first so the heap is allocated once at its size: listing the edges of every
        // face and deduplicating them took twice the memory. The entries differ in their
        // vertices, so the order they pop in does not depend on the order they were pushed.
        let edges_from = |a: usize, last: &mut [u32], visit: &mut dyn FnMut(u32)| {
            for &f in &s.vertex_faces[a] {
                for b in s.faces[f as usize] {
                    if b as usize > a && last[b as usize] != a as u32 && !(s.locked[a] && s.locked[b as usize]) {
                        last[b as usize] = a as u32;
                        visit(b);
                    }
                }
            }
        };
        let mut last = vec![u32::MAX; n];
        let mut edges = 0usize;
        for a in 0..n {
            edges_from(a, &mut last, &mut |_| edges += 1);
        }
        last.fill(u32::MAX);
        let mut initial = Vec::with_capacity(edges);
        for a in 0..n {
            edges_from(a, &mut last, &mut |b| initial.push(s.candidate(a as u32, b)));
        }
        s.heap = QuadHeap::from_vec(initial);
        s
    }

    /// The cheaper direction of collapsing edge `(a, b)`; into a hub if one of them is (into
    /// the one with more faces if both are).
    fn candidate(&self, a: u32, b: u32) -> Candidate {
        let mut q = self.quadric[a as usize];
        q.add(&self.quadric[b as usize]);
        let (ca, cb) = (q.eval(self.pos[a as usize]), q.eval(self.pos[b as usize]));
        let key = |c: f64| if c.is_nan() { f32::MAX.to_bits() } else { (c.max(0.0) as f32).to_bits() };
        let (ha, hb) = (self.hub[a as usize], self.hub[b as usize]);
        let (fa, fb) = (self.live_faces[a as usize], self.live_faces[b as usize]);
        let into_b = match (self.locked[a as usize], self.locked[b as usize], ha, hb) {
            (true, false, ..) => false,
            (false, true, ..) => true,
            (.., false, true) => true,
            (.., true, false) => false,
            (.., true, true) if fa != fb => fa < fb,
            _ => cb <= ca,
        };
        let (u, t, cost) = if into_b { (a, b, key(cb)) } else { (b, a, key(ca)) };
        pack(cost, u, t, self.changed[u as usize].max(self.changed[t as usize]))
    }

    fn offer(&mut self, a: u32, b: u32) {
        if self.locked[a as usize] && self.locked[b as usize] {
            return;
        }
        let c = self.candidate(a, b);
        self.heap.push(c);
        self.work += 1;
    }

    /// The error of a collapse of `u` into `t` before taking `reach` into account: at least the
    /// tracked error of every vertex around it (section 3.2), read from the faces of `u` and of
    /// `t`, or bounded for a hub (see [`Self::hub_bound`]). Hubs found among the vertices read
    /// are remembered in `around`.
    fn error_around(&mut self, u: u32, t: u32, error: &[f64], around: &mut Vec<u32>) -> f64 {
        let (ui, ti) = (u as usize, t as usize);
        let mut e = error[ti].max(error[ui]);
        for v in [u, t] {
            if self.hub[v as usize] {
                e = e.max(self.hub_bound(v));
                continue;
            }
            for &f in &self.vertex_faces[v as usize] {
                self.work += 1;
                if self.face_alive[f as usize] {
                    for w in self.faces[f as usize] {
                        e = e.max(error[w as usize]);
                        if self.hub[w as usize] {
                            around.push(w);
                        }
                    }
                }
            }
        }
        e
    }

    /// An upper bound of the errors of a hub's neighbours: those it has had, and every hub.
    fn hub_bound(&self, h: u32) -> f64 {
        self.hub_neighbour_error.get(&h).copied().unwrap_or(0.0).max(self.hub_error)
    }

    /// `t` took the error `e` in a collapse: the hubs around it and the hub bound learn it.
    fn record_error(&mut self, t: u32, e: f64, around: &[u32]) {
        for &h in around {
            let b = self.hub_neighbour_error.entry(h).or_insert(0.0);
            *b = b.max(e);
        }
        if self.hub[t as usize] {
            self.hub_error = self.hub_error.max(e);
        }
    }

    /// Marks `v`, which has more than [`HUB_FACES`] live faces, as a hub: its bound starts at
    /// its neighbours' errors and its own (once per hub, in its faces).
    fn make_hub(&mut self, v: u32, error: &[f64]) {
        let vi = v as usize;
        self.hub[vi] = true;
        self.hubs += 1;
        let mut b = error[vi];
        for &f in &self.vertex_faces[vi] {
            self.work += 1;
            if self.face_alive[f as usize] {
                for w in self.faces[f as usize] {
                    b = b.max(error[w as usize]);
                }
            }
        }
        self.hub_neighbour_error.insert(v, b);
        self.hub_error = self.hub_error.max(error[vi]);
    }

    /// Face `f` is removed: its vertices have one live face less.
    fn kill_face(&mut self, f: u32) {
        self.face_alive[f as usize] = false;
        self.live -= 1;
        for v in distinct_corners(self.faces[f as usize]) {
            self.live_faces[v as usize] -= 1;
        }
    }

    /// Pops stale entries until a valid collapse `(u, t)` comes up; `None` once no edge is left.
    /// Between ordinary vertices an entry whose vertices have not changed is still an edge
    /// (a face of both dies only in a collapse that changes one of them), but a hub does not
    /// change when it absorbs a vertex, so an edge to a hub is checked for a common live face.
    fn next_collapse(&mut self) -> Option<(u32, u32)> {
        while let Some(c) = self.heap.pop() {
            self.work += 1;
            let (u, t, stamp) = unpack(c);
            let (ui, ti) = (u as usize, t as usize);
            if self.alive[ui]
                && self.alive[ti]
                && self.changed[ui].max(self.changed[ti]) == stamp
                && (!(self.hub[ui] || self.hub[ti]) || self.share_face(u, t))
            {
                return Some((u, t));
            }
        }
        None
    }

    /// Whether `a` and `b` have a live face in common (read in the shorter face list).
    fn share_face(&mut self, a: u32, b: u32) -> bool {
        let (a, b) =
            if self.vertex_faces[a as usize].len() <= self.vertex_faces[b as usize].len() { (a, b) } else { (b, a) };
        let list = &self.vertex_faces[a as usize];
        self.work += list.len() as u64;
        list.iter().any(|&f| self.face_alive[f as usize] && self.faces[f as usize].contains(&b))
    }

    /// Collapses `u` into `t`, appending the faces it removes to `removed`, and offers every
    /// edge of `t` again with `t`'s new quadric (a hub: only the edges to its new
    /// neighbours). `stamp` is the number of collapses done before, plus one: it records
    /// `t`'s change and marks the neighbours offered in `seen`. `error` (with `t`'s new
    /// error) starts the bound of a vertex that becomes a hub.
    fn collapse(&mut self, u: u32, t: u32, removed: &mut Vec<u32>, seen: &mut [u32], stamp: u32, error: &[f64]) {
        let (ui, ti) = (u as usize, t as usize);
        let first_moved = self.vertex_faces[ti].len();
        for f in std::mem::take(&mut self.vertex_faces[ui]) {
            self.work += 1;
            if !self.face_alive[f as usize] {
                continue;
            }
            let tri = &mut self.faces[f as usize];
            if tri.contains(&t) {
                self.kill_face(f);
                removed.push(f);
            } else {
                for x in tri.iter_mut().filter(|x| **x == u) {
                    *x = t;
                }
                self.vertex_faces[ti].push(f);
                self.live_faces[ti] += 1;
            }
        }
        self.alive[ui] = false;
        let qu = self.quadric[ui];
        self.quadric[ti].add(&qu);

        let mut tf = std::mem::take(&mut self.vertex_faces[ti]);
        if self.hub[ti] {
            // Its other edges keep their entries: offer the new neighbours only.
            for &f in &tf[first_moved..] {
                self.work += 1;
                for w in self.faces[f as usize] {
                    if w != t && seen[w as usize] != stamp {
                        seen[w as usize] = stamp;
                        self.offer(t, w);
                    }
                }
            }
            if tf.len() > 2 * self.live_faces[ti] as usize + 64 {
                self.work += tf.len() as u64;
                tf.retain(|&f| self.face_alive[f as usize]);
            }
        } else {
            self.changed[ti] = stamp;
            self.work += tf.len() as u64;
            tf.retain(|&f| self.face_alive[f as usize]);
            self.vertex_faces[ti] = tf;
            if self.live_faces[ti] as usize > HUB_FACES {
                // Once, for a vertex of high valence; before the offers, which then go into it.
                self.make_hub(t, error);
            }
            tf = std::mem::take(&mut self.vertex_faces[ti]);
            for &f in &tf {
                self.work += 1;
                for w in self.faces[f as usize] {
                    if w != t && seen[w as usize] != stamp {
                        seen[w as usize] = stamp;
                        self.offer(t, w);
                    }
                }
            }
        }
        self.vertex_faces[ti] = tf;
    }
}

/// Builds the progressive mesh of `mesh`: collapses every edge, cheapest quadric error first,
/// numbers the vertices by the collapse forest and records the splits coarse to fine.
///
/// Any topology is accepted (see the module docs); the mesh must only pass
/// [`Mesh::validate`]: indices in range, finite positions for used vertices.
pub fn build(mesh: &Mesh) -> Result<ProgressiveMesh, PmError> {
    build_with_progress(mesh, &mut |_, _| {})
}

/// As [`build`], calling `progress(collapses_done, bound)` now and then; `bound` is the
/// number of used vertices, which the collapses (one per vertex that is not a base vertex)
/// approach but never reach.
pub fn build_with_progress(mesh: &Mesh, progress: &mut dyn FnMut(usize, usize)) -> Result<ProgressiveMesh, PmError> {
    build_with_stats(mesh, progress).map(|(pm, _)| pm)
}

/// As [`build_with_progress`], also returning what the builder did.
pub fn build_with_stats(
    mesh: &Mesh,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(ProgressiveMesh, BuildStats), PmError> {
    build_with_options(mesh, BuildOptions::default(), progress)
}

/// Chunk size of [`BuildOptions::default`]: models of more faces are simplified in chunks.
/// Measured on the dragon (871k faces, 2 cores, one run after the other): 64k-face chunks
/// simplify it 2.3x faster than one whole-model simplifier (3.5 s against 8.1 s, smaller
/// working sets and two chunks at a time) into 9.80 bytes/vertex against 9.79, adapting to
/// 0.2% more triangles for the same view; 16k-face chunks were about as fast (3.2 s) and cost
/// 0.4%, 128k-face chunks were slower (4.4 s).
pub const CHUNK_FACES: usize = 1 << 16;

/// How [`build_with_options`] works.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BuildOptions {
    /// A model of more faces than this is simplified in spatial chunks of at most this many
    /// faces (see the module docs), so the simplifier's memory follows the chunk, not
    /// the model; `0` never chunks.
    pub chunk_faces: usize,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self { chunk_faces: CHUNK_FACES }
    }
}

/// The collapse history: `(u, t)` per collapse in input vertex ids, the faces each removed
/// (CSR over `removed`; their indices in [`Model::triangles`] once the simplification is
/// done), and each collapse's geometric error.
#[derive(Default)]
struct Log {
    collapses: Vec<(u32, u32)>,
    removed: Vec<u32>,
    removed_end: Vec<u32>,
    error: Vec<f64>,
}

/// The input ids of a simplifier's local vertices and faces (empty: the ids are the input's).
#[derive(Clone, Copy)]
struct Ids<'a> {
    vertex: &'a [u32],
    face: &'a [u32],
}

impl Ids<'_> {
    fn vertex(&self, l: u32) -> u32 {
        if self.vertex.is_empty() {
            l
        } else {
            self.vertex[l as usize]
        }
    }

    fn face(&self, l: u32) -> u32 {
        if self.face.is_empty() {
            l
        } else {
            self.face[l as usize]
        }
    }
}

/// Per local vertex, the geometric error of section 3.2 as [`run`] tracks it: `reach`, the
/// farthest finest vertex a vertex stands for, and `error`, its tracked error.
struct VertexErrors<'a> {
    reach: &'a mut [f64],
    error: &'a mut [f64],
}

/// Collapses the cheapest edges of `s` until at most `stop_faces` faces are live or no edge
/// is left, appending them to `log`. `reach` and `error` (per local vertex) carry the
/// geometric error of section 3.2: the farthest finest vertex a vertex stands for (`reach`, a
/// nesting bound), raised to the tracked error of every vertex around the collapse ("using
/// the maximum of all neighbor's errors as the actual error"), which keeps the errors locally
/// monotone against fold-overs; the result becomes `t`'s error.
fn run(
    s: &mut Simplifier,
    input: &[[f32; 3]],
    ids: Ids,
    errors: VertexErrors,
    stop_faces: usize,
    log: &mut Log,
    progress: &mut dyn FnMut(usize),
) {
    let VertexErrors { reach, error } = errors;
    let mut seen = vec![u32::MAX; reach.len()];
    let pos64 = |v: u32| input[ids.vertex(v) as usize].map(f64::from);
    let mut around = Vec::new();
    let mut removed = Vec::new();
    let mut stamp = 0u32;
    while s.live > stop_faces {
        let Some((u, t)) = s.next_collapse() else { break };
        let (ui, ti) = (u as usize, t as usize);
        reach[ti] = reach[ti].max(norm(sub(pos64(u), pos64(t))) + reach[ui]);
        around.clear();
        let e = reach[ti].max(s.error_around(u, t, error, &mut around));
        error[ti] = e;
        s.record_error(t, e, &around);
        // At most n - 1 < 2^31 collapses, so stamps (from 1, above the initial 0 of
        // `changed`) never reach the initial u32::MAX of `seen`.
        stamp += 1;
        removed.clear();
        s.collapse(u, t, &mut removed, &mut seen, stamp, error);
        log.collapses.push((ids.vertex(u), ids.vertex(t)));
        log.removed.extend(removed.iter().map(|&f| ids.face(f)));
        log.removed_end.push(log.removed.len() as u32);
        log.error.push(e);
        if log.collapses.len().is_multiple_of(1 << 16) {
            progress(log.collapses.len());
        }
    }
}

/// As [`build_with_stats`], with the chunk size of `opts`.
pub fn build_with_options(
    mesh: &Mesh,
    opts: BuildOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(ProgressiveMesh, BuildStats), PmError> {
    build_mesh(Cow::Borrowed(mesh), opts, progress)
}

/// As [`build_with_options`], taking the mesh so that its positions are freed once numbered
/// into the progressive mesh and its triangles once the normals are made from them (on a
/// large model 18 bytes a triangle less while the splits and criteria are made): what
/// `tessera pm build` runs. The progressive mesh is the same.
pub fn build_owned(
    mesh: Mesh,
    opts: BuildOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(ProgressiveMesh, BuildStats), PmError> {
    build_mesh(Cow::Owned(mesh), opts, progress)
}

/// [`build_with_options`] and [`build_owned`].
fn build_mesh(
    mesh: Cow<Mesh>,
    opts: BuildOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(ProgressiveMesh, BuildStats), PmError> {
    mesh.validate()?;
    check_op_faces(&mesh)?;
    let n = mesh.positions.len();
    let used = mesh.used_vertices();
    let bound = used.iter().filter(|&&u| u).count();
    // Positions relative to the centre of the used vertices' box (finite: `Mesh::validate`
    // ran), so the quadrics of a model far from the origin keep their precision.
    let used_positions = mesh.positions.iter().zip(&used).filter(|(_, &a)| a).map(|(p, _)| p);
    let centre: [f64; 3] = match crate::mesh::bounding_box(used_positions) {
        Some((lo, hi)) => std::array::from_fn(|a| 0.5 * (f64::from(lo[a]) + f64::from(hi[a]))),
        None => [0.0; 3],
    };
    let mut log = Log::default();
    let mut report = |done: usize| progress(done, bound);
    super::trace("simplifying");
    let (stats, alive, model) = if opts.chunk_faces > 0 && mesh.triangles.len() > opts.chunk_faces {
        let (stats, model) = simplify_chunked(mesh, centre, opts.chunk_faces, &mut log, &mut report);
        let mut alive = used;
        for &(u, _) in &log.collapses {
            alive[u as usize] = false;
        }
        (stats, alive, model)
    } else {
        drop(used);
        let pos = mesh.positions.iter().map(|p| sub(p.map(f64::from), centre)).collect();
        let mut s = Simplifier::new(pos, mesh.triangles.clone(), None, vec![false; n]);
        let (mut reach, mut error) = (vec![0.0f64; n], vec![0.0f64; n]);
        let ids = Ids { vertex: &[], face: &[] };
        run(
            &mut s,
            &mesh.positions,
            ids,
            VertexErrors { reach: &mut reach, error: &mut error },
            0,
            &mut log,
            &mut report,
        );
        // Only the survivors and the statistics are read from here on: free the working
        // state (quadrics, face lists, heap: most of the build's memory) before the forest is
        // numbered.
        let stats = BuildStats { collapses: log.collapses.len(), hubs: s.hubs, work: s.work, chunks: 1 };
        let alive = std::mem::take(&mut s.alive);
        drop(s);
        let (positions, triangles) = match mesh {
            Cow::Owned(m) => (m.positions, m.triangles),
            Cow::Borrowed(m) => (m.positions.clone(), m.triangles.clone()),
        };
        (stats, alive, Model { positions, input_id: Vec::new(), triangles, input_face: Vec::new() })
    };
    report(log.collapses.len());
    super::trace("numbering");
    let Log { collapses, removed, removed_end, error: collapse_error } = log;
    // Faces that gathered on an edge during the simplification: refused here, before the
    // numbering and the encoding, where the format's check would find them.
    let mut from = 0;
    for (&(u, t), &end) in collapses.iter().zip(&removed_end) {
        let faces = (end - from) as usize;
        if faces > MAX_OP_FACES as usize {
            return Err(PmError::OpFaces { a: t.min(u), b: t.max(u), faces });
        }
        from = end;
    }

    // Leaves left to right = pre-order of the forest whose vertices' children are the
    // vertices they absorbed, chronologically, roots in ascending input index. Numbered
    // without building the forest: the subtree of a vertex `u` that `t` absorbs comes right
    // after what `t` had gathered, so `u`'s FVID is `t`'s plus `t`'s subtree size just before
    // (and `u`'s subtree is whole then: a dead vertex absorbs nothing). So each collapse
    // records an offset, and the FVIDs follow from the roots' down, latest collapse first
    // (what numbering per chunk needs: docs/design.md, "Builder memory").
    let mut size = vec![1u32; n];
    let offset: Vec<u32> = collapses
        .iter()
        .map(|&(u, t)| {
            let o = size[t as usize];
            size[t as usize] += size[u as usize];
            o
        })
        .collect();
    let mut fvid_of_input = vec![u32::MAX; n];
    let mut base_vertices = Vec::new();
    let mut numbered = 0u32;
    for root in (0..n).filter(|&v| alive[v]) {
        base_vertices.push(numbered);
        fvid_of_input[root] = numbered;
        numbered += size[root];
    }
    drop((size, alive));
    for (&(u, t), &o) in collapses.iter().zip(&offset).rev() {
        fvid_of_input[u as usize] = fvid_of_input[t as usize] + o;
    }
    drop(offset);
    super::trace("positions into FVID order");
    let Model { positions: model_positions, input_id, mut triangles, input_face } = model;
    // Per vertex of the model its FVID (`u32::MAX`: none), read in its order below.
    let fvid: Cow<[u32]> = if input_id.is_empty() {
        Cow::Borrowed(&fvid_of_input)
    } else {
        Cow::Owned(input_id.iter().map(|&v| fvid_of_input[v as usize]).collect())
    };
    drop(input_id);
    let mut positions = vec![[0.0f32; 3]; numbered as usize];
    for (&f, &p) in fvid.iter().zip(&model_positions) {
        if f != u32::MAX {
            positions[f as usize] = p;
        }
    }
    drop(model_positions);

    super::trace("base faces and splits");
    // The triangles moved into the order they are read in: each removed face's to its place
    // in the log, the base faces (never removed) after them in input order, in bucket passes
    // ([`place`]). Gathered through the log, they were read at random (the log runs chunk by
    // chunk, the faces' ids in input order): the 13.9M build in 200 MB spent 31 s here.
    let removed_faces = removed.len();
    let mut dest = vec![u32::MAX; triangles.len()];
    for (k, &f) in removed.iter().enumerate() {
        debug_assert_eq!(dest[f as usize], u32::MAX, "a face removed twice");
        dest[f as usize] = k as u32;
    }
    drop(removed);
    base_faces_after(&mut dest, &input_face, removed_faces as u32);
    drop(input_face);
    place(&mut triangles, &mut dest, 0);
    drop(dest);
    // The corners as FVIDs, in place (what the splits, the base mesh and the criteria read).
    triangles.iter_mut().for_each(|t| *t = t.map(|v| fvid[v as usize]));
    drop(fvid);
    let base_faces = triangles[removed_faces..].to_vec();
    let splits = collapses
        .iter()
        .enumerate()
        .rev()
        .map(|(i, &(u, t))| {
            let start = if i == 0 { 0 } else { removed_end[i - 1] as usize };
            Split {
                v: fvid_of_input[t as usize],
                v_u: fvid_of_input[u as usize],
                faces: triangles[start..removed_end[i] as usize].iter().copied().collect(),
            }
        })
        .collect();
    drop((collapses, removed_end));
    let mut pm = ProgressiveMesh { base_vertices, base_faces, splits, positions, fvid_of_input, ..Default::default() };
    // Splits run coarse to fine, the reverse of the collapses.
    let mut geometric = collapse_error;
    geometric.reverse();
    super::trace("criteria: normals");
    let (normals, criteria) = criteria(&pm, triangles, geometric);
    super::trace("criteria done");
    pm.normals = normals;
    pm.criteria = criteria;
    Ok((pm, stats))
}

/// The model as the steps after the simplification read it: in the input's order after a
/// whole-model simplification, in leaf order after a chunked one (see [`Chunker`]). The log's
/// removed faces are indices into its `triangles`; the log's collapses, and the numbering,
/// use input vertex ids.
struct Model {
    /// Per vertex: its position.
    positions: Vec<[f32; 3]>,
    /// Per vertex: its input id (empty: the ids are the input's).
    input_id: Vec<u32>,
    /// The faces, their corners in this model's vertex ids; the log's removed faces are
    /// indices here.
    triangles: Vec<[u32; 3]>,
    /// Per face: its input id (empty: the ids are the input's).
    input_face: Vec<u32>,
}

/// Gives the faces not yet placed in `dest` (`u32::MAX`, the base faces: never removed) their
/// places from `first` on, in input order: by their index where `input_face` is empty, else by
/// their input ids there (ranked with a bit per input face, so that no array of the faces'
/// size is read at random).
fn base_faces_after(dest: &mut [u32], input_face: &[u32], first: u32) {
    if input_face.is_empty() {
        for (next, d) in (first..).zip(dest.iter_mut().filter(|d| **d == u32::MAX)) {
            *d = next;
        }
        return;
    }
    let mut base = vec![0u64; dest.len().div_ceil(64)];
    for (&d, &f) in dest.iter().zip(input_face) {
        if d == u32::MAX {
            base[f as usize / 64] |= 1 << (f % 64);
        }
    }
    let mut before = Vec::with_capacity(base.len());
    let mut count = first;
    for w in &base {
        before.push(count);
        count += w.count_ones();
    }
    for (d, &f) in dest.iter_mut().zip(input_face) {
        if *d == u32::MAX {
            let (w, b) = (f as usize / 64, f % 64);
            *d = before[w] + (base[w] & ((1u64 << b) - 1)).count_ones();
        }
    }
}

/// A vertex that survived a chunk, with what its collapses there gathered.
struct Carried {
    id: u32,
    quadric: Quadric,
    error: f64,
    reach: f64,
}

/// What is left of a chunk: its live faces (input face id and current vertex ids) and its
/// surviving vertices; and what its subtree did: its collapses, in order, and its statistics.
struct Part {
    faces: Vec<(u32, [u32; 3])>,
    vertices: Vec<Carried>,
    log: Log,
    stats: BuildStats,
}

impl Log {
    /// Appends `other`'s collapses after this log's.
    fn append(&mut self, other: Log) {
        let offset = self.removed.len() as u32;
        self.collapses.extend(other.collapses);
        self.removed.extend(other.removed);
        self.removed_end.extend(other.removed_end.into_iter().map(|e| e + offset));
        self.error.extend(other.error);
    }
}

/// A node of the chunks' kd-tree: a leaf's input faces (a range of the faces in leaf order),
/// or two halves and the number of the right half's first leaf. Leaves are numbered
/// depth-first, so a node covers the leaves `first..end`.
enum Kd {
    Leaf(std::ops::Range<usize>),
    Inner(Box<Kd>, Box<Kd>, u32),
}

/// An input face `f`, its corners `t` and its centroid `c`, while the chunks' kd-tree is built.
struct Centred {
    c: [f32; 3],
    f: u32,
    t: [u32; 3],
}

/// The state shared by the chunks of [`simplify_chunked`], read-only while they run. The
/// chunks see the model in leaf order: the faces in the kd-tree's leaf order and the vertices
/// numbered in the order those faces first use them (chunk ids), so that a chunk reads a
/// range of each array, not the whole input at random.
struct Chunker {
    centre: [f64; 3],
    chunk_faces: usize,
    /// The input faces in leaf order, their corners in chunk ids.
    tris: Vec<[u32; 3]>,
    /// Per chunk id: the vertex's input position.
    positions: Vec<[f32; 3]>,
    /// Per chunk id: the first and the last leaf that holds one of the vertex's faces.
    leaves: Vec<(u32, u32)>,
    /// Collapses done so far, in all chunks (for the progress report).
    done: AtomicUsize,
}

/// Simplifies a model too large for one simplifier in spatial chunks, bottom-up over a
/// kd-tree of its faces (split at the median centroid along the longest axis until a leaf
/// holds at most `chunk_faces`): a leaf's faces are simplified to half their count, two
/// siblings' leftovers are merged and simplified to half again, and the root runs until no
/// edge is left, as the whole-model build does. The simplifier then holds one chunk at a time
/// per thread: sibling subtrees are simplified in parallel (`rayon::join`).
///
/// A vertex with a face of the input outside the chunk is locked there (it may absorb
/// vertices, never be absorbed). A face outside the chunk can only have gained the vertex in
/// its own chunk, where the vertex then had an input face, so every collapse of a chunk
/// removes a vertex all of whose live faces are in the chunk: the faces it removes and the
/// faces it moves are all there, and the chunks' collapses, logged one subtree after the
/// other, are one valid collapse sequence of the whole model, numbered into FVIDs as the
/// whole-model build numbers its own. That a chunk tests the input faces, not the live ones,
/// keeps it from depending on how far its sibling got: the build is the same whatever the
/// threads do. Quadrics are summed where a vertex meets again from two chunks (each face added
/// its plane in exactly one leaf), errors and reaches take their maximum. Within a chunk the
/// order is greedy by quadric error as in the whole-model build; across chunks it is not, so
/// the result differs from it (measured in the README).
///
/// The chunks run on the model in leaf order ([`Chunker`]), which is returned, and their
/// collapses are put back into input ids at the end (their faces stay leaf-order indices); no
/// decision depends on the ids' values (a chunk numbers its vertices by first use in its
/// faces, which are in the same order either way), so the log is the one the input ids give.
/// An owned mesh's triangles are freed once the faces are partitioned with their corners, and
/// its positions once copied into leaf order (what the steps after read).
fn simplify_chunked(
    mesh: Cow<Mesh>,
    centre: [f64; 3],
    chunk_faces: usize,
    log: &mut Log,
    progress: &mut dyn FnMut(usize),
) -> (BuildStats, Model) {
    // The input faces are partitioned with their corners and centroids beside them (made
    // once), so that the median searches, the passes over a node's faces and the leaf order
    // read one array in order: with a face's centroid looked up by its id (and the triangles
    // and positions before it), a spilled build read the three at random on every level, and
    // the 13.9M build in 200 MB did not get through the kd-tree in a minute.
    let n = mesh.positions.len();
    let (p, triangles): (Cow<[_]>, Cow<[_]>) = match mesh {
        Cow::Owned(m) => (Cow::Owned(m.positions), Cow::Owned(m.triangles)),
        Cow::Borrowed(m) => (Cow::Borrowed(&m.positions), Cow::Borrowed(&m.triangles)),
    };
    let mut items: Vec<Centred> = (0..)
        .zip(triangles.iter())
        .map(|(f, &t)| {
            let c = std::array::from_fn(|a| (p[t[0] as usize][a] + p[t[1] as usize][a] + p[t[2] as usize][a]) / 3.0);
            Centred { c, f, t }
        })
        .collect();
    drop(triangles);
    let mut ends = Vec::new();
    let tree = partition(&mut items, 0, chunk_faces, &mut ends);
    super::trace("kd-tree made, the model into leaf order");
    // The faces in leaf order and the vertices numbered by their first use there: a vertex's
    // leaves then only grow, and a chunk's vertices are mostly a range of the chunk ids. The
    // chunks read the input by id before, at random: the 102M build in 1 GB spent 219 s in
    // them and 89 s in the kd-tree (its leaf pass wrote the leaves per input vertex), now
    // 106-138 s (three runs) and 66-67 s, plus 18-21 s for this reordering.
    let mut chunk_id = vec![u32::MAX; n];
    let (mut input_id, mut leaves) = (Vec::new(), Vec::new());
    let (mut tris, mut faces) = (Vec::with_capacity(items.len()), Vec::with_capacity(items.len()));
    let mut start = 0;
    for (leaf, &end) in (0u32..).zip(&ends) {
        for i in &items[start..end] {
            tris.push(i.t.map(|v| {
                let id = &mut chunk_id[v as usize];
                if *id == u32::MAX {
                    *id = input_id.len() as u32;
                    input_id.push(v);
                    leaves.push((leaf, leaf));
                } else {
                    leaves[*id as usize].1 = leaf;
                }
                *id
            }));
            faces.push(i.f);
        }
        start = end;
    }
    drop((items, chunk_id));
    let positions = input_id.iter().map(|&v| p[v as usize]).collect();
    drop(p);
    let count = ends.len() as u32;
    drop(ends);
    super::trace("chunks");
    let c = Chunker { centre, chunk_faces, tris, positions, leaves, done: AtomicUsize::new(0) };
    let cr = &c;
    // The chunks run on rayon's threads; this one reports their progress meanwhile.
    let part = std::thread::scope(|scope| {
        let work = scope.spawn(move || cr.simplify(tree, 0, count, true));
        while !work.is_finished() {
            progress(cr.done.load(Ordering::Relaxed));
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
        work.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    });
    *log = part.log;
    for (u, t) in &mut log.collapses {
        (*u, *t) = (input_id[*u as usize], input_id[*t as usize]);
    }
    let stats = BuildStats { collapses: log.collapses.len(), ..part.stats };
    let Chunker { tris, positions, .. } = c;
    (stats, Model { positions, input_id, triangles: tris, input_face: faces })
}

/// The kd-tree of `faces` (input faces with their centroids, from `at` on in the whole
/// array), the faces reordered in place into leaf order; pushes each leaf's end (in the whole
/// array) to `ends`, so a leaf's number is its index there.
fn partition(faces: &mut [Centred], at: usize, chunk_faces: usize, ends: &mut Vec<usize>) -> Kd {
    if faces.len() > chunk_faces {
        let half = halve(faces);
        let (left, right) = faces.split_at_mut(half);
        let a = partition(left, at, chunk_faces, ends);
        let mid = ends.len() as u32;
        let b = partition(right, at + half, chunk_faces, ends);
        return Kd::Inner(Box::new(a), Box::new(b), mid);
    }
    ends.push(at + faces.len());
    Kd::Leaf(at..at + faces.len())
}

/// Splits `faces` in two at the median centroid along the longest axis of the centroids
/// (ties by face id): the lower half first, in place; returns its length.
fn halve(faces: &mut [Centred]) -> usize {
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for i in faces.iter() {
        for a in 0..3 {
            lo[a] = lo[a].min(i.c[a]);
            hi[a] = hi[a].max(i.c[a]);
        }
    }
    let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
    let mid = faces.len() / 2;
    faces.select_nth_unstable_by(mid, |a, b| a.c[axis].total_cmp(&b.c[axis]).then(a.f.cmp(&b.f)));
    mid
}

impl Chunker {
    /// Simplifies the kd-tree node `kd`, which covers the leaves `first..end`; the root runs
    /// to the end.
    fn simplify(&self, kd: Kd, first: u32, end: u32, root: bool) -> Part {
        let part = match kd {
            Kd::Inner(a, b, mid) => {
                let (mut a, b) =
                    rayon::join(|| self.simplify(*a, first, mid, false), || self.simplify(*b, mid, end, false));
                a.faces.extend(b.faces);
                a.vertices.extend(b.vertices);
                a.log.append(b.log);
                a.stats.hubs += b.stats.hubs;
                a.stats.work += b.stats.work;
                a.stats.chunks += b.stats.chunks;
                a
            }
            Kd::Leaf(range) => Part {
                faces: range.map(|k| (k as u32, self.tris[k])).collect(),
                vertices: Vec::new(),
                log: Log::default(),
                stats: BuildStats::default(),
            },
        };
        self.chunk(part, (first, end), if root { 0 } else { self.chunk_faces / 2 })
    }

    /// Simplifies one chunk, the faces and vertices `part` gathered from the leaves
    /// `first..end`, down to `stop_faces`, appending its collapses to the part's log.
    fn chunk(&self, part: Part, (first, end): (u32, u32), stop_faces: usize) -> Part {
        let Part { faces, vertices, mut log, mut stats } = part;
        // Local ids: the carried vertices first (merging a vertex carried from both halves),
        // then the leaf faces' new ones.
        let mut local: FxHashMap<u32, u32> = FxHashMap::default();
        let mut vertex: Vec<u32> = Vec::new();
        let (mut quadric, mut error, mut reach) = (Vec::new(), Vec::new(), Vec::new());
        for c in vertices {
            match local.entry(c.id) {
                Entry::Vacant(e) => {
                    e.insert(vertex.len() as u32);
                    vertex.push(c.id);
                    quadric.push(c.quadric);
                    error.push(c.error);
                    reach.push(c.reach);
                }
                Entry::Occupied(e) => {
                    let l = *e.get() as usize;
                    quadric[l].add(&c.quadric);
                    error[l] = f64::max(error[l], c.error);
                    reach[l] = f64::max(reach[l], c.reach);
                }
            }
        }
        // A leaf's vertices are all new (its faces add their planes in `Simplifier::new`); a
        // merged chunk's are all carried (a live face's vertices survived its chunk).
        let fresh = vertex.is_empty();
        debug_assert!(fresh || faces.iter().all(|(_, t)| t.iter().all(|v| local.contains_key(v))));
        let (face, tris): (Vec<u32>, Vec<[u32; 3]>) = faces.into_iter().unzip();
        let local_tris: Vec<[u32; 3]> = tris
            .iter()
            .map(|t| {
                t.map(|v| {
                    *local.entry(v).or_insert_with(|| {
                        vertex.push(v);
                        vertex.len() as u32 - 1
                    })
                })
            })
            .collect();
        drop(tris);
        let nl = vertex.len();
        error.resize(nl, 0.0);
        reach.resize(nl, 0.0);
        let locked: Vec<bool> = vertex
            .iter()
            .map(|&g| {
                let (lo, hi) = self.leaves[g as usize];
                lo < first || hi >= end
            })
            .collect();
        let pos = vertex.iter().map(|&g| sub(self.positions[g as usize].map(f64::from), self.centre)).collect();
        let mut s = Simplifier::new(pos, local_tris, (!fresh).then_some(quadric), locked);
        let start = log.collapses.len();
        let ids = Ids { vertex: &vertex, face: &face };
        let mut reported = start;
        let mut report = |k: usize| {
            self.done.fetch_add(k - reported, Ordering::Relaxed);
            reported = k;
        };
        let errors = VertexErrors { reach: &mut reach, error: &mut error };
        run(&mut s, &self.positions, ids, errors, stop_faces, &mut log, &mut report);
        report(log.collapses.len());
        stats.hubs += s.hubs;
        stats.work += s.work;
        stats.chunks += 1;

        let mut dead = vec![false; nl];
        for &(u, _) in &log.collapses[start..] {
            dead[local[&u] as usize] = true;
        }
        let faces = (0..s.faces.len())
            .filter(|&f| s.face_alive[f])
            .map(|f| (face[f], s.faces[f].map(|l| vertex[l as usize])))
            .collect();
        // A survivor without live faces in the chunk or input faces outside it is never
        // touched again.
        let vertices = (0..nl)
            .filter(|&l| !dead[l] && (s.live_faces[l] > 0 || s.locked[l]))
            .map(|l| Carried { id: vertex[l], quadric: s.quadric[l], error: error[l], reach: reach[l] })
            .collect();
        Part { faces, vertices, log, stats }
    }
}

/// Relative slack of the nesting bounds (radius, cone angle) per level.
const SLACK: f64 = 1e-5;

fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Angle between two unit vectors (well conditioned); a right angle if either is zero.
fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
    if norm(a) == 0.0 || norm(b) == 0.0 {
        return std::f64::consts::FRAC_PI_2;
    }
    let d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    norm(cross(a, b)).atan2(d)
}

/// The per-FVID normals and the per-split criteria (see the module docs) of the input
/// triangles `faces` (in FVIDs, in any order; sorted in place, and freed once the normals and
/// leaf cones are made).
fn criteria(pm: &ProgressiveMesh, mut faces: Vec<[u32; 3]>, geometric: Vec<f64>) -> (Vec<[f32; 3]>, Vec<Criteria>) {
    let n = pm.positions.len();
    let pos = |f: usize| pm.positions[f].map(f64::from);
    // The finest faces (in FVIDs) sorted by their first FVID, so that the passes below read
    // and add to the per-FVID arrays in a sweep: in input order they went at random through
    // 44 bytes an FVID, and the 102M build in 1.5 GB spent 115 s in them.
    sort_in_place_by_key(&mut faces, &|t: &[u32; 3]| t[0].min(t[1]).min(t[2]));
    let finest = || faces.iter().copied();
    let face_normal = |t: &[u32; 3]| {
        let [a, b, c] = t.map(|f| pos(f as usize));
        cross(sub(b, a), sub(c, a))
    };
    let mut normal = vec![[0.0f64; 3]; n];
    for t in finest() {
        let fnrm = face_normal(&t);
        for f in distinct_corners(t) {
            for a in 0..3 {
                normal[f as usize][a] += fnrm[a];
            }
        }
    }
    for v in &mut normal {
        let l = norm(*v);
        *v = if l > 0.0 && l.is_finite() { v.map(|x| x / l) } else { [0.0; 3] };
    }
    super::trace("criteria: leaf cones");
    // Leaf cones: the angle between a vertex normal and its incident face normals.
    let mut leaf_alpha = vec![0.0f64; n];
    for t in finest() {
        let fnrm = face_normal(&t);
        let l = norm(fnrm);
        if !(l > 0.0 && l.is_finite()) {
            continue;
        }
        let fnrm = fnrm.map(|x| x / l);
        for f in t {
            let a = angle(normal[f as usize], fnrm);
            leaf_alpha[f as usize] = leaf_alpha[f as usize].max(a);
        }
    }
    drop(faces);
    super::trace("criteria: split tree");

    // Per split, in f64: radius (which is also the geometric error, see below; made from
    // the geometric error), attribute error, cone angle; a split's from its children's, so
    // bottom-up: in the reverse of the split tree's pre-order, a sort ([`preorder`]), where a
    // split's children are the two subtrees done last and its FVIDs those of the splits
    // around it (in split order, what this followed before, a split's children and FVIDs lie
    // anywhere in the arrays: a spilled build read their pages back again and again).
    super::trace("criteria: per split");
    let mut order = preorder(&pm.splits);
    let mut vertices: Vec<[u32; 2]> = pm.splits.iter().map(|s| [s.v, s.v_u]).collect();
    let mut geometric = geometric;
    permute_in_place(&mut vertices, &mut geometric, &order);
    let max_angle = std::f64::consts::FRAC_PI_2;
    // The subtrees done whose parent is not yet: their vertex, radius, attribute error and
    // cone angle.
    let mut done: Vec<(u32, [f64; 3])> = Vec::new();
    let mut criteria = vec![Criteria::default(); pm.splits.len()];
    for (p, &[v, u]) in vertices.iter().enumerate().rev() {
        // A child's radius, attribute error and cone angle: the subtree done last where it
        // splits `f` (the left child splits `v` again, the right one `v_u`), else a leaf's.
        let mut child = |f: u32| match done.last() {
            Some(&(w, c)) if w == f => {
                done.pop();
                c
            }
            _ => [0.0, 0.0, leaf_alpha[f as usize]],
        };
        let (l, r) = (child(v), child(u));
        let (v, u) = (v as usize, u as usize);
        // The geometric error is at least the farthest finest vertex of the region from `v`,
        // so it serves as the region's bounding radius (conservatively: a larger sphere only
        // refines more near the frustum's sides), and the radius costs nothing to store. It
        // is raised where needed so that the children's spheres nest in it: a child's error
        // may exceed its region (raised to its neighbours'), and the runtime tests spheres,
        // which must nest for a child never to ask for a split its parent does not.
        let nest = |c: [f64; 3], d: f64| (d + c[0]) * (1.0 + SLACK);
        let radius = geometric[p].max(nest(l, 0.0)).max(nest(r, norm(sub(pos(u), pos(v)))));
        let attribute = l[1].max(norm(sub(normal[u], normal[v])) + r[1]);
        let alpha = (l[2].max(angle(normal[v], normal[u]) + r[2]) * (1.0 + SLACK) + SLACK).min(max_angle);
        let cone = if norm(normal[v]) == 0.0 { max_angle } else { alpha };
        done.push((v as u32, [radius, attribute, cone]));
        criteria[p] = Criteria {
            sin_alpha: if cone >= max_angle { 1.0 } else { cone.sin() as f32 },
            geometric_error: radius as f32,
            attribute_error: attribute as f32,
            radius: radius as f32,
        };
    }
    drop((vertices, geometric, leaf_alpha));
    // Into split order.
    place(&mut criteria, &mut order, 0);
    let normal: Vec<[f32; 3]> = normal.iter().map(|v| v.map(|x| x as f32)).collect();
    (normal, criteria)
}

#[cfg(test)]
mod tests {
    use super::base_faces_after;

    /// The base faces (those `dest` leaves unplaced) take the places after `first` in the
    /// order of their input ids, whatever order the faces are in: against sorting them.
    #[test]
    fn base_faces_are_placed_in_input_order() {
        let mut rng = testkit::XorShift(0x9e37_79b9_7f4a_7c15);
        let mut next = || rng.next_u64();
        for len in [0usize, 1, 63, 64, 65, 1000, 4099] {
            // A permutation of the input ids (Fisher-Yates), about every third face removed.
            let mut input_face: Vec<u32> = (0..len as u32).collect();
            for i in (1..len).rev() {
                input_face.swap(i, next() as usize % (i + 1));
            }
            let removed: Vec<usize> = (0..len).filter(|_| next() % 3 == 0).collect();
            let mut dest = vec![u32::MAX; len];
            for (place, &k) in removed.iter().enumerate() {
                dest[k] = place as u32;
            }
            let first = removed.len() as u32;
            let mut expected = dest.clone();
            let mut base: Vec<usize> = (0..len).filter(|&k| dest[k] == u32::MAX).collect();
            base.sort_by_key(|&k| input_face[k]);
            for (place, k) in (first..).zip(base) {
                expected[k] = place;
            }
            let mut identity = dest.clone();
            base_faces_after(&mut dest, &input_face, first);
            assert_eq!(dest, expected, "{len} faces");
            // In input order already (no permutation): the places by index.
            let mut by_index = identity.clone();
            for (place, k) in (first..).zip((0..len).filter(|&k| identity[k] == u32::MAX)) {
                by_index[k] = place;
            }
            base_faces_after(&mut identity, &[], first);
            assert_eq!(identity, by_index, "{len} faces in input order");
        }
    }
}
