//! One pass of every level the view asks for ([`Levels::All`](super::Levels::All), see
//! `Adapter::pass_all_levels` for the steps and why they reach the converged state), written
//! once for both forms of the adaptation's state over [`Form`]: the decoded mesh's
//! ([`super::Adapter`]) and the compressed operations' ([`super::DpmAdapter`]).

use std::borrow::Cow;

use rayon::prelude::*;

use super::adapt::{active_of, exclusive_scan, expand_chunks, outermost, update_faces_all_levels, Corner};
use super::one_level::{self, Faces, Moved, Need, Outcome};
use super::{PassStats, NONE};

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
    /// A descending vertex's operation.
    fn descend(&self, v: &Self::Vertex) -> Result<Self::Op, Self::Error>;
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
                let op = form.descend(&v)?;
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
