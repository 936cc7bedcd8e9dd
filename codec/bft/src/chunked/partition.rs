//! Cutting triangles into spatially coherent chunks: a kd-tree on their centroids.

use rayon::prelude::*;

use crate::mesh::bounding_box;

/// Cuts `tris` into chunks of at most `target` triangles ([`kd_leaves`] on their centroids
/// over `positions`): the triangles' indices, and each chunk's range of them, in the tree's
/// order, each range sorted (a chunk keeps its triangles in their order).
pub(super) fn split(
    positions: &[[f32; 3]],
    tris: &[[u32; 3]],
    target: usize,
) -> (Vec<u32>, Vec<std::ops::Range<usize>>) {
    let cent: Vec<[f32; 3]> = tris.par_iter().map(|&t| centroid(positions, t)).collect();
    let mut idx: Vec<u32> = (0..tris.len() as u32).collect();
    let mut leaves = Vec::new();
    kd_leaves(&cent, &mut idx, target, 0, &mut leaves);
    for leaf in &leaves {
        idx[leaf.clone()].sort_unstable();
    }
    (idx, leaves)
}

/// The vertices `tris` use, sorted, and each corner of `tris` as an index into them. The
/// corners are numbered by first use in a hash map and only the distinct vertices (about a
/// sixth of the corners) sorted: one sort of every (vertex, corner) pair was 7% of the
/// 13.9M-triangle dragon's `--lod` build in `perf` (and sorting the vertices, then a binary
/// search per corner, had been 1.4x slower than that sort).
pub(super) fn localize(tris: &[[u32; 3]]) -> (Vec<u32>, Vec<u32>) {
    let mut number: rustc_hash::FxHashMap<u32, u32> =
        rustc_hash::FxHashMap::with_capacity_and_hasher(tris.len(), Default::default());
    let mut first_used: Vec<u32> = Vec::new();
    let corners: Vec<u32> = tris
        .iter()
        .flatten()
        .map(|&v| {
            *number.entry(v).or_insert_with(|| {
                first_used.push(v);
                first_used.len() as u32 - 1
            })
        })
        .collect();
    let mut order: Vec<u64> = first_used.iter().enumerate().map(|(i, &v)| (v as u64) << 32 | i as u64).collect();
    order.sort_unstable();
    let mut rank = vec![0u32; order.len()];
    let verts = order
        .iter()
        .enumerate()
        .map(|(r, &k)| {
            rank[k as u32 as usize] = r as u32;
            (k >> 32) as u32
        })
        .collect();
    (verts, corners.into_iter().map(|c| rank[c as usize]).collect())
}

/// The vertices `tris` use, sorted.
pub(super) fn vertices_of(tris: &[[u32; 3]]) -> Vec<u32> {
    let mut v: Vec<u32> = tris.iter().flatten().copied().collect();
    v.sort_unstable();
    v.dedup();
    v
}

pub(super) fn centroid(p: &[[f32; 3]], t: [u32; 3]) -> [f32; 3] {
    let [a, b, c] = t.map(|v| p[v as usize]);
    [0, 1, 2].map(|k| (a[k] + b[k] + c[k]) / 3.0)
}

/// Cuts `idx` (triangle indices with their centroids) into leaves of at most `target`
/// triangles with a kd-tree of median splits on the longest axis of the centroids' box; each
/// leaf's range is pushed in the tree's order. Leaves are balanced: a node of `n` triangles
/// gets `ceil(n / target)` leaves, split as evenly as they go.
fn kd_leaves(cent: &[[f32; 3]], idx: &mut [u32], target: usize, start: usize, out: &mut Vec<std::ops::Range<usize>>) {
    let n = idx.len();
    if n <= target {
        out.push(start..start + n);
        return;
    }
    let leaves = n.div_ceil(target);
    let left = n * (leaves / 2) / leaves;
    let (lo, hi) = bounding_box(idx.iter().map(|&t| &cent[t as usize])).unwrap_or(([0.0; 3], [0.0; 3]));
    let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
    idx.select_nth_unstable_by(left, |&a, &b| {
        cent[a as usize][axis].total_cmp(&cent[b as usize][axis]).then(a.cmp(&b))
    });
    let (l, r) = idx.split_at_mut(left);
    if n < PARALLEL_SPLIT {
        kd_leaves(cent, l, target, start, out);
        kd_leaves(cent, r, target, start + left, out);
    } else {
        // The halves of a large node on two threads: the encoder splits its buckets, of
        // millions of triangles, one after another (the 13.9M-triangle dragon's eight became
        // chunks in 1.5 s on one thread, 1.2 s on two). The right half's leaves follow the
        // left's.
        let mut right = Vec::new();
        rayon::join(|| kd_leaves(cent, l, target, start, out), || kd_leaves(cent, r, target, start + left, &mut right));
        out.append(&mut right);
    }
}

/// Nodes of at least this many triangles split their halves in parallel.
const PARALLEL_SPLIT: usize = 1 << 16;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn localize_numbers_the_used_vertices_in_order() {
        let tris = [[907, 3, 55], [55, 3, 1 << 31], [7, 907, 1 << 31], [3, 3, 7]];
        let (verts, local) = localize(&tris);
        assert_eq!(verts, vec![3, 7, 55, 907, 1 << 31]);
        let back: Vec<u32> = local.iter().map(|&l| verts[l as usize]).collect();
        assert_eq!(back, tris.iter().flatten().copied().collect::<Vec<_>>());
        assert_eq!(vertices_of(&tris), verts);
        assert_eq!(localize(&[]), (vec![], vec![]));
    }
}
