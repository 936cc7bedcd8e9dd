//! The nSP-tree store: the paper's partition, the lossless contract, vertex clustering at
//! every precision, view-dependent navigation and bad input.

use std::collections::HashMap;

use codec::nsp::{self, decode, view, Canonical, NspFile, Params};
use codec::Mesh;

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
            let drawn = view::decode_all(&file).unwrap();
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
        let drawn = view::decode_uniform(&file, b).unwrap();
        let (pos, tris) = clustering(&canon, b);
        assert_eq!(oriented_set(&drawn.positions, &drawn.triangles), oriented_set(&pos, &tris), "at {b} bits");
    }
}

/// Table 1 of the paper: with p_r = 7 and n = 4, the dragon at 28 bits with N_min = 6000
/// makes 1,473 cells and the bunny at 16 bits with N_min = 5000 makes 65.
#[test]
fn the_papers_partition_is_reproduced() {
    for (rel, bits, min, cells) in
        [("stanford/bunny_zipper_c3d.obj.gz", 16u8, 5000u32, 65usize), ("stanford/dragon_vrip.ply.gz", 28, 6000, 1473)]
    {
        let mesh = testkit::load_mesh(rel);
        let canon = Canonical::of_mesh(&mesh, bits).unwrap();
        let params = Params { bits, root_bits: 7, splits: 4, min_simplices: min, advance: 0 };
        let part = nsp::tree::partition(params, &canon.points, &canon.simplices);
        assert_eq!(part.tree.nodes.len(), cells, "{rel}");
        if bits == 28 {
            // The paper's dragon has 871,306 triangles: ours merged at 28 bits.
            assert_eq!(canon.triangles(), 871_306);
        }
    }
}

fn views(file: &NspFile) -> Vec<view::View> {
    let c = &file.header.cube;
    let lo = [c.origin[0] as f32, c.origin[1] as f32, c.origin[2] as f32];
    let e = file.header.extent;
    let hi = [(c.origin[0] + e[0]) as f32, (c.origin[1] + e[1]) as f32, (c.origin[2] + e[2]) as f32];
    testkit::cameras_around(lo, hi, 4.0 / 3.0)
        .into_iter()
        .flat_map(|camera| [0.5f32, 4.0].map(|error_px| view::View { camera, width: 640, height: 480, error_px }))
        .collect()
}

#[test]
fn views_draw_each_triangle_once_and_coarsening_gives_back_the_same_state() {
    let mesh = testkit::load_mesh("stanford/armadillo_100k.obj.gz");
    for advance in [0, 2] {
        let (_, file) = build(&mesh, Params { bits: 16, root_bits: 5, splits: 4, min_simplices: 3000, advance });
        views_once_and_reversible(&file);
    }
}

fn views_once_and_reversible(file: &NspFile) {
    let mut nav = view::Navigator::default();
    let mut mixed = 0;
    for v in views(file) {
        let sel = view::select(file, &v);
        let precisions: std::collections::HashSet<u8> = sel.iter().map(|s| s.1).collect();
        mixed += (precisions.len() > 1) as usize;
        let drawn = view::draw(file, &sel, &nav.update(file, &sel).unwrap());
        let set = oriented_set(&drawn.positions, &drawn.triangles);
        let mut unoriented: Vec<_> = set
            .iter()
            .map(|t| {
                let mut t = *t;
                t.sort();
                t
            })
            .collect();
        unoriented.sort();
        let n = unoriented.len();
        unoriented.dedup();
        assert_eq!(unoriented.len(), n, "a triangle is drawn twice");
        assert!(drawn.triangles.len() > 100);
    }
    assert!(mixed >= 3, "the views must mix precisions");
    // Refine every drawn cell two bits, then coarsen back: the same complex.
    let sel = view::select(file, &views(file)[0]);
    let before = view::draw(file, &sel, &nav.update(file, &sel).unwrap());
    let finer: Vec<(u32, u8)> = sel.iter().map(|&(c, b)| (c, b + 2)).collect();
    let refined = view::draw(file, &finer, &nav.update(file, &finer).unwrap());
    assert!(refined.triangles.len() > before.triangles.len());
    let after = view::draw(file, &sel, &nav.update(file, &sel).unwrap());
    assert_eq!(oriented_set(&after.positions, &after.triangles), oriented_set(&before.positions, &before.triangles));
}

/// Edges used by exactly one drawn triangle (a closed input has none).
fn open_edges(d: &view::Drawn) -> usize {
    let mut count: HashMap<[[u32; 3]; 2], u32> = HashMap::new();
    for t in &d.triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let (pa, pb) = (d.positions[a as usize].map(f32::to_bits), d.positions[b as usize].map(f32::to_bits));
            *count.entry([pa.min(pb), pa.max(pb)]).or_default() += 1;
        }
    }
    count.values().filter(|&&c| c == 1).count()
}

/// The border rule on a closed model: every open edge of a mixed-precision drawing is
/// counted against the drawing at one precision (clustering can itself open edges, where a
/// triangle collapses to an edge); the figure is printed for the README.
#[test]
fn border_rule_cracks_are_counted_on_a_closed_model() {
    let mesh = testkit::load_mesh("stanford/bunny00_cgal_75k.obj.gz");
    for advance in [0, 2] {
        let (_, file) = build(&mesh, Params { bits: 16, root_bits: 5, splits: 4, min_simplices: 3000, advance });
        let full = view::decode_all(&file).unwrap();
        assert_eq!(open_edges(&full), 0, "the full decode of a closed mesh is closed");
        let mut nav = view::Navigator::default();
        for v in views(&file).iter().take(4) {
            let sel = view::select(&file, v);
            let d = view::draw(&file, &sel, &nav.update(&file, &sel).unwrap());
            let max = sel.iter().map(|s| s.1).max().unwrap();
            let uniform = view::decode_uniform(&file, max).unwrap();
            // With the advance a vertex is drawn where the cell it lies in puts it; only a
            // kd-cell spanning several cells (or outside every drawn one) can be drawn at two
            // positions, both inside it.
            let min = sel.iter().map(|s| s.1).min().unwrap();
            assert!(d.split_distance as f64 <= file.header.cube.side * 3f64.sqrt() / (1u64 << min) as f64);
            assert!(d.split_vertices as usize <= d.triangles.len() / 1000, "{} split vertices", d.split_vertices);
            eprintln!(
                "--advance {advance}: {} cells, precisions {min}..{max} bits: {} open edges (uniform at {max} bits: {}), \
                 {} triangles, {} stitched, {} vertices drawn at two positions (at most {:.2} kd-cells of {min} bits apart)",
                sel.len(),
                open_edges(&d),
                open_edges(&uniform),
                d.triangles.len(),
                d.stitched,
                d.split_vertices,
                d.split_distance as f64 / (file.header.cube.side / (1u64 << min) as f64)
            );
        }
    }
}

#[test]
fn damaged_files_name_the_problem() {
    let mesh = testkit::load_mesh("stanford/dragon_vrip_res4.ply.gz");
    let canon = Canonical::of_mesh(&mesh, 14).unwrap();
    // Without and with the geometry advance (its prologues and descendant lists decode
    // from the stream too).
    for advance in [0, 2] {
        damaged(nsp::encode(&canon, Params { advance, ..small_params(14, 300) }, &|_| {}).unwrap().bytes);
    }
}

/// Random cell streams behind valid tables (the fuzz target's second half, a few hundred
/// inputs in CI), with and without the geometry advance: an error or a decode whose
/// triangles index its vertices, never a panic.
#[test]
fn random_cell_streams_never_panic() {
    let mut rng = testkit::XorShift(11);
    let mut decoded = [0usize; 4];
    for i in 0..400u64 {
        let len = 1 + (rng.next_u64() % 300) as usize;
        let mut data: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
        data[0] = (i % 4) as u8;
        let file = NspFile::from_bytes(nsp::format::wrap_for_fuzzing(&data)).unwrap();
        for bits in [3u8, 10] {
            if let Ok(d) = view::decode_uniform(&file, bits) {
                let n = d.positions.len() as u32;
                assert!(d.triangles.iter().flatten().all(|&v| v < n));
                decoded[(i % 4) as usize] += 1;
            }
        }
    }
    eprintln!("decoded without error, by advance: {decoded:?}");
}

fn damaged(bytes: Vec<u8>) {
    let file = NspFile::from_bytes(bytes.clone()).unwrap();
    // A flipped byte inside a cell's stream: that cell is named.
    let (c, e) = file.entries.iter().enumerate().find(|(_, e)| e.len > 40).map(|(c, e)| (c, e.clone())).unwrap();
    let mut bad = bytes.clone();
    bad[e.offset as usize + 20] ^= 0x10;
    let err = view::decode_all(&NspFile::from_bytes(bad).unwrap()).unwrap_err().to_string();
    assert!(err.starts_with(&format!("cell {c}:")), "{err}");
    // Truncated, or a damaged header or table: refused when opened.
    for cut in [bytes.len() - 1, bytes.len() / 2, 10] {
        let err = NspFile::from_bytes(bytes[..cut].to_vec()).err().expect("refused").to_string();
        assert!(err.starts_with("not an .nsp file"), "{err}");
    }
    for pos in [12usize, 200, bytes.len() - 30] {
        let mut bad = bytes.clone();
        bad[pos] ^= 1;
        let err = NspFile::from_bytes(bad).err().expect("refused").to_string();
        assert!(err.contains("checksum") || err.contains("not an .nsp"), "{err}");
    }
    // Damage with the checksums made to match again (as a fuzzer would): an error or a
    // decode, never a panic or a hang.
    let mut rng = testkit::XorShift(5);
    let mut errors = 0;
    for _ in 0..300 {
        let mut bad = bytes.clone();
        let (start, len) = (e.offset as usize, e.len as usize);
        for _ in 0..1 + rng.next_u64() % 3 {
            bad[start + (rng.next_u64() % len as u64) as usize] = rng.next_u64() as u8;
        }
        nsp::format::refresh_checksums(&mut bad).unwrap();
        let f = NspFile::from_bytes(bad).unwrap();
        if let Err(err) = view::decode_all(&f) {
            assert!(err.to_string().starts_with("cell "), "{err}");
            errors += 1;
        }
    }
    assert!(errors > 0, "some damage must be caught");
}

/// The out-of-core builder writes the in-core builder's file byte for byte, with buckets cut
/// again and leaves batched (small limits), on PLY and OBJ files with polygons, repeated and
/// degenerate faces, holes and several components.
#[test]
fn the_out_of_core_build_writes_the_in_core_file() {
    let limits = nsp::ooc::Limits { bucket_records: 700, batch_records: 900 };
    for (rel, bits, min) in [
        ("stanford/dragon_vrip_res3.ply.gz", 14u8, 1500u32),
        ("stanford/bunny_zipper_c3d.obj.gz", 16, 5000),
        ("classic/suzanne.obj", 12, 200),
        ("degenerate/fused_vertices.obj", 10, 20),
        ("odedstein/sword-quad-dominant.obj.gz", 16, 3000),
    ] {
        let path = testkit::mesh_path(rel);
        let params = Params { bits, root_bits: 5, splits: 4, min_simplices: min, advance: 0 };
        let mesh = codec::load_path(&path).unwrap();
        let in_core = nsp::encode(&Canonical::of_mesh(&mesh, bits).unwrap(), params, &|_| {}).unwrap();
        let mut out = Vec::new();
        let built = nsp::ooc::build_file_with(&path, params, None, &mut out, &|_, _, _| {}, limits).unwrap();
        assert_eq!(built.bytes as usize, out.len());
        assert!(out == in_core.bytes, "{rel}: {} bytes out of core, {} in core", out.len(), in_core.bytes.len());
        assert_eq!(built.cells, in_core.tree.nodes.len());
    }
}

/// Triangles as the `b`-bit grid cells their corners lie in, rotated so the smallest comes
/// first (orientation kept).
fn cell_set(cube: &nsp::Cube, b: u8, positions: &[[f32; 3]], tris: &[[u32; 3]]) -> Vec<[[u32; 3]; 3]> {
    let cell = |i: u32| cube.quantize(positions[i as usize]).map(|x| x >> (cube.bits - b));
    let mut out: Vec<[[u32; 3]; 3]> = tris
        .iter()
        .map(|t| {
            let p = t.map(cell);
            let r = (0..3).min_by_key(|&r| p[r]).unwrap();
            [p[r], p[(r + 1) % 3], p[(r + 2) % 3]]
        })
        .collect();
    out.sort_unstable();
    out
}

/// Section 7's geometry advance: with `m` bits of advance the full decode is still the
/// canonical complex (the files differ), at every uniform precision `b` the connectivity is
/// still the vertex clustering at `b`, and a kd-cell inside the cell that holds it is drawn
/// at the mean of the centres of its non-empty descendants at `min(b + m, p)` bits.
#[test]
fn the_geometry_advance_draws_clustering_at_descendant_means_and_stays_lossless() {
    for rel in ["classic/suzanne.obj", "degenerate/non_manifold_face_graph.obj", "stanford/bunny_zipper_c3d.obj.gz"] {
        let mesh = testkit::load_mesh(rel);
        for m in [1u8, 3] {
            let (canon, file) = build(&mesh, Params { advance: m, ..small_params(12, 400) });
            let drawn = view::decode_all(&file).unwrap();
            let want = canon.to_mesh();
            assert_eq!(
                oriented_set(&drawn.positions, &drawn.triangles),
                oriented_set(&want.positions, &want.triangles),
                "{rel} with m = {m}"
            );
        }
    }
    let mesh = testkit::load_mesh("stanford/dragon_vrip_res4.ply.gz");
    let p = 14u8;
    let m = 2u8;
    let (canon, file) = build(&mesh, Params { advance: m, ..small_params(p, 300) });
    let (_, plain) = build(&mesh, small_params(p, 300));
    assert!(file.tree.nodes.len() > 64, "the test needs a split tree");
    assert!(file.tree.nodes == plain.tree.nodes, "the advance does not change the partition");
    let mut inside = 0usize;
    for b in 0..=p {
        let drawn = view::decode_uniform(&file, b).unwrap();
        let (pos, tris) = clustering(&canon, b);
        assert_eq!(
            cell_set(&canon.cube, b, &drawn.positions, &drawn.triangles),
            cell_set(&canon.cube, b, &pos, &tris),
            "connectivity at {b} bits"
        );
        // The descendants of each b-bit cell among all the model's points.
        let f = (b + m).min(p);
        let mut desc: HashMap<[u32; 3], Vec<[u32; 3]>> = HashMap::new();
        for q in &canon.points {
            desc.entry(q.map(|x| x >> (p - b))).or_default().push(q.map(|x| x >> (p - f)));
        }
        for s in decode::decode_uniform_states(&file, b).unwrap() {
            for &v in &s.cx.order {
                let kd = &s.cx.cells[v as usize];
                let full = kd.xyz.map(|x| x << (p - b));
                if !file.tree.contains(s.cell, full, p) {
                    continue;
                }
                let mut d = desc[&kd.xyz].clone();
                d.sort_unstable();
                d.dedup();
                let unit = (1u64 << (p - f)) as f64;
                let mean =
                    [0, 1, 2].map(|a| d.iter().map(|g| (g[a] as f64 + 0.5) * unit).sum::<f64>() / d.len() as f64);
                let got = s.cx.position(v, p);
                for a in 0..3 {
                    assert!((got[a] - mean[a]).abs() < 1e-6, "cell {} at {b} bits: {got:?} != {mean:?}", s.cell);
                }
                inside += 1;
            }
        }
    }
    assert!(inside > 10_000, "{inside} kd-cells checked");
}

/// The out-of-core builder writes the in-core file with the geometry advance too (its
/// children hand their parents points `m` bits finer).
#[test]
fn the_out_of_core_build_writes_the_in_core_file_with_the_advance() {
    let limits = nsp::ooc::Limits { bucket_records: 700, batch_records: 900 };
    for (rel, bits, min, m) in
        [("stanford/dragon_vrip_res3.ply.gz", 14u8, 1500u32, 2u8), ("classic/suzanne.obj", 12, 200, 3)]
    {
        let path = testkit::mesh_path(rel);
        let params = Params { bits, root_bits: 5, splits: 4, min_simplices: min, advance: m };
        let mesh = codec::load_path(&path).unwrap();
        let in_core = nsp::encode(&Canonical::of_mesh(&mesh, bits).unwrap(), params, &|_| {}).unwrap();
        let mut out = Vec::new();
        nsp::ooc::build_file_with(&path, params, None, &mut out, &|_, _, _| {}, limits).unwrap();
        assert!(out == in_core.bytes, "{rel}: {} bytes out of core, {} in core", out.len(), in_core.bytes.len());
    }
}

/// A worker's cells arrive in steps: a cell first drawn at its minimal precision (no bytes
/// of its stream held), later refined when its next segments arrive, decodes exactly as the
/// whole file does. (A decoder started over no bytes used to read zeros ahead, and resuming
/// it decoded from them: "truncated stream" on the next frame.)
#[test]
fn cells_refined_as_their_segments_arrive_decode_as_the_whole_file() {
    let mesh = codec::load_path(&testkit::mesh_path("stanford/bunny_oded_6k.obj")).unwrap();
    let (_, whole) = build(&mesh, small_params(12, 800));
    let mut parts = NspFile::from_skeleton(whole.skeleton().to_vec()).unwrap();
    let tree = &whole.tree;
    let leaves: Vec<u32> =
        (0..tree.nodes.len() as u32).filter(|&c| tree.is_leaf(c) && whole.entries[c as usize].len > 0).collect();
    assert!(leaves.len() > 4, "the bunny is cut into cells");
    let mut held: HashMap<u32, u32> = HashMap::new();
    let mut nav = view::Navigator::default();
    let mut fresh = view::Navigator::default();
    // Every leaf at its minimal precision, then one bit more at a time up to the full one.
    let max = leaves.iter().map(|&c| tree.max_prec(c)).max().unwrap();
    for step in 0..=max {
        let cut: Vec<(u32, u8)> =
            leaves.iter().map(|&c| (c, tree.min_prec(c).max(step.min(tree.max_prec(c))))).collect();
        let mut need: Vec<(u32, u8)> = cut.clone();
        for &(c, _) in &cut {
            let mut a = tree.nodes[c as usize].parent;
            while a != u32::MAX {
                need.push((a, tree.max_prec(a)));
                a = tree.nodes[a as usize].parent;
            }
        }
        for (c, b) in need {
            let upto = whole.needed(c, b);
            let have = held.entry(c).or_insert(0);
            if upto > *have {
                parts.receive(c, *have, whole.cell_range(c, *have, upto).unwrap()).unwrap();
                *have = upto;
            }
        }
        let got = view::draw(&parts, &cut, &nav.update(&parts, &cut).unwrap());
        let want = view::draw(&whole, &cut, &fresh.update(&whole, &cut).unwrap());
        assert_eq!(got.triangles.len(), want.triangles.len(), "step {step}");
        assert_eq!(oriented_set(&got.positions, &got.triangles), oriented_set(&want.positions, &want.triangles));
        fresh = view::Navigator::default();
    }
}
