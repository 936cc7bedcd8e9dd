//! One pass of one level (Algorithms 1 to 5 of section 5), written once for both forms of the
//! adaptation's state: the decoded mesh's ([`super::Adapter`]) and the compressed operations'
//! ([`super::DpmAdapter`]). A form says what a vertex is, where a splitting vertex's
//! operation comes from (a split record, or an operation decoded from its address), and how a
//! split, a collapse and a kept vertex move; the steps, their order and the face buffers are
//! here, with what the all-levels pass (`all_levels.rs`) shares: the operation cache, the
//! scans, the face update and the FVID search.

use glam::Vec3;
use rayon::prelude::*;

use crate::pass_stats::PassStats;
use crate::progressive::{Criteria, ProgressiveMesh, NONE};

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
    /// The operation of a vertex that splits (in a one-level pass, or down a descent).
    fn op(&self, v: &Self::Vertex) -> Result<Self::Op, Self::Error>;
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
        .map(|i| if cnt[i] == 2 { form.op(&form.kept(i)).map(Some) } else { Ok(None) })
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

/// One entry of the split/collapse cache: what a vertex needs to evaluate an operation without
/// touching the split records.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Cached {
    pub(super) center: Vec3,
    pub(super) normal: Vec3,
    pub(super) crit: Criteria,
}

impl Cached {
    pub(super) fn of(pm: &ProgressiveMesh, s: u32) -> Self {
        if s == NONE {
            return Cached::default();
        }
        let v = pm.splits[s as usize].v as usize;
        Cached {
            center: Vec3::from(pm.positions[v]),
            normal: Vec3::from(pm.normals.get(v).copied().unwrap_or_default()),
            crit: pm.criteria.get(s as usize).copied().unwrap_or_default(),
        }
    }
}

/// Algorithm 2's cancellations, for both adapters: a collapse (state 0) whose target (the
/// vertex before it) splits (state 2) keeps its vertex (1). Returns the vertex counts and the
/// splits, collapses and cancelled collapses they make.
pub(super) fn cancel_collapses(state: &[u32]) -> (Vec<u32>, usize, usize, usize) {
    let cnt: Vec<u32> = (0..state.len())
        .into_par_iter()
        .map(|i| if state[i] == 0 && state[i - 1] == 2 { 1 } else { state[i] })
        .collect();
    let splits = cnt.par_iter().filter(|&&c| c == 2).count();
    let collapses = cnt.par_iter().filter(|&&c| c == 0).count();
    let cancelled = state.par_iter().filter(|&&c| c == 0).count() - collapses;
    (cnt, splits, collapses, cancelled)
}

/// Algorithm 4's indices of a new face `t` of the split of `v` into `v` (new slot `j`) and
/// `v_u` (slot `j + 1`), for both adapters: a corner in `[v, v_u)` is `v`, one in `v_u`'s range
/// (up to the FVID of slot `j + 2`) is `v_u`, any other the active vertex with the greatest
/// FVID `<=` the corner's, by binary search in the new sorted FVIDs.
pub(super) fn split_face_indices(t: [u32; 3], v: u32, v_u: u32, j: u32, new_fvid: &[u32]) -> [u32; 3] {
    let end = new_fvid.get(j as usize + 2).copied().unwrap_or(NONE);
    t.map(|f| match f {
        f if f >= v && f < v_u => j,
        f if f >= v_u && f < end => j + 1,
        f => active_of(new_fvid, f),
    })
}

/// Exclusive prefix sum in parallel chunks; `out.len() == v.len() + 1`, the last entry the total.
pub(super) fn exclusive_scan(v: &[u32]) -> Vec<u32> {
    const CHUNK: usize = 1 << 14;
    let sums: Vec<u32> = v.par_chunks(CHUNK).map(|c| c.iter().sum()).collect();
    let mut offsets = Vec::with_capacity(sums.len());
    let mut acc = 0u32;
    for s in sums {
        offsets.push(acc);
        acc += s;
    }
    let mut out = vec![0u32; v.len() + 1];
    out[..v.len()].par_chunks_mut(CHUNK).zip(v.par_chunks(CHUNK)).zip(offsets).for_each(|((o, c), mut a)| {
        for (x, &y) in o.iter_mut().zip(c) {
            *x = a;
            a += y;
        }
    });
    out[v.len()] = acc;
    out
}

/// Algorithm 5 and the rebuild of the face buffers, for both adapters: every old corner moves to
/// its vertex's new position, a collapsed vertex's to its target (the previous one), a split
/// vertex's to `v_u` (the next one) when the corner's FVID reaches `v_u`; the faces whose owner
/// is the split a collapsing vertex undoes (`collapsed(i)`) are dropped, order kept, and
/// `new_faces` appended. `faces` are the index and FVID buffers, `owner` the owners; returns
/// the face count.
pub(super) fn update_faces(
    faces: [&mut Vec<[u32; 3]>; 2],
    owner: &mut Vec<u32>,
    cnt: &[u32],
    vertex_sum: &[u32],
    new_fvid: &[u32],
    collapsed: &(dyn Fn(usize) -> u32 + Sync),
    new_faces: Vec<([u32; 3], [u32; 3], u32)>,
) -> usize {
    // A collapsing vertex's corner goes to its target, the vertex before it, which stays (a
    // target never collapses); a split vertex's two slots are searched as a descent's leaves.
    let corner = |i: usize, owner: u32| match cnt[i] {
        0 if owner != NONE && collapsed(i) == owner => Corner::Undone,
        0 => Corner::Region(i - 1),
        _ => Corner::Free,
    };
    update_faces_all_levels(faces, owner, cnt, vertex_sum, new_fvid, &corner, new_faces)
}

/// Where an old face's corner at an active vertex goes in an all-levels pass.
pub(super) enum Corner {
    /// The vertex is in no collapsing region: it stays or splits.
    Free,
    /// It is in a region that undoes the face's split: the face goes.
    Undone,
    /// It is in a region whose vertex is old vertex `p`.
    Region(usize),
}

/// The face update of an all-levels pass, for both adapters: a corner in a region moves to the
/// region's vertex (or the face goes, [`Corner::Undone`]), a corner of a kept vertex to its new
/// position, one of a split vertex to the leaf whose range holds its FVID (binary search among
/// that vertex's leaves, `new_fvid[vertex_sum[i]..vertex_sum[i + 1]]`); then `new_faces` are
/// appended. Returns the face count.
pub(super) fn update_faces_all_levels(
    faces: [&mut Vec<[u32; 3]>; 2],
    owner: &mut Vec<u32>,
    cnt: &[u32],
    vertex_sum: &[u32],
    new_fvid: &[u32],
    corner: &(dyn Fn(usize, u32) -> Corner + Sync),
    new_faces: Vec<([u32; 3], [u32; 3], u32)>,
) -> usize {
    let [face_idx, face_fvid] = faces;
    let kept: Vec<([u32; 3], [u32; 3], u32)> = (0..face_idx.len())
        .into_par_iter()
        .filter_map(|k| {
            let (old, fv, owner) = (face_idx[k], face_fvid[k], owner[k]);
            let mut idx = [0u32; 3];
            for c in 0..3 {
                let i = old[c] as usize;
                idx[c] = match corner(i, owner) {
                    Corner::Undone => return None,
                    Corner::Region(p) => vertex_sum[p],
                    Corner::Free if cnt[i] == 1 => vertex_sum[i],
                    Corner::Free => {
                        let (a, b) = (vertex_sum[i] as usize, vertex_sum[i + 1] as usize);
                        (a + new_fvid[a..b].partition_point(|&x| x <= fv[c]) - 1) as u32
                    }
                };
            }
            Some((idx, fv, owner))
        })
        .collect();
    let total = kept.len() + new_faces.len();
    let (mut fi, mut ff, mut fo) = (Vec::with_capacity(total), Vec::with_capacity(total), Vec::with_capacity(total));
    for (a, b, c) in kept.into_iter().chain(new_faces) {
        fi.push(a);
        ff.push(b);
        fo.push(c);
    }
    *face_idx = fi;
    *face_fvid = ff;
    *owner = fo;
    total
}

/// The index of the active vertex a finest FVID `f` stands for, in the sorted active FVIDs:
/// the one with the greatest FVID `<= f` (0 if none).
pub(super) fn active_of(sorted: &[u32], f: u32) -> u32 {
    sorted.partition_point(|&x| x <= f).saturating_sub(1) as u32
}
