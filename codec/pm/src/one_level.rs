//! One pass of one level (Algorithms 1 to 5 of section 5), written once for both forms of the
//! adaptation's state: the decoded mesh's ([`super::Adapter`]) and the compressed operations'
//! ([`super::DpmAdapter`]). A form says what a vertex is, where a splitting vertex's
//! operation comes from (a split record, or an operation decoded from its address), and how a
//! split, a collapse and a kept vertex move; the steps, their order and the face buffers are
//! here.

use rayon::prelude::*;

use super::adapt::{cancel_collapses, exclusive_scan, split_face_indices, update_faces, Cached};
use super::{PassStats, NONE};

/// Whether the view asks for an operation, from its cache.
pub(super) type Need<'n> = &'n (dyn Fn(&Cached) -> bool + Sync);

/// A form of the adaptation's state: its active vertices, sorted by FVID.
pub(super) trait Form: Sync {
    /// One active vertex, as the pass moves it.
    type Vertex: Copy + Send + Sync;
    /// A splitting vertex's operation, fetched once for the pass.
    type Op: Send + Sync;
    type Error: Send;

    /// The number of active vertices.
    fn len(&self) -> usize;
    /// Vertex `i`'s FVID.
    fn fvid(&self, i: usize) -> u32;
    /// The FVID vertex `i` collapses into when it is a right child ([`NONE`] otherwise).
    fn target(&self, i: usize) -> u32;
    /// Whether vertex `i` splits this pass.
    fn splits(&self, i: usize, need: Need) -> bool;
    /// The cache of the split that made vertex `i` (its collapse).
    fn collapse_cache(&self, i: usize) -> &Cached;
    /// The operation of splitting vertex `i`.
    fn op(&self, i: usize) -> Result<Self::Op, Self::Error>;
    /// An operation's split: the faces it adds, its `v` and `v_u`, and the owner its faces
    /// get.
    fn split<'a>(&'a self, op: &'a Self::Op) -> (&'a [[u32; 3]], u32, u32, u32);
    /// The owner of the faces vertex `i`'s collapse removes.
    fn owner(&self, i: usize) -> u32;
    /// Vertex `i` as it stays.
    fn kept(&self, i: usize) -> Self::Vertex;
    /// Vertex `i` after vertex `i + 1` collapsed into it.
    fn collapsed_into(&self, i: usize) -> Self::Vertex;
    /// The two vertices splitting vertex `v` with its operation `op` makes, `v` then `v_u`.
    fn children(&self, v: &Self::Vertex, op: &Self::Op) -> Result<[Self::Vertex; 2], Self::Error>;
    /// A moved vertex's FVID.
    fn fvid_of(v: &Self::Vertex) -> u32;
}

/// The face buffers a pass rebuilds: current vertex indices, finest FVIDs, and owners.
pub(super) struct Faces<'f> {
    pub idx: &'f mut Vec<[u32; 3]>,
    pub fvid: &'f mut Vec<[u32; 3]>,
    pub owner: &'f mut Vec<u32>,
}

/// The state after a pass that changed something: the vertices in FVID order and their FVIDs.
pub(super) struct Moved<V> {
    pub vertices: Vec<V>,
    pub fvid: Vec<u32>,
}

/// What a pass did, and the vertices to store (`None` when nothing split or collapsed).
pub(super) struct Outcome<V> {
    pub stats: PassStats,
    pub moved: Option<Moved<V>>,
}

/// One pass of one level over `form`, the faces rebuilt in `faces`.
pub(super) fn pass<F: Form>(form: &F, faces: Faces, need: Need) -> Result<Outcome<F::Vertex>, F::Error> {
    let n = form.len();
    // Algorithm 1: vertex state update.
    let state: Vec<u32> = (0..n)
        .into_par_iter()
        .map(|i| {
            if form.splits(i, need) {
                return 2;
            }
            let target = form.target(i);
            if target != NONE
                && !need(form.collapse_cache(i))
                && i > 0
                && form.fvid(i - 1) == target
                && (i + 1 == n || form.target(i + 1) != form.fvid(i))
            {
                return 0;
            }
            1
        })
        .collect();
    // Algorithm 2: collapses whose target splits are cancelled.
    let (cnt, splits, collapses, cancelled) = cancel_collapses(&state);
    let unchanged = PassStats { splits, collapses, cancelled, vertices: n, faces: faces.idx.len(), held: false };
    if splits == 0 && collapses == 0 {
        return Ok(Outcome { stats: unchanged, moved: None });
    }

    // The operations of the splitting vertices, fetched once for the pass.
    let ops: Vec<Option<F::Op>> = (0..n)
        .into_par_iter()
        .map(|i| if cnt[i] == 2 { form.op(i).map(Some) } else { Ok(None) })
        .collect::<Result<_, _>>()?;

    // Algorithm 3: memory management.
    let face_cnt: Vec<u32> =
        (0..n).into_par_iter().map(|i| ops[i].as_ref().map_or(0, |op| form.split(op).0.len() as u32)).collect();
    let face_sum = exclusive_scan(&face_cnt);
    let vertex_sum = exclusive_scan(&cnt);
    // Straight into one buffer, in order (a buffer of pairs first cost the decoded mesh's
    // passes about a third more time).
    let vertices: Vec<F::Vertex> = (0..n)
        .into_par_iter()
        .flat_map_iter(|i| {
            let out: [Option<Result<F::Vertex, F::Error>>; 2] = match cnt[i] {
                0 => [None, None],
                // Algorithm 2's collapse: the target takes the collapse back.
                1 if i + 1 < n && cnt[i + 1] == 0 => [Some(Ok(form.collapsed_into(i))), None],
                1 => [Some(Ok(form.kept(i))), None],
                // Algorithm 4: the split writes v and v_u.
                _ => match form.children(&form.kept(i), ops[i].as_ref().expect("fetched above")) {
                    Ok([v, u]) => [Some(Ok(v)), Some(Ok(u))],
                    Err(e) => [Some(Err(e)), None],
                },
            };
            out.into_iter().flatten()
        })
        .collect::<Result<_, _>>()?;
    debug_assert_eq!(vertices.len(), vertex_sum[n] as usize);
    let new_fvid: Vec<u32> = vertices.par_iter().map(F::fvid_of).collect();
    debug_assert!(new_fvid.windows(2).all(|w| w[0] < w[1]));

    // Algorithm 4: the new faces of the splits.
    let new_fvid_ref = &new_fvid;
    let new_faces: Vec<([u32; 3], [u32; 3], u32)> = (0..n)
        .into_par_iter()
        .filter(|&i| cnt[i] == 2)
        .flat_map_iter(|i| {
            let (added, v, v_u, owner) = form.split(ops[i].as_ref().expect("fetched above"));
            let j = vertex_sum[i];
            added.iter().map(move |&t| (split_face_indices(t, v, v_u, j, new_fvid_ref), t, owner))
        })
        .collect();
    debug_assert_eq!(new_faces.len(), face_sum[n] as usize);

    // Algorithm 5: index update and compaction of the old faces.
    let Faces { idx, fvid, owner } = faces;
    let faces = update_faces([idx, fvid], owner, &cnt, &vertex_sum, &new_fvid, &|i| form.owner(i), new_faces);
    let stats = PassStats { vertices: vertices.len(), faces, ..unchanged };
    Ok(Outcome { stats, moved: Some(Moved { vertices, fvid: new_fvid }) })
}
