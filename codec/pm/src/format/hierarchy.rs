//! The out-of-core hierarchy of section 4.1: a bounding volume hierarchy over the split
//! operations, built top-down. A node takes, from the operation subtrees handed to it, the
//! operations with the greatest geometric error first ("those with the highest simplification
//! error are required first"), as many as fit in its size; the subtrees below them go to its
//! children, so a complete operation subtree stays in one subtree of the hierarchy and inner
//! nodes hold the coarse operations.
//!
//! **The split differs from the paper's.** The paper splits by a modified surface area
//! heuristic, `A ≈ A_l log2[s_l / (s_max + 1)] + A_r log2[s_r / (s_max + 1)]` (`A` a side's box
//! area, `s` its bytes). Built that way over the boxes of the subtree roots' bounding spheres
//! (the logarithm taken at least 1, as printed it goes negative for a side that fits in one
//! node), the bunny's hierarchy of 4 kB nodes degenerated into a chain of nodes each holding a
//! layer of the whole model (the heuristic split off small groups again and again), so that a
//! close view required 80% of the file. The split here halves the subtrees' bytes along the
//! longest axis of their centres (measured: the same view then requires 75%, the file is 4%
//! smaller as fewer pointers cross nodes, `cargo test -p tessera-codec --test pm_adapt
//! out_of_core -- --nocapture`).
//!
//! **Four children, not two.** An inner node is a cut through the top of the subtrees handed
//! to it, so nearly every operation in it has a child in another node, and such a pointer
//! costs a node delta and a whole local address (about 2.7 bytes): with two children per
//! node, inner nodes hold half the operations and the layout cost 1.18 (bunny) and 1.39
//! (dragon) bytes per operation over the in-core file, above the paper's "approximately 1".
//! The remaining subtrees are therefore halved twice (each half again only while it holds
//! more than a node), into up to four children: 1.03 and 0.70 bytes per operation, and a close
//! view of the bunny in 4 kB nodes requires 74% of the file against 73% (eight children:
//! 0.34 and 0.62, but 80%: inner nodes then span too much of the model). `cargo test -p
//! tessera-codec --release --test pm_ooc -- --ignored --nocapture` prints the sizes.
//!
//! **A last halving into leaves.** Where what is left below a node holds at most six nodes'
//! bytes, two halvings leave parts of up to one and a half nodes, each an inner node with a
//! small remnant leaf below it; a third halving makes them leaves (up to eight children).
//! Measured: the dragon's layout costs 0.55 bytes per operation instead of 0.70, and the close
//! bunny view of `out_of_core_adaptation_equals_in_core_within_a_budget` (4 kB nodes) requires
//! 313,648 bytes instead of 318,320. Up to eight nodes' bytes, the bunny in 64 kB nodes
//! would cost 0.35 instead of 1.03, but that view would require 331,667 bytes: a leaf over a
//! whole region carries fine operations that the remnant below a coarse inner node kept apart.
//! (These figures predate the pairs of pointers into one node, the format's version 5, which
//! took the layout to 0.87 bytes per operation on the bunny and 0.49 on the dragon, and the
//! estimate of a node's bytes that counts its pointers ([`UNITS`]), which took it to 0.31 and
//! 0.46: the nodes come out as large as asked instead of a fifth smaller. The close bunny view
//! in 4 kB nodes then requires 321,565 bytes of a 400,434-byte file, against 305,152 of
//! 414,960: larger nodes carry more than a view needs, as above.)
//!
//! Where the paper is silent: a node whose remaining subtrees fit in one node gets a single
//! child; nodes are numbered in pre-order (a parent before its children, which out-of-core
//! addresses rely on: a child operation's node is never before its parent's).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::progressive::NONE;

/// Halvings of an inner node's remaining subtrees into its children (2^SPLITS children).
const SPLITS: usize = 2;

/// The estimate of a node's coded bytes, in units of a quarter byte: an operation's in-core
/// coded size, plus [`OP_EXTRA`] (out of core every child that splits costs a node-delta
/// symbol), plus [`POINTER`] per child whose operation is in another node (its node delta and
/// local address instead of an in-node offset). Measured on the first out-of-core coding (with
/// the in-core tables, the costlier of the two) of the dragon subdivided to 13.9M triangles:
/// 0.78 bytes an operation, 3.0 bytes a pointer (the final coding, with the counted tables:
/// 0.10 and 1.9; on the bunny and the dragon 0.10-0.12 and 1.8-1.9). Before, a byte an
/// operation stood for both: leaves came out below the limit and inner nodes, nearly all
/// pointers, above it, so that the 13.9M and 102M builds were grouped and coded again with a
/// limit about a fifth lower (the 13.9M dragon in 2,389 nodes of at most 49,964 bytes instead of
/// 1,365: 0.2% larger).
const UNITS: u64 = 4;
const OP_EXTRA: u64 = 3;
const POINTER: u64 = 12;

/// What the hierarchy needs of the operations (in pre-order: children after their parent),
/// read when needed: the encoder computes it from the quantized operations (a table of it
/// cost 36 bytes an operation, a fifth of the out-of-core coding's memory).
pub(super) trait OpGeometry {
    fn len(&self) -> usize;
    /// Operation `i`'s children's operations ([`NONE`]: none).
    fn children(&self, i: usize) -> [u32; 2];
    /// Its coded size (an estimate while the hierarchy is built).
    fn size(&self, i: usize) -> u32;
    /// Its geometric error (as it decodes).
    fn error(&self, i: usize) -> f32;
    /// Its bounding sphere's centre.
    fn center(&self, i: usize) -> [f32; 3];
}

/// Operation `i`'s children in `ops`.
fn kids(ops: &dyn OpGeometry, i: usize) -> impl Iterator<Item = usize> {
    ops.children(i).into_iter().filter(|&c| c != NONE).map(|c| c as usize)
}

/// The hierarchy: per operation its node, per node its parent.
pub(super) struct Hierarchy {
    pub(super) node_of: Vec<u32>,
    pub(super) parents: Vec<Option<u32>>,
}

/// An operation in a node's heap: by greatest error, then first in pre-order; and whether its
/// parent operation is in the node (its pointer then stays inside if it is taken too).
struct ByError(f32, usize, bool);

impl PartialEq for ByError {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

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
/// parent) from its `roots`, nodes of at most `s_max` bytes as estimated (see [`UNITS`]). `None`
/// where an operation alone is larger than `s_max`.
pub(super) fn build(ops: &dyn OpGeometry, roots: &[usize], s_max: u64) -> Option<Hierarchy> {
    let m = ops.len();
    let s_max = s_max * UNITS;
    let cost = |i: usize| u64::from(ops.size(i)) * UNITS + OP_EXTRA;
    // Subtree sizes (a whole subtree has no pointer out of it), children before parents.
    let mut subtree = vec![0u64; m];
    for i in (0..m).rev() {
        subtree[i] = cost(i) + kids(ops, i).map(|c| subtree[c]).sum::<u64>();
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
                todo.extend(kids(ops, i));
            }
            continue;
        }
        // The operations with the greatest error first, as many as fit: an operation costs
        // its bytes and a pointer per child (out of the node until the child is taken), and
        // takes its own pointer back into the node.
        let mut heap: BinaryHeap<ByError> = frontier.iter().map(|&i| ByError(ops.error(i), i, false)).collect();
        let mut used = 0u64;
        while let Some(top) = heap.peek() {
            let (i, inside) = (top.1, top.2);
            let pointers = POINTER * kids(ops, i).count() as u64;
            let back = if inside { POINTER } else { 0 };
            if used + cost(i) + pointers - back > s_max {
                break;
            }
            heap.pop();
            used += cost(i) + pointers - back;
            node_of[i] = id;
            for c in kids(ops, i) {
                heap.push(ByError(ops.error(c), c, true));
            }
        }
        if used == 0 {
            return None;
        }
        let rest: Vec<usize> = heap.into_iter().map(|e| e.1).collect();
        if rest.is_empty() {
            continue;
        }
        let below: u64 = rest.iter().map(|&i| subtree[i]).sum();
        if rest.len() == 1 || below <= s_max {
            stack.push((rest, Some(id)));
            continue;
        }
        // Split in halves, each half again while it holds more than a node (SPLITS times):
        // up to 2^SPLITS children, pushed so that the first is numbered next (pre-order).
        // Where one more halving would leave parts of about a node, the children are leaves
        // (up to 2^(SPLITS+1)) instead of inner nodes with a remnant each.
        let halvings = if 2 * below <= 3 * (s_max << SPLITS) { SPLITS + 1 } else { SPLITS };
        let mut parts = vec![rest];
        for _ in 0..halvings {
            parts = parts
                .into_iter()
                .flat_map(|p| {
                    if p.len() > 1 && p.iter().map(|&i| subtree[i]).sum::<u64>() > s_max {
                        let (l, r) = partition(ops, &subtree, p);
                        vec![l, r]
                    } else {
                        vec![p]
                    }
                })
                .collect();
        }
        for p in parts.into_iter().rev() {
            stack.push((p, Some(id)));
        }
    }
    Some(Hierarchy { node_of, parents })
}

/// `x` as an integer that orders as [`f32::total_cmp`] orders (the transformation it makes).
fn total_order(x: f32) -> i32 {
    let b = x.to_bits() as i32;
    b ^ (((b >> 31) as u32) >> 1) as i32
}

/// Splits subtree roots in two halves of equal bytes along the longest axis of their centres.
fn partition(ops: &dyn OpGeometry, subtree: &[u64], mut rest: Vec<usize>) -> (Vec<usize>, Vec<usize>) {
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for &i in &rest {
        let c = ops.center(i);
        for k in 0..3 {
            lo[k] = lo[k].min(c[k]);
            hi[k] = hi[k].max(c[k]);
        }
    }
    let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
    // Keyed once: the centres are computed from the quantized operations.
    rest.sort_by_cached_key(|&i| (total_order(ops.center(i)[axis]), i));
    let total: u64 = rest.iter().map(|&i| subtree[i]).sum();
    let mut acc = 0;
    let mut k = 1;
    for (j, &i) in rest.iter().enumerate() {
        acc += subtree[i];
        if acc * 2 >= total {
            k = (j + 1).clamp(1, rest.len() - 1);
            break;
        }
    }
    let right = rest.split_off(k);
    (rest, right)
}
