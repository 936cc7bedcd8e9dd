//! Property tests: every random mesh round-trips exactly (triangle multiset on input vertex
//! indices, orientation, quantized positions), whatever its topology.

use codec::Mesh;
use proptest::prelude::*;
use testkit::{assert_round_trip, XorShift};

fn positions(n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = XorShift(seed | 1);
    let mut next = move || rng.unit() * 2.0 - 1.0;
    (0..n).map(|_| [next(), next(), next()]).collect()
}

/// A `w x h` grid of quads split into triangles, some removed (holes), some flipped.
fn grid(w: usize, h: usize, holes: &[bool], flips: &[bool], offset: u32) -> Vec<[u32; 3]> {
    let id = |x: usize, y: usize| offset + (y * (w + 1) + x) as u32;
    let mut tris = vec![];
    for y in 0..h {
        for x in 0..w {
            let q = [id(x, y), id(x + 1, y), id(x + 1, y + 1), id(x, y + 1)];
            for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                let k = tris.len();
                if holes.get(k % holes.len().max(1)).copied().unwrap_or(false) {
                    tris.push(None);
                    continue;
                }
                let flip = flips.get(k % flips.len().max(1)).copied().unwrap_or(false);
                tris.push(Some(if flip { [t[0], t[2], t[1]] } else { t }));
            }
        }
    }
    tris.into_iter().flatten().collect()
}

fn shuffle<T>(v: &mut [T], seed: u64) {
    let mut rng = XorShift(seed | 1);
    for i in (1..v.len()).rev() {
        v.swap(i, (rng.next_u64() >> 33) as usize % (i + 1));
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    /// Arbitrary triangle soups: repeated, degenerate and inconsistently oriented triangles,
    /// unused vertices.
    #[test]
    fn random_soups(n in 3usize..40, tris in prop::collection::vec((0u32..40, 0u32..40, 0u32..40), 1..120),
                    seed: u64, bits in 8u8..=24) {
        let triangles = tris.into_iter().map(|(a, b, c)| [a % n as u32, b % n as u32, c % n as u32]).collect();
        let mesh = Mesh::new(positions(n, seed), triangles);
        assert_round_trip(&mesh, bits);
    }

    /// Grids with holes and flipped triangles, in shuffled order.
    #[test]
    fn grids_with_holes(w in 1usize..14, h in 1usize..14, holes in prop::collection::vec(prop::bool::weighted(0.15), 1..40),
                        flips in prop::collection::vec(prop::bool::weighted(0.05), 1..40), seed: u64) {
        let mut triangles = grid(w, h, &holes, &flips, 0);
        shuffle(&mut triangles, seed);
        let mesh = Mesh::new(positions((w + 1) * (h + 1), seed), triangles);
        assert_round_trip(&mesh, 16);
    }

    /// Fans around one shared, non-manifold vertex, plus non-manifold edges (three or more
    /// triangles on one edge).
    #[test]
    fn nonmanifold_fans(fans in prop::collection::vec(3usize..9, 1..6), closed in prop::collection::vec(any::<bool>(), 6),
                        fins in 0usize..4, seed: u64) {
        let mut triangles = vec![];
        let mut next = 1u32;
        for (f, &k) in fans.iter().enumerate() {
            let ring: Vec<u32> = (0..k as u32).map(|i| next + i).collect();
            next += k as u32;
            let segments = if closed[f] { k } else { k - 1 };
            for i in 0..segments {
                triangles.push([0, ring[i], ring[(i + 1) % k]]);
            }
        }
        // Fins: extra triangles on the edge (0, 1) make it non-manifold.
        for _ in 0..fins {
            triangles.push([0, 1, next]);
            next += 1;
        }
        shuffle(&mut triangles, seed);
        let mesh = Mesh::new(positions(next as usize, seed), triangles);
        assert_round_trip(&mesh, 12);
    }

    /// Many small components (grids and tetrahedra) with vertices in shuffled order.
    #[test]
    fn many_components(parts in prop::collection::vec((1usize..4, 1usize..4, any::<bool>()), 1..30), seed: u64) {
        let mut triangles = vec![];
        let mut n = 0u32;
        for &(w, h, tetra) in &parts {
            if tetra {
                let v = [n, n + 1, n + 2, n + 3];
                triangles.extend([[v[0], v[2], v[1]], [v[0], v[1], v[3]], [v[1], v[2], v[3]], [v[0], v[3], v[2]]]);
                n += 4;
            } else {
                triangles.extend(grid(w, h, &[false], &[false], n));
                n += ((w + 1) * (h + 1)) as u32;
            }
        }
        let mut perm: Vec<u32> = (0..n).collect();
        shuffle(&mut perm, seed);
        let triangles: Vec<[u32; 3]> = triangles.into_iter().map(|t| t.map(|v| perm[v as usize])).collect();
        let mesh = Mesh::new(positions(n as usize, seed), triangles);
        let enc = assert_round_trip(&mesh, 16);
        prop_assert_eq!(enc.header.components as usize, parts.len());
    }
}

#[test]
fn empty_and_tiny_meshes() {
    assert_round_trip(&Mesh::default(), 16);
    let one = Mesh::new(positions(3, 7), vec![[0, 1, 2]]);
    assert_round_trip(&one, 16);
    let degenerate = Mesh::new(positions(2, 7), vec![[0, 0, 1], [1, 1, 1]]);
    let enc = assert_round_trip(&degenerate, 16);
    assert_eq!(enc.stats.loose_triangles, 2);
    // All vertices at one point: a zero-extent bounding box.
    let flat = Mesh::new(vec![[1.0, 2.0, 3.0]; 4], vec![[0, 1, 2], [0, 2, 3]]);
    assert_round_trip(&flat, 16);
}
