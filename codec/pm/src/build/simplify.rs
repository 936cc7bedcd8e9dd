//! The quadric-error simplifier (see the module docs of [`super`]): Garland-Heckbert
//! quadrics, a 4-ary heap of candidate collapses with lazy invalidation, hubs, and the loop
//! ([`run`]) that collapses edges cheapest first and logs them with their geometric errors.

use std::collections::HashMap;

use super::options::HUB_FACES;
use super::vec3::{norm, sub};

/// The corners of `tri`, each vertex once, in corner order (a face like `[a, a, b]` is one
/// face of `a`, not two).
pub(super) fn distinct_corners(tri: [u32; 3]) -> impl Iterator<Item = u32> {
    (0..3).filter(move |&k| !tri[..k].contains(&tri[k])).map(move |k| tri[k])
}

/// A symmetric 4x4 error quadric, upper triangle row by row.
#[derive(Clone, Copy, Default)]
pub(super) struct Quadric([f64; 10]);

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

    pub(super) fn add(&mut self, o: &Self) {
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
pub(super) struct Simplifier {
    /// Positions in `f64`, relative to the centre of the used vertices' bounding box, so the
    /// quadrics of a model far from the origin keep their precision.
    pos: Vec<[f64; 3]>,
    pub(super) quadric: Vec<Quadric>,
    /// Per vertex, the number of collapses done when it last absorbed a vertex.
    changed: Vec<u32>,
    pub(super) alive: Vec<bool>,
    /// Vertices that are never removed (see [`Self::new`]).
    pub(super) locked: Vec<bool>,
    /// Current vertex ids of every face (input order, so orientation is kept).
    pub(super) faces: Vec<[u32; 3]>,
    pub(super) face_alive: Vec<bool>,
    /// The number of live faces.
    live: usize,
    /// The faces of each vertex, each listed once; removed faces linger until compacted.
    vertex_faces: Vec<Vec<u32>>,
    /// Per vertex: its live faces (the entries of `vertex_faces` whose face is alive).
    pub(super) live_faces: Vec<u32>,
    /// Per vertex: whether it is a hub (see the module docs).
    hub: Vec<bool>,
    /// Per hub: at least the error of every vertex that has been its neighbour since it
    /// became a hub, and of its neighbours then.
    hub_neighbour_error: HashMap<u32, f64>,
    /// At least the error of every hub.
    hub_error: f64,
    pub(super) hubs: usize,
    heap: QuadHeap,
    /// See [`BuildStats::work`].
    pub(super) work: u64,
}

impl Simplifier {
    /// The state for `faces` over vertices at `pos` (relative to the model's centre). Each
    /// face adds its plane to its vertices' quadrics when `quadric` is `None`; a chunk of a
    /// chunked build passes the quadrics its vertices gathered in earlier chunks instead.
    /// `locked` vertices are never removed (their faces reach outside the chunk): an edge
    /// collapses into them, and an edge between two of them is not offered.
    pub(super) fn new(
        pos: Vec<[f64; 3]>,
        faces: Vec<[u32; 3]>,
        quadric: Option<Vec<Quadric>>,
        locked: Vec<bool>,
    ) -> Self {
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

/// The collapse history: `(u, t)` per collapse in input vertex ids, the faces each removed
/// (CSR over `removed`; their indices in [`Model::triangles`] once the simplification is
/// done), and each collapse's geometric error.
#[derive(Default)]
pub(super) struct Log {
    pub(super) collapses: Vec<(u32, u32)>,
    pub(super) removed: Vec<u32>,
    pub(super) removed_end: Vec<u32>,
    pub(super) error: Vec<f64>,
}

/// The input ids of a simplifier's local vertices and faces (empty: the ids are the input's).
#[derive(Clone, Copy)]
pub(super) struct Ids<'a> {
    pub(super) vertex: &'a [u32],
    pub(super) face: &'a [u32],
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
pub(super) struct VertexErrors<'a> {
    pub(super) reach: &'a mut [f64],
    pub(super) error: &'a mut [f64],
}

/// Collapses the cheapest edges of `s` until at most `stop_faces` faces are live or no edge
/// is left, appending them to `log`. `reach` and `error` (per local vertex) carry the
/// geometric error of section 3.2: the farthest finest vertex a vertex stands for (`reach`, a
/// nesting bound), raised to the tracked error of every vertex around the collapse ("using
/// the maximum of all neighbor's errors as the actual error"), which keeps the errors locally
/// monotone against fold-overs; the result becomes `t`'s error.
pub(super) fn run(
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
