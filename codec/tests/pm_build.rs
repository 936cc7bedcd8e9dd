//! The progressive mesh builder: refining through every split gives back the input triangles
//! exactly (multiset, orientation) for every shared mesh and random triangle soups; the FVIDs
//! are a permutation; every intermediate level is a consistent mesh over the active vertices.

use std::time::Instant;

use codec::pm::{build, build_owned, build_with_options, refine_all, BuildOptions, PmError, ProgressiveMesh, Refiner};
use codec::{Mesh, MeshError};
use proptest::prelude::*;
use testkit::{all_shared_meshes, shared_meshes, sorted_canonical, soup};

fn all_same(t: [u32; 3]) -> bool {
    t[0] == t[1] && t[1] == t[2]
}

fn repeats(t: [u32; 3]) -> bool {
    t[0] == t[1] || t[1] == t[2] || t[0] == t[2]
}

/// Builds and checks everything that holds for any input: FVIDs, positions, the base mesh,
/// the split records, and the exact round trip through `refine_all`.
fn build_and_check(mesh: &Mesh) -> ProgressiveMesh {
    check(mesh, build(mesh).expect("builds"))
}

/// As [`build_and_check`] for a build in chunks of at most `chunk_faces`; also returns the
/// number of chunks.
fn build_chunked_and_check(mesh: &Mesh, chunk_faces: usize) -> (ProgressiveMesh, usize) {
    let (pm, stats) = build_with_options(mesh, BuildOptions { chunk_faces }, &mut |_, _| {}).expect("builds");
    (check(mesh, pm), stats.chunks)
}

fn check(mesh: &Mesh, pm: ProgressiveMesh) -> ProgressiveMesh {
    let used = mesh.used_vertices();
    let n_used = used.iter().filter(|&&u| u).count();

    // FVIDs: a permutation of 0..used over the used vertices; positions follow them.
    assert_eq!(pm.fvid_of_input.len(), mesh.positions.len());
    assert_eq!(pm.positions.len(), n_used);
    let mut input_of_fvid = vec![u32::MAX; n_used];
    for (v, &f) in pm.fvid_of_input.iter().enumerate() {
        if !used[v] {
            assert_eq!(f, u32::MAX, "unused vertex {v} has an FVID");
            continue;
        }
        assert!((f as usize) < n_used, "FVID {f} out of range");
        assert_eq!(input_of_fvid[f as usize], u32::MAX, "FVID {f} given twice");
        input_of_fvid[f as usize] = v as u32;
        assert_eq!(pm.positions[f as usize], mesh.positions[v]);
    }

    // Collapses run until no edge is left: at least one base vertex per component (the last
    // faces of a component vanish with their edges), and the base faces are the input faces
    // that never had two distinct vertices.
    assert!(pm.base_vertices.windows(2).all(|w| w[0] < w[1]), "base vertices not ascending");
    assert!(pm.base_vertices.len() >= mesh.components());
    assert_eq!(pm.base_faces.len(), mesh.triangles.iter().filter(|t| all_same(**t)).count());
    assert_eq!(pm.base_vertices.len() + pm.splits.len(), n_used);
    for s in &pm.splits {
        assert!(s.v < s.v_u, "split {} -> {}: v_u must follow v", s.v, s.v_u);
        assert!(!s.faces.is_empty(), "split {} -> {} creates no face", s.v, s.v_u);
    }
    assert_eq!(pm.base_faces.len() + pm.splits.iter().map(|s| s.faces.len()).sum::<usize>(), mesh.triangles.len());

    let back = refine_all(&pm).into_iter().map(|t| t.map(|f| input_of_fvid[f as usize]));
    assert!(
        sorted_canonical(back) == sorted_canonical(mesh.triangles.iter().copied()),
        "refined triangles differ from the input"
    );
    pm
}

/// Walks every level from the base mesh up: the split vertex is active and `v_u` is not, every
/// face references active vertices only, a face repeats an index only if its input triangle
/// did, and the FVID rule agrees with replaying the collapses themselves.
fn check_every_level(pm: &ProgressiveMesh) {
    let n = pm.positions.len();
    let mut r = Refiner::new(pm);
    let mut finest: Vec<[u32; 3]> = pm.base_faces.clone();
    loop {
        let k = r.applied();
        // Independent replay: after k splits, the collapses of splits[k..] are in effect, and
        // `v_u -> v` chains lead every finest vertex to its active vertex.
        let mut parent = vec![u32::MAX; n];
        for s in &pm.splits[k..] {
            parent[s.v_u as usize] = s.v;
        }
        let rep = |mut f: u32| {
            while parent[f as usize] != u32::MAX {
                f = parent[f as usize];
            }
            f
        };
        let current = r.current_faces();
        assert_eq!(current.len(), finest.len());
        for (c, f) in current.iter().zip(&finest) {
            assert!(c.iter().all(|&v| r.is_active(v)), "level {k}: face {c:?} uses an inactive vertex");
            assert_eq!(*c, f.map(rep), "level {k}: FVID rule disagrees with the collapses");
            assert!(!repeats(*c) || repeats(*f), "level {k}: face {f:?} became degenerate as {c:?}");
        }
        let Some(s) = pm.splits.get(k) else { break };
        assert!(r.is_active(s.v) && !r.is_active(s.v_u), "split {k}: {} -> {}", s.v, s.v_u);
        assert!(r.split_next());
        finest.extend_from_slice(&s.faces);
    }
    assert!(!r.split_next());
}

#[test]
fn every_shared_mesh_refines_back_to_its_input() {
    let files = all_shared_meshes();
    assert!(files.len() >= 50, "expected the whole shared mesh set, found {}", files.len());
    for path in files {
        let mesh = codec::load_path(&path).unwrap_or_else(|e| panic!("{e}"));
        let name = path.strip_prefix(shared_meshes()).unwrap_or(&path).display().to_string();
        // The 871k-triangle dragon runs in the ignored speed test.
        if mesh.triangles.len() > 300_000 {
            eprintln!("{name:<45} skipped ({} triangles)", mesh.triangles.len());
            continue;
        }
        let start = Instant::now();
        let pm = build_and_check(&mesh);
        eprintln!(
            "{name:<45} {:>7} tris {:>7} splits, base {} vertices {} faces ({:.2}s)",
            mesh.triangles.len(),
            pm.splits.len(),
            pm.base_vertices.len(),
            pm.base_faces.len(),
            start.elapsed().as_secs_f64()
        );
        if mesh.triangles.len() <= 1000 {
            check_every_level(&pm);
        }
    }
}

#[test]
fn tetrahedron_ends_as_two_vertices_and_no_faces() {
    // The first collapse removes two faces and leaves the other two on one edge; collapsing
    // that edge removes both, and with them the last edge: two base vertices remain.
    let mesh = Mesh {
        positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        triangles: vec![[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]],
        ..Default::default()
    };
    let pm = build_and_check(&mesh);
    assert_eq!((pm.base_vertices.len(), pm.base_faces.len(), pm.splits.len()), (2, 0, 2));
    assert!(pm.splits.iter().all(|s| s.faces.len() == 2));
    check_every_level(&pm);
}

#[test]
fn degenerate_and_duplicate_triangles_are_kept() {
    let mesh = Mesh {
        positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [f32::NAN; 3], [0.0, 0.0, 1.0], [5.0; 3]],
        triangles: vec![
            [0, 1, 2],
            [0, 1, 2],
            [2, 1, 0],
            [0, 0, 1],
            [4, 4, 4],
            [4, 4, 4],
            [5, 5, 5],
            [0, 1, 4],
            [1, 0, 4],
            [0, 1, 5],
        ],
        ..Default::default()
    };
    let pm = build_and_check(&mesh);
    assert_eq!(pm.fvid_of_input[3], u32::MAX);
    assert_eq!(pm.base_faces.len(), 3);
    check_every_level(&pm);
}

#[test]
fn empty_mesh_builds_an_empty_progressive_mesh() {
    let pm = build_and_check(&Mesh::new(vec![[0.0; 3]], vec![]));
    assert_eq!(pm, ProgressiveMesh { fvid_of_input: vec![u32::MAX], ..Default::default() });
    assert!(refine_all(&pm).is_empty());
}

#[test]
fn invalid_input_is_an_error() {
    let bad_index = Mesh::new(vec![[0.0; 3]; 3], vec![[0, 1, 3]]);
    assert_eq!(
        build(&bad_index),
        Err(PmError::Mesh(MeshError::IndexOutOfRange { triangle: 0, index: 3, vertices: 3 }))
    );
    let nan = Mesh::new(vec![[0.0; 3], [0.0, f32::INFINITY, 0.0], [1.0; 3]], vec![[0, 1, 2]]);
    assert!(matches!(build(&nan), Err(PmError::Mesh(MeshError::NonFinite { vertex: 1, .. }))));
}

/// Vertices of high valence become hubs (see `codec::pm::build`), which changes how they
/// collapse; the results must hold as for any mesh: a closed cone (two hubs), a hub edge shared
/// by many faces, and random non-manifold triangles around one vertex with degenerate ones.
#[test]
fn hubs_refine_back_to_their_input() {
    use codec::pm::{build_with_stats, HUB_FACES};
    let k = HUB_FACES + 100;
    let ring = |i: usize| {
        let a = i as f32 / k as f32 * std::f32::consts::TAU;
        [a.cos(), a.sin(), 0.1 * (3.0 * a).sin()]
    };
    // Apex 0, base centre 1, rim 2..k+2.
    let mut cone = Mesh::new(vec![[0.0, 0.0, 1.0], [0.0, 0.0, -0.2]], vec![]);
    cone.positions.extend((0..k).map(ring));
    for i in 0..k as u32 {
        let (a, b) = (2 + i, 2 + (i + 1) % k as u32);
        cone.triangles.push([0, a, b]);
        cone.triangles.push([1, b, a]);
    }
    // Vertices 0 and 1 share k faces, and 0 has a fan too.
    let mut shared = Mesh::new(vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], vec![]);
    shared.positions.extend((0..k).map(ring));
    for i in 0..k as u32 {
        shared.triangles.push([0, 1, 2 + i]);
        if i + 1 < k as u32 {
            shared.triangles.push([0, 2 + i, 3 + i]);
        }
    }
    // Random triangles around vertex 0 from 300 others, some degenerate, some repeated.
    let mut rng = testkit::XorShift(0x9e37_79b9_7f4a_7c15);
    let mut soup = Mesh::new(vec![[0.0; 3]], vec![]);
    soup.positions.extend((0..300).map(|_| [rng.unit(), rng.unit(), rng.unit()]));
    for _ in 0..2 * k {
        let (a, b) = (1 + rng.next_u64() as u32 % 300, 1 + rng.next_u64() as u32 % 300);
        soup.triangles.push(match rng.next_u64() % 16 {
            0 => [0, 0, a],
            1 => [a, a, a],
            _ => [0, a, b],
        });
    }
    for (name, mesh) in [("cone", &cone), ("shared edge", &shared), ("soup", &soup)] {
        let (_, stats) = build_with_stats(mesh, &mut |_, _| {}).expect("builds");
        assert!(stats.hubs >= 1, "{name}: no hub");
        let pm = build_and_check(mesh);
        check_every_level(&pm);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn random_soups_refine_back_to_their_input(mesh in soup()) {
        let pm = build_and_check(&mesh);
        check_every_level(&pm);
    }

    #[test]
    fn random_soups_built_in_chunks_refine_back_to_their_input(mesh in soup(), chunk_faces in 1usize..24) {
        let (pm, chunks) = build_chunked_and_check(&mesh, chunk_faces);
        prop_assert_eq!(chunks > 1, mesh.triangles.len() > chunk_faces);
        check_every_level(&pm);
    }
}

/// A model simplified in chunks (borders locked until the chunks merge) is a valid
/// progressive mesh: every level is consistent and refining gives back the input exactly,
/// on scans with holes, non-manifold and degenerate meshes, in chunks small enough that
/// most of the model's vertices sit on a chunk border at some point.
#[test]
fn meshes_built_in_chunks_refine_back_to_their_input() {
    for (rel, chunk_faces) in [
        ("stanford/bunny_npm_lowres.obj", 64),
        ("odedstein/plane_holes.obj.gz", 500),
        ("classic/beetle.obj", 1000),
        ("degenerate/non_manifold_face_graph.obj", 16),
        ("stanford/bunny_zipper_c3d.obj.gz", 4096),
    ] {
        let mesh = codec::load_path(&shared_meshes().join(rel)).unwrap_or_else(|e| panic!("{e}"));
        let (pm, chunks) = build_chunked_and_check(&mesh, chunk_faces);
        let whole = build_with_options(&mesh, BuildOptions { chunk_faces: 0 }, &mut |_, _| {}).unwrap().0;
        eprintln!(
            "{rel}: {} triangles in {chunks} chunks of at most {chunk_faces}: base {} vertices (whole: {})",
            mesh.triangles.len(),
            pm.base_vertices.len(),
            whole.base_vertices.len()
        );
        assert!(chunks >= 2 * mesh.triangles.len() / chunk_faces - 1, "{rel}: {chunks} chunks");
        assert_ne!(pm.splits, whole.splits, "{rel}: the chunked build equals the whole one");
        // Sibling chunks run in parallel; the result does not depend on how many threads
        // there are or how they interleave.
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let again = pool.install(|| build_with_options(&mesh, BuildOptions { chunk_faces }, &mut |_, _| {}));
            assert!(again.unwrap().0 == pm, "{rel}: the chunked build differs on {threads} threads");
        }
        if mesh.triangles.len() <= 2000 {
            check_every_level(&pm);
        }
        // What `tessera pm build` runs: the builder that takes the mesh and frees it early.
        let owned = build_owned(mesh, BuildOptions { chunk_faces }, &mut |_, _| {}).unwrap().0;
        assert!(owned == pm, "{rel}: the build that takes the mesh differs");
    }
}

/// The speed figure: `cargo test -p tessera-codec --release --test pm_build -- --ignored --nocapture`.
#[test]
#[ignore = "builds the 871k-triangle dragon; run in release"]
fn dragon_speed() {
    let mesh = codec::load_path(&shared_meshes().join("stanford/dragon_vrip.ply.gz")).unwrap();
    let start = Instant::now();
    let pm = build(&mesh).unwrap();
    let secs = start.elapsed().as_secs_f64();
    eprintln!(
        "dragon: {} tris, {} collapses in {:.2}s = {:.0} ops/s; base {} vertices {} faces",
        mesh.triangles.len(),
        pm.splits.len(),
        secs,
        pm.splits.len() as f64 / secs,
        pm.base_vertices.len(),
        pm.base_faces.len()
    );
    let start = Instant::now();
    build_and_check(&mesh);
    eprintln!("dragon: build + full round-trip check in {:.2}s", start.elapsed().as_secs_f64());
}
