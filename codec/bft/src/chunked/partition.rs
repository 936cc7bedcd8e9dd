//! Cutting triangles into spatially coherent chunks: a kd-tree on their centroids.

use crate::mesh::bounding_box;

pub(super) fn centroid(p: &[[f32; 3]], t: [u32; 3]) -> [f32; 3] {
    let [a, b, c] = t.map(|v| p[v as usize]);
    [0, 1, 2].map(|k| (a[k] + b[k] + c[k]) / 3.0)
}

/// Cuts `idx` (triangle indices with their centroids) into leaves of at most `target`
/// triangles with a kd-tree of median splits on the longest axis of the centroids' box; each
/// leaf's range is pushed in the tree's order. Leaves are balanced: a node of `n` triangles
/// gets `ceil(n / target)` leaves, split as evenly as they go.
pub(super) fn kd_leaves(
    cent: &[[f32; 3]],
    idx: &mut [u32],
    target: usize,
    start: usize,
    out: &mut Vec<std::ops::Range<usize>>,
) {
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
    kd_leaves(cent, l, target, start, out);
    kd_leaves(cent, r, target, start + left, out);
}
