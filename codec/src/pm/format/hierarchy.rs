//! The out-of-core hierarchy of section 4.1: a bounding volume hierarchy over the split
//! operations, built top-down. A node takes, from the operation subtrees handed to it, the
//! operations with the greatest geometric error first ("those with the highest simplification
//! error are required first"), as many as fit in its size; the subtrees below them go to its
//! children, split in two by the paper's modified surface area heuristic
//!
//! ```text
//! A ≈ A_l log2[s_l / (s_max + 1)] + A_r log2[s_r / (s_max + 1)]
//! ```
//!
//! (`A` the area of a side's box, `s` its bytes), so a complete operation subtree stays in one
//! subtree of the hierarchy and inner nodes hold the coarse operations. Where the paper is
//! silent: the logarithm, the number of levels a side will take, is taken at least 1 (a side
//! that fits in one node still costs its area once; the formula as printed goes negative
//! there); the boxes are those of the subtree roots' bounding spheres; a node whose
//! remaining subtrees fit in one node gets a single child; nodes are numbered in pre-order
//! (a parent before its children, which out-of-core addresses rely on: a child operation's
//! node is never before its parent's).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// What the hierarchy needs of an operation.
pub(super) struct OpGeometry {
    /// Its children's operations (`usize::MAX`: none).
    pub(super) children: [usize; 2],
    /// Its coded size (an estimate while the hierarchy is built).
    pub(super) size: u64,
    /// Its geometric error (as it decodes).
    pub(super) error: f32,
    /// Its bounding sphere.
    pub(super) center: [f32; 3],
    pub(super) radius: f32,
}

/// The hierarchy: per operation its node, per node its parent.
pub(super) struct Hierarchy {
    pub(super) node_of: Vec<u32>,
    pub(super) parents: Vec<Option<u32>>,
}

/// An operation in a node's heap: by greatest error, then first in pre-order.
#[derive(PartialEq)]
struct ByError(f32, usize);

impl Eq for ByError {}

impl PartialOrd for ByError {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for ByError {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0).then(other.1.cmp(&self.1))
    }
}

/// Builds the hierarchy over the operation forest `ops` (in pre-order: children after their
/// parent) from its `roots`, nodes of at most `s_max` bytes. `None` where an operation alone
/// is larger than `s_max`.
pub(super) fn build(ops: &[OpGeometry], roots: &[usize], s_max: u64) -> Option<Hierarchy> {
    let m = ops.len();
    // Subtree sizes, children before parents.
    let mut subtree = vec![0u64; m];
    for i in (0..m).rev() {
        subtree[i] = ops[i].size + ops[i].children.iter().filter(|&&c| c != usize::MAX).map(|&c| subtree[c]).sum::<u64>();
    }
    let mut node_of = vec![u32::MAX; m];
    let mut parents: Vec<Option<u32>> = vec![];
    let mut stack: Vec<(Vec<usize>, Option<u32>)> = vec![(roots.to_vec(), None)];
    while let Some((frontier, parent)) = stack.pop() {
        let id = parents.len() as u32;
        parents.push(parent);
        let total: u64 = frontier.iter().map(|&r| subtree[r]).sum();
        if total <= s_max {
            // A leaf: the subtrees whole.
            let mut todo = frontier;
            while let Some(i) = todo.pop() {
                node_of[i] = id;
                todo.extend(ops[i].children.iter().filter(|&&c| c != usize::MAX));
            }
            continue;
        }
        // The operations with the greatest error first, as many as fit.
        let mut heap: BinaryHeap<ByError> = frontier.iter().map(|&i| ByError(ops[i].error, i)).collect();
        let mut used = 0u64;
        while let Some(top) = heap.peek() {
            let i = top.1;
            if used + ops[i].size > s_max {
                break;
            }
            heap.pop();
            used += ops[i].size;
            node_of[i] = id;
            for &c in ops[i].children.iter().filter(|&&c| c != usize::MAX) {
                heap.push(ByError(ops[c].error, c));
            }
        }
        if used == 0 {
            return None;
        }
        let rest: Vec<usize> = heap.into_iter().map(|e| e.1).collect();
        if rest.is_empty() {
            continue;
        }
        if rest.len() == 1 || total - used <= s_max {
            stack.push((rest, Some(id)));
            continue;
        }
        let (left, right) = partition(ops, &subtree, rest, s_max);
        // The left side is numbered next (pre-order).
        stack.push((right, Some(id)));
        stack.push((left, Some(id)));
    }
    Some(Hierarchy { node_of, parents })
}

/// Splits subtree roots in two along the axis and position of the least modified surface
/// area cost (module docs).
fn partition(ops: &[OpGeometry], subtree: &[u64], mut rest: Vec<usize>, s_max: u64) -> (Vec<usize>, Vec<usize>) {
    let levels = |s: u64| ((s as f64 / (s_max + 1) as f64).log2()).max(1.0);
    let area = |lo: [f32; 3], hi: [f32; 3]| {
        let d = [0, 1, 2].map(|k| (hi[k] - lo[k]).max(0.0) as f64);
        2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])
    };
    let grow = |b: &mut ([f32; 3], [f32; 3]), o: &OpGeometry| {
        for k in 0..3 {
            b.0[k] = b.0[k].min(o.center[k] - o.radius);
            b.1[k] = b.1[k].max(o.center[k] + o.radius);
        }
    };
    let empty = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    let n = rest.len();
    let mut best: Option<(f64, usize, usize)> = None;
    for axis in 0..3 {
        rest.sort_by(|&a, &b| ops[a].center[axis].total_cmp(&ops[b].center[axis]).then(a.cmp(&b)));
        // Costs of the left sides from the left, of the right sides from the right.
        let mut left_cost = vec![0f64; n];
        let (mut b, mut s) = (empty, 0u64);
        for (k, &i) in rest.iter().enumerate() {
            grow(&mut b, &ops[i]);
            s += subtree[i];
            left_cost[k] = area(b.0, b.1) * levels(s);
        }
        let (mut b, mut s) = (empty, 0u64);
        for k in (1..n).rev() {
            let i = rest[k];
            grow(&mut b, &ops[i]);
            s += subtree[i];
            let cost = left_cost[k - 1] + area(b.0, b.1) * levels(s);
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, k));
            }
        }
    }
    let (_, axis, k) = best.expect("at least two subtrees");
    rest.sort_by(|&a, &b| ops[a].center[axis].total_cmp(&ops[b].center[axis]).then(a.cmp(&b)));
    let right = rest.split_off(k);
    (rest, right)
}
