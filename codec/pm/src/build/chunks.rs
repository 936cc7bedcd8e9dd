//! Chunks (see the module docs of [`super`]): a model of more than
//! [`BuildOptions::chunk_faces`](super::BuildOptions::chunk_faces) faces is cut by a kd-tree
//! into spatial chunks, each simplified with its border locked, siblings in parallel, and the
//! survivors of sibling chunks merged and simplified again up the tree.

use std::borrow::Cow;
use std::collections::hash_map::Entry;
use std::sync::atomic::{AtomicUsize, Ordering};

use rustc_hash::FxHashMap;

use super::numbering::Model;
use super::options::BuildStats;
use super::simplify::{run, Ids, Log, Quadric, Simplifier, VertexErrors};
use super::vec3::sub;
use crate::mesh::Mesh;

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
pub(super) fn simplify_chunked(
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
    crate::pm::trace("kd-tree made, the model into leaf order");
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
    crate::pm::trace("chunks");
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
