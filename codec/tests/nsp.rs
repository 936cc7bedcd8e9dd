//! The nSP-tree store: the paper's partition, the lossless contract, vertex clustering at
//! every precision, view-dependent navigation and bad input.

use std::collections::HashMap;

use codec::nsp::{self, decode, Canonical, NspFile, Params};
use codec::Mesh;
use testkit;

fn build(mesh: &Mesh, params: Params) -> (Canonical, NspFile) {
    let canon = Canonical::of_mesh(mesh, params.bits).unwrap();
    let built = nsp::encode(&canon, params, &|_| {}).unwrap();
    (canon, NspFile::from_bytes(built.bytes).unwrap())
}

/// Triangles as position triples, rotated so the smallest comes first (orientation kept).
fn oriented_set(positions: &[[f32; 3]], tris: &[[u32; 3]]) -> Vec<[[u32; 3]; 3]> {
    let mut out: Vec<[[u32; 3]; 3]> = tris
        .iter()
        .map(|t| {
            let p = t.map(|i| positions[i as usize].map(f32::to_bits));
            let r = (0..3).min_by_key(|&r| p[r]).unwrap();
            [p[r], p[(r + 1) % 3], p[(r + 2) % 3]]
        })
        .collect();
    out.sort_unstable();
    out
}

/// The vertex clustering of a canonical complex on the `b`-bit grid: its triangles (first
/// occurrence's orientation), at the cells' centres.
fn clustering(canon: &Canonical, b: u8) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let shift = canon.cube.bits - b;
    let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
    let mut positions = Vec::new();
    let mut seen = std::collections::HashSet::new();
    let mut tris = Vec::new();
    let half = (1u64 << shift) as f64 * 0.5;
    let mut id = |q: [u32; 3]| {
        let g = q.map(|x| x >> shift);
        *ids.entry(g).or_insert_with(|| {
            positions.push(canon.cube.world(g.map(|x| ((x as u64) << shift) as f64 + half)));
            positions.len() as u32 - 1
        })
    };
    for s in canon.simplices.iter().filter(|s| s.dim == 2) {
        let t = s.v.map(|v| id(canon.points[v as usize]));
        if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
            let mut k = t;
            k.sort_unstable();
            if seen.insert(k) {
                tris.push(t);
            }
        }
    }
    (positions, tris)
}

fn small_params(bits: u8, min: u32) -> Params {
    Params { bits, root_bits: 4, splits: 4, min_simplices: min, advance: 0 }
}

#[test]
fn full_decode_is_the_canonical_complex_on_shared_meshes() {
    for rel in [
        "degenerate/all_degen.obj",
        "degenerate/fused_vertices.obj",
        "degenerate/non_manifold_face_graph.obj",
        "odedstein/cube.obj",
        "classic/suzanne.obj",
        "classic/teapot.obj",
        "stanford/dragon_vrip_res4.ply.gz",
        "stanford/bunny_zipper_c3d.obj.gz",
    ] {
        let mesh = testkit::load_mesh(rel);
        for (bits, min) in [(12u8, 200u32), (16, 1000)] {
            let (canon, file) = build(&mesh, small_params(bits, min));
            let drawn = decode::decode_all(&file).unwrap();
            let want = canon.to_mesh();
            assert_eq!(
                oriented_set(&drawn.positions, &drawn.triangles),
                oriented_set(&want.positions, &want.triangles),
                "{rel} at {bits} bits ({} cells)",
                file.tree.nodes.len()
            );
            let edges = canon.simplices.iter().filter(|s| s.dim == 1).count() as u64;
            let points = canon.simplices.iter().filter(|s| s.dim == 0).count() as u64;
            // Border duplicates of edges and points are counted once per cell holding them.
            assert!(drawn.edges >= edges && drawn.points >= points, "{rel}");
        }
    }
}

#[test]
fn every_uniform_precision_is_vertex_clustering() {
    let mesh = testkit::load_mesh("stanford/dragon_vrip_res4.ply.gz");
    let (canon, file) = build(&mesh, small_params(14, 300));
    assert!(file.tree.nodes.len() > 64, "the test needs a split tree");
    for b in 0..=14u8 {
        let drawn = decode::decode_uniform(&file, b).unwrap();
        let (pos, tris) = clustering(&canon, b);
        assert_eq!(oriented_set(&drawn.positions, &drawn.triangles), oriented_set(&pos, &tris), "at {b} bits");
    }
}

