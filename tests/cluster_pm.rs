//! End-to-end tests of progressive meshes (`.dpm`) under `mpirun`: tiles against the full
//! mesh's frame (no cracks at tile borders), one adaptation per worker whatever its tiles,
//! out-of-core files within a graphics memory budget, occlusion culling, bad files.

mod common;

use std::path::Path;

use common::{alone, covered, identical, mpirun, ok, pixels, reference};
use testkit::mesh_arg as mesh;

/// Compares a progressive-mesh render with the full mesh's: the fraction of pixels covered in
/// either image that are covered in both and within `tolerance` in every channel.
fn matching_fraction(a: &Path, b: &Path, tolerance: u8) -> (f64, usize) {
    let (pa, pb) = (pixels(a), pixels(b));
    assert_eq!((pa.0, pa.1), (pb.0, pb.1));
    let (mut covered, mut matching) = (0usize, 0usize);
    for (x, y) in pa.2.chunks(4).zip(pb.2.chunks(4)) {
        if x[3] == 0 && y[3] == 0 {
            continue;
        }
        covered += 1;
        if x[3] == y[3] && x.iter().zip(y).all(|(u, v)| u.abs_diff(*v) <= tolerance) {
            matching += 1;
        }
    }
    (matching as f64 / covered.max(1) as f64, covered)
}

/// Pixels of `a` along the interior tile borders of a `cols x rows` grid (the columns and rows
/// on both sides of each border) that are uncovered while `b` covers them: cracks.
fn border_holes(a: &Path, b: &Path, cols: u32, rows: u32) -> usize {
    let ((w, h, pa), (_, _, pb)) = (pixels(a), pixels(b));
    let grid = codec::view::TileGrid::new(w, h, cols, rows).unwrap();
    let mut lines_x = Vec::new();
    let mut lines_y = Vec::new();
    for i in 0..grid.tiles() {
        let [x0, y0, _, _] = grid.tile_rect(i);
        if x0 > 0 {
            lines_x.extend([x0 - 1, x0]);
        }
        if y0 > 0 {
            lines_y.extend([y0 - 1, y0]);
        }
    }
    let hole = |x: u32, y: u32| {
        let k = 4 * (y * w + x) as usize;
        pa[k + 3] == 0 && pb[k + 3] == 255
    };
    let mut n = 0;
    for y in 0..h {
        for x in 0..w {
            if (lines_x.contains(&x) || lines_y.contains(&y)) && hole(x, y) {
                n += 1;
            }
        }
    }
    n
}

#[test]
fn progressive_mesh_tiles_match_the_full_mesh() {
    let dir = tempfile::tempdir().unwrap();
    type Case = (usize, &'static str, Vec<&'static str>);
    let models: [(&str, &str, Vec<Case>); 2] = [
        (
            "stanford/bunny_zipper_c3d.obj.gz",
            "960x540",
            vec![(2, "4x3", vec![]), (3, "3x2", vec!["--balance", "--frames", "2", "--no-frame-reuse"])],
        ),
        ("stanford/dragon_vrip.ply.gz", "1920x1080", vec![(2, "8x8", vec![])]),
    ];
    for (rel, size, cases) in models {
        let model = mesh(rel);
        let dpm = dir.path().join("model.dpm");
        ok(&alone(&["pm", "build", &model, "-o", dpm.to_str().unwrap()]));
        let reference = reference(&model, size, dir.path());
        let full = codec::load_path(std::path::Path::new(&model)).unwrap().triangles.len() as u64;
        for (np, tiles, extra) in cases {
            let out = dir.path().join("pm.png");
            let stats = dir.path().join("pm.jsonl");
            let mut args = vec!["render", dpm.to_str().unwrap(), "--size", size, "--tiles", tiles, "--error-px", "0.5"];
            args.extend(["--out", out.to_str().unwrap(), "--stats", stats.to_str().unwrap()]);
            args.extend(&extra);
            ok(&mpirun(np, &[], &args));
            let produced = if extra.contains(&"--frames") { dir.path().join("pm-0002.png") } else { out.clone() };
            let (fraction, covered) = matching_fraction(&produced, &reference, 8);
            eprintln!("{rel} -np {np} --tiles {tiles}: {covered} covered pixels, {fraction:.4} match within 8/255");
            assert!(covered > 10_000, "{rel}: the model is in view");
            assert!(fraction >= 0.99, "{rel} -np {np} --tiles {tiles}: only {fraction:.4} of covered pixels match");
            // Each worker adapts one mesh for all of its tiles: refined in its region, coarse
            // outside, so every tile of a worker has that mesh's triangle count, under the
            // full mesh's.
            let line: serde_json::Value =
                serde_json::from_str(std::fs::read_to_string(&stats).unwrap().lines().next().unwrap()).unwrap();
            let mut by_worker: std::collections::BTreeMap<u64, Vec<u64>> = Default::default();
            for t in line["tiles"].as_array().unwrap() {
                by_worker.entry(t["worker"].as_u64().unwrap()).or_default().push(t["triangles"].as_u64().unwrap());
            }
            assert_eq!(by_worker.len(), np - 1, "{rel}: every worker has tiles");
            for counts in by_worker.values() {
                assert!(counts.iter().all(|&t| t == counts[0] && t < full), "{rel}: {by_worker:?} against {full}");
            }
            let (c, r) = tiles.split_once('x').unwrap();
            let holes = border_holes(&produced, &reference, c.parse().unwrap(), r.parse().unwrap());
            assert_eq!(holes, 0, "{rel} -np {np} --tiles {tiles}: {holes} uncovered pixels at tile borders");
        }
    }
}

/// A worker adapts one mesh for all of its tiles, so one worker's frame does not depend on
/// how the frame is cut: 6x4 tiles give the 1x1 frame pixel for pixel (the model's box lies
/// inside the reached tiles, so both adapt to the same refinement).
#[test]
fn one_worker_adapts_once_whatever_its_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let dpm = dir.path().join("model.dpm");
    ok(&alone(&["pm", "build", &mesh("stanford/bunny_zipper_c3d.obj.gz"), "-o", dpm.to_str().unwrap()]));
    let mut frames = Vec::new();
    for tiles in ["1x1", "6x4"] {
        let out = dir.path().join(format!("t{tiles}.png"));
        let stats = dir.path().join(format!("t{tiles}.jsonl"));
        let args = ["render", dpm.to_str().unwrap(), "--size", "960x540", "--tiles", tiles, "--frames", "2", "--orbit"];
        ok(&mpirun(
            2,
            &[],
            &[&args[..], &["--out", out.to_str().unwrap(), "--stats", stats.to_str().unwrap()]].concat(),
        ));
        let line: serde_json::Value =
            serde_json::from_str(std::fs::read_to_string(&stats).unwrap().lines().next().unwrap()).unwrap();
        let counts: Vec<u64> =
            line["tiles"].as_array().unwrap().iter().map(|t| t["triangles"].as_u64().unwrap()).collect();
        assert!(counts.iter().all(|&c| c == counts[0]), "{tiles}: one mesh for every tile, {counts:?}");
        frames.push(pixels(&dir.path().join(format!("t{tiles}-0002.png"))));
    }
    assert!(covered(&dir.path().join("t1x1-0002.png")) > 10_000, "the model is in view");
    assert!(frames[0] == frames[1], "6x4 tiles differ from 1x1");
}

/// Out-of-core progressive meshes (`pm build --node-kb`): each worker reads the file's nodes
/// itself. With a budget whose node pool (a quarter) holds every node the frames equal the
/// in-core file's pixel for pixel; with a pool of a third of the nodes (`--gpu-nodes-mb`) the
/// stats show the slots full, node traffic in every frame and fewer triangles, and the frame
/// still covers the model. A budget too small for the mesh at the frame's error keeps every
/// frame's graphics memory within it, at a raised error (the stats' `error_scale`, a note).
/// A corrupt node stops the run in one line that names it, and no image is written.
#[test]
fn out_of_core_progressive_meshes_render_within_the_budget() {
    let dir = tempfile::tempdir().unwrap();
    let bunny = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let (incore, ooc) = (dir.path().join("in.dpm"), dir.path().join("ooc.dpm"));
    ok(&alone(&["pm", "build", &bunny, "-o", incore.to_str().unwrap()]));
    ok(&alone(&["pm", "build", &bunny, "-o", ooc.to_str().unwrap(), "--node-kb", "4"]));
    // A close orbit: the bunny's box is larger than the frame. The near and far planes are
    // given: by default they follow the model's box, which an out-of-core file bounds by its
    // nodes' boxes cut to the quantization grid, not the in-core vertices' box.
    let camera = ["--eye", "0,0.12,0.08", "--target", "-0.02,0.1,0", "--near", "0.01", "--far", "1"];
    let view = [&["--size", "960x540", "--tiles", "4x2"][..], &camera].concat();
    let render = |model: &Path, name: &str, budget: &[&str]| {
        let (out, stats) = (dir.path().join(format!("{name}.png")), dir.path().join(format!("{name}.jsonl")));
        let args = [&[model.to_str().unwrap(), "--frames", "3", "--orbit", "--gpu-budget-mb"][..], budget].concat();
        let o = mpirun(
            2,
            &[],
            &[&["render"][..], &args, &view, &["--out", out.to_str().unwrap(), "--stats", stats.to_str().unwrap()]]
                .concat(),
        );
        ok(&o);
        let noted = String::from_utf8_lossy(&o.stderr).contains("to keep its mesh within --gpu-budget-mb");
        let lines: Vec<serde_json::Value> = std::fs::read_to_string(&stats)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .filter(|l: &serde_json::Value| l["rank"] == 1)
            .collect();
        assert_eq!(lines.len(), 3, "{name}: a worker line per frame");
        (lines, noted)
    };
    let (a, _) = render(&incore, "in", &["512"]);
    let (b, _) = render(&ooc, "all", &["64"]);
    let (c, _) = render(&ooc, "third", &["64", "--gpu-nodes-mb", "0.12"]);
    // Every node (191 of 4 kB) in a 1 MB pool, and 2 MB for the tables and a mesh that at
    // 0.5 px takes about 2.6 MB.
    let (d, noted) = render(&ooc, "tight", &["3", "--gpu-nodes-mb", "1"]);
    for k in 1..=3 {
        let f = |name: &str| dir.path().join(format!("{name}-{k:04}.png"));
        assert!(identical(&f("in"), &f("all")), "frame {k}: the out-of-core frame differs from the in-core one");
        assert!(covered(&f("third")) * 10 > covered(&f("in")) * 9, "frame {k}: a third of the nodes covers the model");
    }
    let tri = |l: &serde_json::Value| l["tiles"][0]["triangles"].as_u64().unwrap();
    for k in 0..3 {
        let (pa, pb, pc) = (&a[k]["pm"], &b[k]["pm"], &c[k]["pm"]);
        assert_eq!(pa["node_slots"], 0, "in core: no nodes");
        assert_eq!(pb["resident_nodes"], pb["node_slots"], "frame {k}: every node fits 1 MB");
        let slots = pc["node_slots"].as_u64().unwrap();
        assert!(slots > 0 && pc["resident_nodes"].as_u64().unwrap() <= slots);
        assert!(pc["required_nodes"].as_u64().unwrap() > slots, "frame {k}: the view requires more than the budget");
        assert!(pc["loaded_bytes"].as_u64().unwrap() > 0, "frame {k}: nodes come in as the view turns");
        assert!(pc["gpu_bytes"].as_u64().unwrap() > 0);
        assert!(tri(&c[k]) < tri(&b[k]), "frame {k}: fewer triangles within the smaller budget");
        for (l, budget) in [(&a[k], 512), (&b[k], 64), (&c[k], 64), (&d[k], 3)] {
            let bytes = l["pm"]["gpu_bytes"].as_u64().unwrap();
            assert!(bytes <= budget << 20, "frame {k}: {bytes} bytes of graphics memory, budget {budget} MB");
        }
        for l in [&a[k], &b[k], &c[k]] {
            assert_eq!(l["pm"]["error_scale"], 1.0, "frame {k}: the mesh fits the budget at its error");
        }
        let scale = d[k]["pm"]["error_scale"].as_f64().unwrap();
        assert!(scale > 1.0 && tri(&d[k]) < tri(&b[k]), "frame {k}: 3 MB holds a coarser mesh ({scale}x the error)");
    }
    assert!(noted, "a note says the tight budget coarsened the mesh");
    // A byte of a node flipped: its checksum fails when a worker reads it.
    let mut bytes = std::fs::read(&ooc).unwrap();
    let at = bytes.len() - 100;
    bytes[at] ^= 0x40;
    let bad = dir.path().join("bad.dpm");
    std::fs::write(&bad, &bytes).unwrap();
    let out = dir.path().join("bad.png");
    let o =
        mpirun(2, &[], &[&["render", bad.to_str().unwrap()][..], &view, &["--out", out.to_str().unwrap()]].concat());
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    let line = err.lines().find(|l| l.contains("checksum mismatch")).unwrap_or_else(|| panic!("{err}"));
    assert!(line.contains("corrupt .dpm data: node ") && line.contains("rank 1"), "{line}");
    assert!(!out.exists() && !dir.path().join("bad-0001.png").exists(), "no image is written");
    // A budget that holds no node is refused by rank 0, before any worker starts.
    let o = alone(
        &[&["render", ooc.to_str().unwrap(), "--gpu-budget-mb", "0.001"][..], &view, &["--out", out.to_str().unwrap()]]
            .concat(),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("holds no node") && !err.contains("ready"), "{err}");
    assert!(!out.exists());
}

/// `render --occlusion`: each worker culls what its last frame hid. Along a slow orbit of the
/// bunny seen from its side, the frames after the first adapt fewer triangles and match the
/// unculled frames for at least 99% of their covered pixels within 8/255 (the dragon seen
/// down its length: 31% fewer triangles, in the README).
#[test]
fn occlusion_culling_in_cluster_frames() {
    let dir = tempfile::tempdir().unwrap();
    let dpm = dir.path().join("bunny.dpm");
    ok(&alone(&["pm", "build", &mesh("stanford/bunny_zipper_c3d.obj.gz"), "-o", dpm.to_str().unwrap()]));
    let mut runs = Vec::new();
    for occlusion in [false, true] {
        let name = if occlusion { "occ" } else { "all" };
        let (out, stats) = (dir.path().join(format!("{name}.png")), dir.path().join(format!("{name}.jsonl")));
        let mut args = vec![
            "render",
            dpm.to_str().unwrap(),
            "--size",
            "960x540",
            "--tiles",
            "2x2",
            "--frames",
            "3",
            "--orbit",
            "--orbit-degrees",
            "6",
            "--view",
            "three-quarter",
            "--azimuth",
            "90",
            "--out",
            out.to_str().unwrap(),
            "--stats",
            stats.to_str().unwrap(),
        ];
        if occlusion {
            args.push("--occlusion");
        }
        ok(&mpirun(2, &[], &args));
        let triangles: Vec<u64> = std::fs::read_to_string(&stats)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .filter(|l| l["rank"] == 1)
            .map(|l| l["tiles"][0]["triangles"].as_u64().unwrap())
            .collect();
        runs.push(triangles);
    }
    let (all, culled) = (&runs[0], &runs[1]);
    assert_eq!(all[0], culled[0], "the first frame has no depth to cull with");
    for (k, (&a, &c)) in all.iter().zip(culled).enumerate().skip(1) {
        let frame = k + 1;
        assert!(c * 20 < a * 19, "frame {frame}: {c} triangles culled against {a}");
        let f = |name: &str| dir.path().join(format!("{name}-{frame:04}.png"));
        let (matching, covered) = matching_fraction(&f("all"), &f("occ"), 8);
        assert!(covered > 10_000 && matching >= 0.99, "frame {frame}: {matching} of {covered} pixels match");
        eprintln!("frame {frame}: {a} triangles, {c} culled; {matching:.4} of {covered} pixels match");
    }
}

#[test]
fn bad_progressive_meshes_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let dpm = dir.path().join("bad.dpm");
    let mut bytes = b"TESSDPM\x1a".to_vec();
    bytes.extend([0u8; 40]);
    std::fs::write(&dpm, &bytes).unwrap();
    let out = dir.path().join("x.png");
    let o = alone(&["render", dpm.to_str().unwrap(), "--size", "64x64", "--out", out.to_str().unwrap()]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("bad.dpm"), "names the file: {err}");
    assert!(!out.exists(), "no image is written");
}
