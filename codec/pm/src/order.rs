//! Orders of a progressive mesh's splits, made and applied in passes that read and write
//! their arrays as sequential streams, so that they stay fast where the arrays are pages the
//! kernel may drop (`pm build --spill-dir`, docs/design.md "Spilling"): the split tree's
//! pre-order as a sort ([`preorder`]), and moving arrays into an order in place
//! ([`permute_in_place`], [`place`]).

use crate::progressive::Split;

/// The splits in the pre-order of their tree (each split before its left then its right
/// subtree, the roots in FVID order), as split indices: the splits sorted by their vertex's
/// FVID `v`, in index order where they split the same vertex (a stable radix sort, least
/// significant digit first, of `(v, index)` pairs).
///
/// That sort is the pre-order of a valid progressive mesh: a split's left subtree splits
/// the FVIDs `v..v_u` and its right subtree `v_u..v_end`, so the subtrees' splits sort after
/// their root and the left one's before the right one's; the splits of one vertex run
/// coarse to fine in index order, each the left child of the one before. It follows no
/// pointers (following the split tree's children from the roots, what the encoder did,
/// reads the splits at random); the encoder checks the order it gives against the FVID
/// ranges as it walks it.
pub(crate) fn preorder(splits: &[Split]) -> Vec<u32> {
    let max_v = splits.iter().map(|s| s.v).max().unwrap_or(0);
    let bits = (32 - max_v.leading_zeros()).max(1);
    let passes = bits.div_ceil(11);
    let digit = bits.div_ceil(passes);
    let mut a: Vec<u64> = splits.iter().enumerate().map(|(i, s)| u64::from(s.v) << 32 | i as u64).collect();
    let mut b = vec![0u64; a.len()];
    let mask = (1u64 << digit) - 1;
    for pass in 0..passes {
        let shift = 32 + pass * digit;
        let mut at = vec![0usize; 1 << digit];
        for &x in &a {
            at[((x >> shift) & mask) as usize] += 1;
        }
        let mut sum = 0;
        for c in at.iter_mut() {
            (*c, sum) = (sum, sum + *c);
        }
        for &x in &a {
            let d = &mut at[((x >> shift) & mask) as usize];
            b[*d] = x;
            *d += 1;
        }
        std::mem::swap(&mut a, &mut b);
    }
    drop(b);
    a.into_iter().map(|x| x as u32).collect()
}

/// Sorts `a` by `key` in place, in passes that read and write it as [`BUCKETS`] sequential
/// streams (an American flag sort on the key's top byte, then each bucket on the next, until
/// a bucket is small enough for `sort_unstable_by_key`), for the same reason as
/// [`permute_in_place`]. Unstable, and the same order on every run.
pub(crate) fn sort_in_place_by_key<T, K: Fn(&T) -> u32>(a: &mut [T], key: &K) {
    let max = a.iter().map(key).max().unwrap_or(0);
    sort_digits(a, key, 32 - max.leading_zeros());
}

/// [`sort_in_place_by_key`] of elements whose keys agree above their lowest `bits` bits.
fn sort_digits<T, K: Fn(&T) -> u32>(a: &mut [T], key: &K, bits: u32) {
    if a.len() <= PLACED_BY_CYCLES || bits == 0 {
        a.sort_unstable_by_key(key);
        return;
    }
    let shift = bits.saturating_sub(8);
    let bucket = |x: &T| ((key(x) >> shift) & 0xff) as usize;
    let (mut head, end) = bucket_bounds(a.iter().map(bucket));
    let starts = head;
    for k in 0..BUCKETS {
        while head[k] < end[k] {
            let i = head[k];
            let t = bucket(&a[i]);
            if t == k {
                head[k] += 1;
            } else {
                a.swap(i, head[t]);
                head[t] += 1;
            }
        }
    }
    for k in 0..BUCKETS {
        sort_digits(&mut a[starts[k]..end[k]], key, shift);
    }
}

/// Per bucket of a pass its first place and its end, from each element's bucket in turn.
fn bucket_bounds(buckets: impl Iterator<Item = usize>) -> ([usize; BUCKETS], [usize; BUCKETS]) {
    let mut end = [0usize; BUCKETS];
    for b in buckets {
        end[b] += 1;
    }
    let mut head = [0usize; BUCKETS];
    let mut at = 0;
    for k in 0..BUCKETS {
        head[k] = at;
        at += end[k];
        end[k] = at;
    }
    (head, end)
}

/// Moves `a[order[i]]` and `b[order[i]]` to `a[i]` and `b[i]` for every `i` (`order` a
/// permutation), in place, in passes that keep to a few hundred places at a time: each
/// element's destination is distributed by its top bits into [`BUCKETS`] buckets (a pass of
/// an American flag sort: every bucket filled from its head, swapping what does not belong
/// there to where it does), then each bucket the same way, until a bucket holds at most
/// [`PLACED_BY_CYCLES`] elements, which are placed by following the permutation's cycles.
///
/// Following the cycles through the whole arrays (what this did before) reads and writes
/// them at random: fine in memory, but where the arrays are pages the kernel may drop
/// (`pm build --spill-dir`), the 102M build in a 3 GB cgroup reached it after 9 minutes and was
/// still in it at 15, when it was stopped.
/// Here each pass reads and writes the arrays as [`BUCKETS`] sequential streams.
///
/// The two slices are moved one after the other, so that a pass works over one of them (a
/// spilled build's pages in use at once: the splits' 32 bytes an operation, then the
/// criteria's 16, rather than both).
pub(crate) fn permute_in_place<A, B>(a: &mut [A], b: &mut [B], order: &[u32]) {
    let dest = || {
        let mut dest = vec![0u32; order.len()];
        for (i, &k) in order.iter().enumerate() {
            dest[k as usize] = i as u32;
        }
        dest
    };
    place(a, &mut dest(), 0);
    place(b, &mut dest(), 0);
}

/// Buckets a pass of [`permute_in_place`] distributes into.
const BUCKETS: usize = 256;
/// The most elements [`permute_in_place`] places by following cycles.
const PLACED_BY_CYCLES: usize = 1 << 12;

/// Places the elements of `a` where `dest` says, less `first` (the slices' first
/// destination), swapping both slices together.
pub(crate) fn place<A>(a: &mut [A], dest: &mut [u32], first: u32) {
    let n = dest.len();
    if n <= PLACED_BY_CYCLES {
        for i in 0..n {
            while (dest[i] - first) as usize != i {
                let j = (dest[i] - first) as usize;
                a.swap(i, j);
                dest.swap(i, j);
            }
        }
        return;
    }
    // Bucket `k` holds the destinations `first + k * width ..`.
    let width = n.div_ceil(BUCKETS);
    let bucket = |d: u32| (d - first) as usize / width;
    let (mut head, end) = bucket_bounds(dest.iter().map(|&d| bucket(d)));
    for k in 0..BUCKETS {
        while head[k] < end[k] {
            let i = head[k];
            let t = bucket(dest[i]);
            if t == k {
                head[k] += 1;
            } else {
                let j = head[t];
                head[t] += 1;
                a.swap(i, j);
                dest.swap(i, j);
            }
        }
    }
    let (mut a, mut dest) = (a, dest);
    let mut start = first;
    while !dest.is_empty() {
        let len = width.min(dest.len());
        let (a0, a1) = a.split_at_mut(len);
        let (d0, d1) = dest.split_at_mut(len);
        place(a0, d0, start);
        (a, dest) = (a1, d1);
        start += len as u32;
    }
}

#[cfg(test)]
mod tests {
    use super::{permute_in_place, preorder, sort_in_place_by_key};
    use crate::progressive::Split;

    /// Every permutation of five elements (cycles of every length) moves both slices as a
    /// gather through the order would.
    #[test]
    fn permuting_in_place_is_the_gather() {
        let mut orders = vec![vec![]];
        for k in 0..5u32 {
            orders = orders
                .into_iter()
                .flat_map(|o: Vec<u32>| {
                    (0..=o.len()).map(move |at| {
                        let mut o = o.clone();
                        o.insert(at, k);
                        o
                    })
                })
                .collect();
        }
        assert_eq!(orders.len(), 120);
        // And permutations past a pass of buckets (two levels of them, and remainders).
        for n in [5_000u32, 1_300_000] {
            let mut order: Vec<u32> = (0..n).collect();
            let mut x = 0x9e37_79b9u64;
            for i in (1..order.len()).rev() {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                order.swap(i, (x % (i as u64 + 1)) as usize);
            }
            orders.push(order);
        }
        for order in orders {
            let n = order.len() as u32;
            let (mut a, mut b): (Vec<String>, Vec<u32>) = (0..n).map(|i| (format!("s{i}"), 10 * i)).unzip();
            permute_in_place(&mut a, &mut b, &order);
            let want_a: Vec<String> = order.iter().map(|&i| format!("s{i}")).collect();
            let want_b: Vec<u32> = order.iter().map(|&i| 10 * i).collect();
            assert_eq!((a, b), (want_a, want_b), "{order:?}");
        }
    }

    /// The sort is the split tree's pre-order, which [`crate::pm::SplitTree`] gives by
    /// following its children (on a mesh built from a real model, whose vertices split
    /// several times each).
    #[test]
    fn the_sort_is_the_split_trees_preorder() {
        let mesh = crate::load::load_path(&testkit::mesh_path("stanford/bunny_zipper_c3d.obj.gz")).unwrap();
        let pm = crate::pm::build(&mesh).unwrap();
        let tree = crate::pm::SplitTree::new(&pm);
        let mut want = Vec::new();
        for &root in tree.roots.iter().filter(|&&r| r != crate::pm::NONE) {
            let mut stack = vec![root];
            while let Some(s) = stack.pop() {
                want.push(s);
                for c in tree.children[s as usize].into_iter().rev().filter(|&c| c != crate::pm::NONE) {
                    stack.push(c);
                }
            }
        }
        assert!(pm.splits.len() > 30_000);
        assert_eq!(preorder(&pm.splits), want);
        // Past one pass of digits: FVIDs of more than 11 bits, in pieces of 11 or fewer.
        let splits: Vec<Split> = [(5_000_000u32, 1), (7, 2), (5_000_000, 3), (2048, 4), (7, 5), (0, 6)]
            .iter()
            .map(|&(v, v_u)| Split { v, v_u, ..Default::default() })
            .collect();
        assert_eq!(preorder(&splits), [5, 1, 4, 3, 0, 2]);
    }

    /// Sorting in place sorts, past the small case (keys of several bytes, many equal).
    #[test]
    fn sorting_in_place_sorts() {
        let mut rng = testkit::XorShift(0x2545_f491);
        for (n, range) in [(100usize, 1u64 << 31), (50_000, 1 << 24), (300_000, 1000), (70_000, 1 << 32)] {
            let mut a: Vec<(u32, u32)> = (0..n as u32).map(|i| ((rng.next_u64() % range) as u32, i)).collect();
            let mut want = a.clone();
            want.sort_unstable();
            sort_in_place_by_key(&mut a, &|p: &(u32, u32)| p.0);
            assert!(a.windows(2).all(|w| w[0].0 <= w[1].0), "n {n}: not sorted");
            a.sort_unstable();
            assert_eq!(a, want, "n {n}: not a permutation");
        }
    }
}
