//! One pass of every level the view asks for ([`Levels::All`](super::Levels::All), see
//! `Adapter::pass_all_levels` for the steps and why they reach the converged state), written
//! once for both forms of the adaptation's state over [`Form`]: the decoded mesh's
//! ([`super::Adapter`]) and the compressed operations' ([`super::DpmAdapter`]).

use std::borrow::Cow;

use rayon::prelude::*;

use super::one_level::{self, active_of, exclusive_scan, update_faces_all_levels, Corner, Faces, Moved, Need, Outcome};
use crate::pass_stats::PassStats;
use crate::progressive::NONE;

/// What an all-levels pass needs of a form beyond a one-level pass's.
pub(super) trait Form: one_level::Form {
    /// The active FVIDs, in order.
    fn fvids(&self) -> Cow<'_, [u32]>;
    /// The most splits one vertex's descent makes in a pass.
    fn descent_budget(&self) -> u32;
    /// When the view no longer asks for the split that made vertex `i` (its creator): that
    /// split's FVID range `v..end` and a tag the form names it by.
    fn undone(&self, i: usize, need: Need) -> Option<(u32, u32, u32)>;
    /// The vertex a region collapses into: its first vertex `i` with the region's split,
    /// tagged `tag`, done again.
    fn region_vertex(&self, i: usize, tag: u32) -> Self::Vertex;
    /// Whether a vertex of a descent splits now.
    fn descends(&self, v: &Self::Vertex, need: Need) -> bool;
    /// Whether an old face owned by `owner`, with a corner in the region that starts at FVID
    /// `start` and undoes the split tagged `tag`, goes with the region.
    fn undoes(&self, owner: u32, start: u32, tag: u32) -> bool;
}

/// One pass of every level over `form`, the faces rebuilt in `faces`.
pub(super) fn pass<F: Form>(form: &F, faces: Faces, need: Need) -> Result<Outcome<F::Vertex>, F::Error> {
    let n = form.len();
    let fvid = form.fvids();
    let fvid = &fvid[..];

    // 1. Undone splits as ranges of positions in the sorted buffer, and their outermost ones.
    let undone: Vec<(u32, u32, u32)> = (0..n)
        .into_par_iter()
        .filter_map(|i| {
            let (v, end, tag) = form.undone(i, need)?;
            let p = fvid.partition_point(|&x| x < v);
            let q = fvid.partition_point(|&x| x < end);
            Some((p as u32, q as u32, tag))
        })
        .collect();
    let (regions, region, collapses) = outermost(undone, n);

    // 2. The new vertices, in chunks of the sorted buffer, with the operations of the splits
    //    done (down each subtree while the view asks, left before right: FVID order).
    let expand = |i: usize, out: &mut Vec<F::Vertex>, done: &mut Vec<F::Op>| -> Result<(), F::Error> {
        let r = region[i];
        if r != NONE {
            let (p, _, tag) = regions[r as usize];
            if p as usize == i {
                out.push(form.region_vertex(i, tag));
            }
        } else if form.splits(i, need) {
            let mut stack = vec![(form.kept(i), 0)];
            let mut budget = form.descent_budget();
            while let Some((v, depth)) = stack.pop() {
                if budget == 0 || depth == super::LEVELS_PER_PASS || !form.descends(&v, need) {
                    out.push(v);
                    continue;
                }
                budget -= 1;
                let op = form.op(&v)?;
                let [l, u] = form.children(&v, &op)?;
                done.push(op);
                stack.push((u, depth + 1));
                stack.push((l, depth + 1));
            }
        } else {
            out.push(form.kept(i));
        }
        Ok(())
    };
    let (vertices, cnt, done) = expand_chunks(n, expand)?;
    let splits: usize = done.iter().map(Vec::len).sum();
    let unchanged = PassStats { splits, collapses, cancelled: 0, vertices: n, faces: faces.idx.len(), held: false };
    if splits == 0 && collapses == 0 {
        return Ok(Outcome { stats: unchanged, moved: None });
    }
    let vertex_sum = exclusive_scan(&cnt);
    let new_fvid: Vec<u32> = vertices.par_iter().map(F::fvid_of).collect();
    debug_assert!(new_fvid.windows(2).all(|w| w[0] < w[1]));

    // 3. Faces: the old ones moved or dropped, then those of the splits done.
    let new_ref = &new_fvid;
    let new_faces: Vec<([u32; 3], [u32; 3], u32)> = done
        .par_iter()
        .flat_map_iter(|d| d.iter())
        .flat_map_iter(|op| {
            let (added, _, _, owner) = form.split(op);
            added.iter().map(move |&t| (t.map(|f| active_of(new_ref, f)), t, owner))
        })
        .collect();
    let corner = |i: usize, owner: u32| match region[i] {
        NONE => Corner::Free,
        r => {
            let (p, _, tag) = regions[r as usize];
            if form.undoes(owner, fvid[p as usize], tag) {
                Corner::Undone
            } else {
                Corner::Region(p as usize)
            }
        }
    };
    let Faces { idx, fvid: face_fvid, owner } = faces;
    let faces = update_faces_all_levels([idx, face_fvid], owner, &cnt, &vertex_sum, &new_fvid, &corner, new_faces);
    let stats = PassStats { vertices: vertices.len(), faces, ..unchanged };
    Ok(Outcome { stats, moved: Some(Moved { vertices, fvid: new_fvid }) })
}

/// What [`expand_chunks`] returns: the new vertices, each old vertex's count, each chunk's extra.
pub(super) type Expanded<V, X> = (Vec<V>, Vec<u32>, Vec<X>);

/// The vertices that replace the `n` of the sorted buffer in an all-levels pass, for both
/// adapters, made in parallel chunks: `expand(i, out, extra)` pushes old vertex `i`'s (none
/// inside a region but its first, itself, or its descent's leaves) onto `out`. Returns them in
/// order, each old vertex's count of them, and each chunk's `extra`.
pub(super) fn expand_chunks<V: Send, X: Default + Send, E: Send>(
    n: usize,
    expand: impl Fn(usize, &mut Vec<V>, &mut X) -> Result<(), E> + Sync,
) -> Result<Expanded<V, X>, E> {
    const CHUNK: usize = 1 << 12;
    let parts: Vec<(Vec<V>, Vec<u32>, X)> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let (mut out, mut cnt, mut extra) = (Vec::new(), Vec::with_capacity(CHUNK), X::default());
            for i in c * CHUNK..((c + 1) * CHUNK).min(n) {
                let before = out.len();
                expand(i, &mut out, &mut extra)?;
                cnt.push((out.len() - before) as u32);
            }
            Ok((out, cnt, extra))
        })
        .collect::<Result<_, E>>()?;
    let (mut vertices, mut cnt, mut extras) =
        (Vec::with_capacity(parts.iter().map(|p| p.0.len()).sum()), Vec::with_capacity(n), Vec::new());
    for (v, c, x) in parts {
        vertices.extend(v);
        cnt.extend(c);
        extras.push(x);
    }
    Ok((vertices, cnt, extras))
}

/// The outermost of the `undone` ranges of positions `(p, q, tag)` (nested or disjoint), each
/// a collapsing region of an all-levels pass, for both adapters: the regions sorted, each
/// position's region ([`NONE`]: none) and the vertices the collapses remove.
pub(super) fn outermost(mut undone: Vec<(u32, u32, u32)>, n: usize) -> (Vec<(u32, u32, u32)>, Vec<u32>, usize) {
    undone.par_sort_unstable_by_key(|&(p, q, _)| (p, std::cmp::Reverse(q)));
    let mut regions: Vec<(u32, u32, u32)> = Vec::new();
    for r in undone {
        if regions.last().is_none_or(|last| r.0 >= last.1) {
            regions.push(r);
        }
    }
    let mut region = vec![NONE; n];
    for (k, &(p, q, _)) in regions.iter().enumerate() {
        region[p as usize..q as usize].fill(k as u32);
    }
    let collapses = regions.iter().map(|&(p, q, _)| (q - p - 1) as usize).sum();
    (regions, region, collapses)
}
