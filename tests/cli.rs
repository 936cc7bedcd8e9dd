//! End-to-end tests of the `tessera` binary on real files.

mod common;

use std::path::Path;
use std::process::{Command, Output};

// These runs take the test process's environment as it is, as a user's shell would.
use common::{bare as tessera, bin, ok, output};
use testkit::{arg as s, mesh_path as mesh, stderr};

#[test]
fn encode_stats_decode_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let input = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let bft = dir.path().join("bunny.bft");
    let o = tessera(&["encode", s(&input), "-o", s(&bft), "--quant-bits", "14"]);
    ok(&o);

    let o = tessera(&["stats", s(&bft), "--json"]);
    ok(&o);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["triangles"], 69_451);
    assert_eq!(j["quant_bits"], 14);
    assert_eq!(j["bytes"], std::fs::metadata(&bft).unwrap().len());
    // The scan's 1,113 unreferenced vertices are not coded: 35,947 - 1,113.
    assert_eq!(j["vertices"], 34_834);
    assert!(j["components"].as_u64().unwrap() >= 1);
    let conn = j["connectivity_bits_per_triangle"].as_f64().unwrap();
    assert!(conn > 0.0 && conn <= 2.0, "connectivity {conn} bits/triangle");
    assert!(j["geometry_bits_per_vertex"].as_f64().unwrap() > 0.0);

    let original = codec::load_path(&input).unwrap();
    for ext in ["ply", "obj"] {
        let out = dir.path().join(format!("bunny.{ext}"));
        let o = tessera(&["decode", s(&bft), "-o", s(&out)]);
        ok(&o);
        let back = codec::load_path(&out).unwrap();
        assert_eq!(back.triangles.len(), original.triangles.len());
        assert_eq!(back.positions.len(), 34_834);
        // Exactly the input's triangles, by position, once the input is quantized to 14 bits.
        let used = original.used_vertices();
        let q = codec::Quantization::fit(&original.positions, Some(&used), 14).unwrap();
        let key = |m: &codec::Mesh, t: [u32; 3], quantize: bool| {
            let c = t.map(|i| {
                let p = m.positions[i as usize];
                (if quantize { q.dequantize(q.quantize(p)) } else { p }).map(f32::to_bits)
            });
            [[c[0], c[1], c[2]], [c[1], c[2], c[0]], [c[2], c[0], c[1]]].into_iter().min().unwrap()
        };
        let mut a: Vec<_> = back.triangles.iter().map(|&t| key(&back, t, false)).collect();
        let mut b: Vec<_> = original.triangles.iter().map(|&t| key(&original, t, true)).collect();
        a.sort_unstable();
        b.sort_unstable();
        assert!(a == b, "decoded {ext} differs from the quantized input");
    }

    let o = tessera(&["stats", s(&bft)]);
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stdout).contains("connectivity"));
}

#[test]
fn bad_input_gets_a_clear_error_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();

    let o = tessera(&["encode", s(&d.join("missing.obj")), "-o", s(&d.join("x.bft"))]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("missing.obj"), "{}", stderr(&o));

    let nan = d.join("nan.obj");
    std::fs::write(&nan, "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n").unwrap();
    let o = tessera(&["encode", s(&nan), "-o", s(&d.join("nan.bft"))]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("non-finite"), "{}", stderr(&o));
    assert!(!d.join("nan.bft").exists());

    let oob = d.join("oob.obj");
    std::fs::write(&oob, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
    let o = tessera(&["encode", s(&oob), "-o", s(&d.join("oob.bft"))]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("oob.obj"), "{}", stderr(&o));

    let o = tessera(&["encode", s(&mesh("classic/cow.obj")), "-o", s(&d.join("c.bft")), "--quant-bits", "30"]);
    assert_eq!(o.status.code(), Some(2), "clap rejects the flag");

    // A corrupt .bft must not replace an existing output.
    let bft = d.join("cow.bft");
    ok(&tessera(&["encode", s(&mesh("classic/cow.obj")), "-o", s(&bft)]));
    let mut bytes = std::fs::read(&bft).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x40;
    let bad = d.join("bad.bft");
    std::fs::write(&bad, &bytes).unwrap();
    let out = d.join("out.ply");
    std::fs::write(&out, "old").unwrap();
    let o = tessera(&["decode", s(&bad), "-o", s(&out)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("checksum"), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "old");

    std::fs::write(&bad, &std::fs::read(&bft).unwrap()[..40]).unwrap();
    let o = tessera(&["stats", s(&bad)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("truncated"), "{}", stderr(&o));

    let o = tessera(&["decode", s(&bft), "-o", s(&d.join("out.xyz"))]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains(".ply or .obj"), "{}", stderr(&o));

    // No temporary files are left behind by failed writes.
    let leftovers: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".tessera-"))
        .collect();
    assert!(leftovers.is_empty());
}

#[test]
fn pm_build_stats_adapt_and_corrupt_file() {
    let dir = tempfile::tempdir().unwrap();
    let input = mesh("classic/spot.obj");
    let dpm = dir.path().join("spot.dpm");
    let o = tessera(&["pm", "build", s(&input), "-o", s(&dpm)]);
    ok(&o);

    let o = tessera(&["pm", "stats", s(&dpm), "--json"]);
    ok(&o);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let bpv = j["bytes_per_vertex"].as_f64().unwrap();
    assert!(bpv > 0.0 && bpv < 40.0, "{bpv} bytes/vertex");
    assert_eq!(j["bytes"], std::fs::metadata(&dpm).unwrap().len());
    for k in ["criteria_per_vertex", "tree_pointers_per_vertex", "connectivity_per_vertex", "geometry_per_vertex"] {
        assert!(j[k].as_f64().unwrap() > 0.0, "{k}");
    }

    let original = codec::load_path(&input).unwrap();
    let full = dir.path().join("full.ply");
    let o = tessera(&["pm", "adapt", s(&dpm), "--full", "-o", s(&full)]);
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stdout).contains(&format!("{} triangles", original.triangles.len())));
    assert_eq!(codec::load_path(&full).unwrap().triangles.len(), original.triangles.len());

    // Simplified in chunks: a different file that refines to the same triangles.
    let chunked = dir.path().join("chunked.dpm");
    let o = tessera(&["pm", "build", s(&input), "-o", s(&chunked), "--chunk-faces", "1000"]);
    ok(&o);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("simplified in 15 chunks of at most 1000 triangles"), "{out}");
    assert_ne!(std::fs::read(&chunked).unwrap(), std::fs::read(&dpm).unwrap());
    let o = tessera(&["pm", "adapt", s(&chunked), "--full", "-o", s(&full)]);
    ok(&o);
    assert_eq!(codec::load_path(&full).unwrap().triangles.len(), original.triangles.len());

    let view = dir.path().join("view.ply");
    let o = tessera(&["pm", "adapt", s(&dpm), "--size", "64x48", "--error-px", "0.5", "-o", s(&view)]);
    ok(&o);
    let adapted = codec::load_path(&view).unwrap().triangles.len();
    assert!(adapted > 0 && adapted <= original.triangles.len(), "{adapted} triangles");

    // A flipped byte: a clear error, exit code 1, no output.
    let mut bytes = std::fs::read(&dpm).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x10;
    let bad = dir.path().join("bad.dpm");
    std::fs::write(&bad, &bytes).unwrap();
    let out = dir.path().join("bad.ply");
    for args in [vec!["pm", "stats", s(&bad)], vec!["pm", "adapt", s(&bad), "--full", "-o", s(&out)]] {
        let o = tessera(&args);
        assert_eq!(o.status.code(), Some(1));
        assert!(stderr(&o).contains("corrupt"), "{}", stderr(&o));
    }
    assert!(!out.exists());
}

/// `pm build --spill-dir` keeps its large arrays in files there (blocks of 1 MiB and more
/// here) and writes the same bytes; a folder it cannot use is refused in one line, with no
/// output.
#[test]
fn pm_build_spills_into_files_and_writes_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let input = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let (plain, spilled) = (dir.path().join("plain.dpm"), dir.path().join("spilled.dpm"));
    let o = tessera(&["pm", "build", s(&input), "-o", s(&plain), "--node-kb", "16"]);
    ok(&o);
    let o = tessera(&[
        "pm",
        "build",
        s(&input),
        "-o",
        s(&spilled),
        "--node-kb",
        "16",
        "--spill-dir",
        s(dir.path()),
        "--spill-min-mb",
        "1",
    ]);
    ok(&o);
    let out = String::from_utf8_lossy(&o.stdout);
    let kept = out.lines().find(|l| l.contains("of arrays in files in")).unwrap_or_else(|| panic!("{out}"));
    let files: u32 = kept.split("at most ").nth(1).and_then(|r| r.split(' ').next()).unwrap().parse().unwrap();
    assert!(files > 0 && !kept.contains("could not"), "{kept}");
    assert_eq!(std::fs::read(&plain).unwrap(), std::fs::read(&spilled).unwrap());

    // Spilling by itself where the memory is short (1 MiB taken as available), into the
    // temporary folder; refused in one line where that folder is in memory.
    let tmp = dir.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let auto = dir.path().join("auto.dpm");
    let args = ["pm", "build", s(&input), "-o", s(&auto), "--node-kb", "16", "--assume-available-mb", "1"];
    let o = output(Command::new(bin()).args(args).env("TMPDIR", &tmp));
    ok(&o);
    let err = stderr(&o);
    // Decided from the vertex count, before the triangles were read.
    assert!(
        err.contains("(twice its 34834 vertices) need about")
            && err.contains(&format!("keeping the build's large arrays in files in {}", tmp.display())),
        "{err}"
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains("of arrays in files in"));
    assert_eq!(std::fs::read(&plain).unwrap(), std::fs::read(&auto).unwrap());
    if std::fs::metadata("/dev/shm").is_ok() {
        let bad = dir.path().join("bad.dpm");
        let args = ["pm", "build", s(&input), "-o", s(&bad), "--assume-available-mb", "1"];
        let o = output(Command::new(bin()).args(args).env("TMPDIR", "/dev/shm"));
        assert_eq!(o.status.code(), Some(1));
        let err = stderr(&o);
        assert!(
            err.trim().lines().count() == 1
                && err.contains("--spill-dir DIR on a disk (cannot spill into /dev/shm")
                && err.contains("--no-memory-check"),
            "{err}"
        );
        assert!(!bad.exists());
    }

    let missing = dir.path().join("no such folder");
    let bad = dir.path().join("bad.dpm");
    let mut folders = vec![missing];
    // A folder in memory would only move the memory.
    if std::fs::metadata("/dev/shm").is_ok() {
        folders.push("/dev/shm".into());
    }
    for f in folders {
        let o = tessera(&["pm", "build", s(&input), "-o", s(&bad), "--spill-dir", s(&f)]);
        assert_eq!(o.status.code(), Some(1));
        let err = stderr(&o);
        assert!(err.trim().lines().count() == 1 && err.contains("cannot keep the build's arrays in"), "{err}");
        assert!(!bad.exists());
    }
}

/// `pm adapt` of an out-of-core file reads the nodes its view needs, not the file (the count
/// is on stdout: a close view reads fewer than all), and writes the in-core file's mesh for the
/// same camera (given whole: the default camera frames the node boxes, as `render` does); a
/// corrupt node that the view needs is a one-line error naming it, and nothing is written.
/// `pm stats` of it reads node by node.
#[test]
fn pm_adapt_out_of_core_reads_only_the_nodes_the_view_needs() {
    let dir = tempfile::tempdir().unwrap();
    let (dpm, ooc) = (dir.path().join("bunny.dpm"), dir.path().join("bunny-nodes.dpm"));
    let bunny = mesh("stanford/bunny_zipper_c3d.obj.gz");
    for (out, nodes) in [(&dpm, None), (&ooc, Some("4"))] {
        let mut args = vec!["pm", "build", s(&bunny), "-o", s(out)];
        args.extend(nodes.map(|kb| ["--node-kb", kb]).into_iter().flatten());
        let o = tessera(&args);
        ok(&o);
    }
    let frame = ["--near", "0.01", "--far", "1", "--target", "-0.02,0.1,0"];
    let close = ["--size", "960x540", "--error-px", "4", "--eye", "0,0.1,0.05"];
    let whole = ["--size", "640x480", "--error-px", "0.5", "--eye", "0.1,0.15,0.3"];
    let out = dir.path().join("out.ply");
    let mut read_counts = vec![];
    for view in [&close, &whole] {
        let mut meshes = vec![];
        for model in [&dpm, &ooc] {
            let mut args = vec!["pm", "adapt", s(model), "-o", s(&out)];
            args.extend(view.iter().chain(&frame));
            let o = tessera(&args);
            ok(&o);
            let said = String::from_utf8_lossy(&o.stdout).to_string();
            meshes.push(std::fs::read(&out).unwrap());
            if model == &ooc {
                // "; read K of N nodes (X of Y MB)"
                let counts = said.split("; read ").nth(1).expect(&said).split(" nodes").next().unwrap();
                let k: Vec<usize> = counts.split(" of ").map(|n| n.parse().unwrap()).collect();
                read_counts.push((k[0], k[1]));
            }
        }
        assert!(meshes[0].len() > 1000 && meshes[0] == meshes[1], "{view:?}: the out-of-core mesh differs");
    }
    let [(close_read, nodes), (whole_read, _)] = read_counts[..] else { panic!("{read_counts:?}") };
    assert!(0 < close_read && close_read < whole_read && whole_read <= nodes, "{read_counts:?}");
    // `pm stats` reads it node by node too: its numbers are the file's.
    let o = tessera(&["pm", "stats", s(&ooc), "--json"]);
    ok(&o);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["bytes"], std::fs::metadata(&ooc).unwrap().len());
    assert_eq!(j["nodes"].as_u64(), Some(nodes as u64));
    assert!(j["node_reads"].as_u64().unwrap() >= nodes as u64, "{j}");

    // A flipped byte in the first node (the hierarchy's root, which every refinement needs).
    let file = codec::pm::format::NodeFile::open(&ooc).unwrap();
    let mut bytes = std::fs::read(&ooc).unwrap();
    bytes[file.prefix().len() + 5] ^= 0x10;
    let bad = dir.path().join("bad.dpm");
    std::fs::write(&bad, &bytes).unwrap();
    let bad_out = dir.path().join("bad.ply");
    let mut args = vec!["pm", "adapt", s(&bad), "-o", s(&bad_out)];
    args.extend(close.iter().chain(&frame));
    let o = tessera(&args);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.trim().lines().count() == 1 && e.contains("node 0: checksum mismatch"), "{e}");
    assert!(!bad_out.exists());
}

/// `pm adapt --gpu` writes the CPU's file, from an in-core `.dpm` and from an out-of-core one
/// (4 kB nodes; both read the nodes the view requires, every node to refine fully); a node pool for fewer nodes gives a coarser
/// mesh, and one that holds no node is refused in one line; a GPU budget too small for the
/// mesh at the view's error gives a coarser one at a larger error, said in a note, and one
/// below the base mesh is refused in one line.
#[test]
fn pm_adapt_on_the_gpu_writes_the_cpu_file() {
    let dir = tempfile::tempdir().unwrap();
    let dpm = dir.path().join("bunny.dpm");
    let ooc = dir.path().join("bunny-nodes.dpm");
    let bunny = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let o = tessera(&["pm", "build", s(&bunny), "-o", s(&dpm)]);
    ok(&o);
    let o = tessera(&["pm", "build", s(&bunny), "-o", s(&ooc), "--node-kb", "4"]);
    ok(&o);
    let xdg = std::env::temp_dir().join("tessera-xdg");
    std::fs::create_dir_all(&xdg).unwrap();
    let run = |model: &Path, view: &[&str], gpu: &[&str], out: &Path| {
        let mut args = vec!["pm", "adapt", s(model), "-o", s(out)];
        args.extend(view);
        args.extend(gpu);
        output(Command::new(bin()).env("XDG_RUNTIME_DIR", &xdg).args(&args))
    };
    let read = |o: Output, out: &Path| {
        ok(&o);
        std::fs::read(out).unwrap()
    };
    let close = ["--size", "960x540", "--eye", "0,0.12,0.08", "--target", "-0.02,0.1,0"];
    for view in [
        &["--full"][..],
        &["--size", "1920x1080", "--error-px", "0.5"],
        &["--size", "640x480", "--error-px", "2", "--eye", "0.3,0.1,0.2", "--normal-weight", "0.02"],
        // Out of core, 122 of the 149 nodes.
        &["--size", "960x540", "--error-px", "4", "--eye", "0,0.1,0.05", "--target", "-0.02,0.1,0"],
        &close,
    ] {
        let out = dir.path().join("out.ply");
        for (model, what) in [(&dpm, "in core"), (&ooc, "out of core")] {
            // "; read K of N nodes (...)": out of core, the required nodes on both.
            let nodes_read = |o: &Output| String::from_utf8_lossy(&o.stdout).split("; read ").nth(1).map(str::to_owned);
            let o = run(model, view, &[], &out);
            let cpu_read = nodes_read(&o);
            let cpu = read(o, &out);
            assert!(cpu.len() > 1000, "{view:?}: a mesh is written");
            let o = run(model, view, &["--gpu"], &out);
            assert_eq!(cpu_read.is_some(), model == &ooc && view != ["--full"], "{view:?}");
            if cpu_read.is_some() {
                assert_eq!(nodes_read(&o), cpu_read, "{view:?}");
            }
            let gpu = read(o, &out);
            assert!(cpu == gpu, "{view:?}: the GPU's PLY ({what}) differs from the CPU's");
        }
    }
    let out = dir.path().join("small.ply");
    let small = codec::load_path(&{
        read(run(&ooc, &close, &["--gpu", "--gpu-nodes-mb", "0.1"], &out), &out);
        out.clone()
    })
    .unwrap();
    let whole = codec::load_path(&dir.path().join("out.ply")).unwrap();
    assert!(
        small.triangles.len() * 2 < whole.triangles.len() && !small.triangles.is_empty(),
        "0.1 MB of nodes: {} triangles of {}",
        small.triangles.len(),
        whole.triangles.len()
    );
    let o = run(&ooc, &close, &["--gpu", "--gpu-nodes-mb", "0.001"], &dir.path().join("none.ply"));
    assert!(!o.status.success() && !dir.path().join("none.ply").exists());
    let e = stderr(&o);
    assert!(
        e.trim().lines().count() == 1
            && e.starts_with("error: a node pool of 1048 bytes holds no node: the largest takes ")
            && e.trim().ends_with("(raise --gpu-budget-mb or --gpu-nodes-mb)"),
        "{e}"
    );
    // 4 MB: the close view's mesh (about 9 MB with its slack) does not fit at 1 px.
    let out = dir.path().join("budget.ply");
    let o = run(&dpm, &close, &["--gpu", "--gpu-budget-mb", "4"], &out);
    ok(&o);
    assert!(stderr(&o).contains("to stay within --gpu-budget-mb"), "{}", stderr(&o));
    let bounded = codec::load_path(&out).unwrap();
    assert!(
        !bounded.triangles.is_empty() && bounded.triangles.len() < whole.triangles.len(),
        "4 MB: {} triangles of {}",
        bounded.triangles.len(),
        whole.triangles.len()
    );
    // Less than the in-core model's operations.
    let o = run(&dpm, &close, &["--gpu", "--gpu-budget-mb", "0.05"], &dir.path().join("tiny.ply"));
    assert!(!o.status.success() && !dir.path().join("tiny.ply").exists());
    let e = stderr(&o);
    assert!(
        e.trim().lines().count() == 1
            && e.starts_with("error: a GPU budget of 52428 bytes does not hold")
            && e.trim().ends_with("raise --gpu-budget-mb"),
        "{e}"
    );
}

/// `tessera sort --dump` writes a PLY per non-empty tile and the summary; both tile codings
/// give the same tiles' triangles, the prefix-coded ones in a few percent more bytes.
#[test]
fn sort_dumps_tiles_in_either_coding() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let mut tiles_of = Vec::new();
    for coding in ["range", "prefix"] {
        let out = dir.path().join(coding);
        let o = tessera(&["sort", s(&model), "--tiles", "4x3", "--tile-coding", coding, "--dump", s(&out)]);
        ok(&o);
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
        let per_tile = summary["per_tile"].as_array().unwrap();
        assert!(per_tile.len() > 4, "{coding}: {} tiles", per_tile.len());
        let mut tiles = Vec::new();
        for t in per_tile {
            let index = t["index"].as_u64().unwrap();
            let ply = codec::load_path(&out.join(format!("tile-{index}.ply"))).unwrap();
            assert_eq!(ply.triangles.len() as u64, t["triangles"].as_u64().unwrap(), "{coding} tile {index}");
            tiles.push((index, ply.triangles.len(), ply.positions.len()));
        }
        tiles_of.push((tiles, summary["totals"]["tiled_bft_bytes"].as_f64().unwrap()));
    }
    assert_eq!(tiles_of[0].0, tiles_of[1].0, "the same tiles, triangles and vertices");
    let ratio = tiles_of[1].1 / tiles_of[0].1;
    assert!((1.0..1.15).contains(&ratio), "prefix / range bytes {ratio}");
}

#[test]
fn nsp_build_stats_adapt_and_corrupt_file() {
    let dir = tempfile::tempdir().unwrap();
    let input = mesh("stanford/dragon_vrip_res4.ply.gz");
    let nsp = dir.path().join("d.nsp");
    let o = tessera(&[
        "nsp",
        "build",
        s(&input),
        "-o",
        s(&nsp),
        "--bits",
        "14",
        "--root-bits",
        "5",
        "--min-simplices",
        "500",
    ]);
    ok(&o);

    let o = tessera(&["nsp", "stats", s(&nsp), "--json"]);
    ok(&o);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["bytes"], std::fs::metadata(&nsp).unwrap().len());
    assert_eq!(j["bits"], 14);
    assert!(j["cells"].as_u64().unwrap() > 64 && j["duplication"].as_f64().unwrap() > 1.0);

    // Refined fully: the canonical complex (here, the input's triangles less the repeated ones).
    let canon = codec::nsp::Canonical::of_mesh(&codec::load_path(&input).unwrap(), 14).unwrap();
    let full = dir.path().join("full.ply");
    let o = tessera(&["nsp", "adapt", s(&nsp), "--full", "-o", s(&full)]);
    ok(&o);
    assert_eq!(codec::load_path(&full).unwrap().triangles.len(), canon.triangles());

    let view = dir.path().join("view.obj");
    let o = tessera(&["nsp", "adapt", s(&nsp), "--size", "64x48", "--error-px", "4", "-o", s(&view)]);
    ok(&o);
    let coarse = codec::load_path(&view).unwrap().triangles.len();
    assert!(coarse > 0 && coarse < canon.triangles() / 2, "{coarse} of {}", canon.triangles());

    // A damaged cell: one line naming the cell, a non-zero exit, no output file.
    let mut bytes = std::fs::read(&nsp).unwrap();
    bytes[j["header_and_table_bytes"].as_u64().unwrap() as usize + 20] ^= 0x5a;
    let bad = dir.path().join("bad.nsp");
    std::fs::write(&bad, &bytes).unwrap();
    let out = dir.path().join("bad.ply");
    let o = tessera(&["nsp", "adapt", s(&bad), "--full", "-o", s(&out)]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(err.lines().count() == 1 && err.contains("bad.nsp: cell ") && err.contains("checksum"), "{err}");
    assert!(!out.exists());
    // A .bft given to nsp stats.
    std::fs::write(&bad, b"TESSBFT\x1a").unwrap();
    let o = tessera(&["nsp", "stats", s(&bad)]);
    let err = stderr(&o);
    assert!(!o.status.success() && err.contains("this is a .bft model") && err.contains("use tessera stats"), "{err}");
    // And the other way round, a mesh given where a model is read; a model given to encode.
    let mesh = dir.path().join("m.obj");
    std::fs::write(&mesh, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let o = tessera(&["stats", s(&mesh)]);
    assert!(!o.status.success() && stderr(&o).contains("this is a mesh file; tessera stats reads a .bft model"));
    let o = tessera(&["encode", s(&bad), "-o", s(&dir.path().join("x.bft"))]);
    assert!(!o.status.success() && stderr(&o).contains("this is a .bft model"), "{}", stderr(&o));
}

/// `render --out movie.mp4` pipes every frame to ffmpeg: ffprobe counts them and reads their
/// size; a failing ffmpeg leaves a one-line error and no file, temporary or not.
#[test]
fn render_writes_a_movie_through_ffmpeg() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("stanford/bunny_oded_6k.obj");
    for (name, (w, h)) in [("m.mp4", (160, 120)), ("m.mkv", (97, 61))] {
        let out = dir.path().join(name);
        let size = format!("{w}x{h}");
        let o = tessera(&["render", s(&model), "--size", &size, "--frames", "4", "--orbit", "--out", s(&out)]);
        ok(&o);
        let probe =
            output(Command::new("ffprobe").args(["-v", "error", "-count_frames", "-select_streams", "v:0"]).args([
                "-show_entries",
                "stream=nb_read_frames,width,height",
                "-of",
                "csv=p=0",
                s(&out),
            ]));
        let text = String::from_utf8_lossy(&probe.stdout).trim().to_string();
        // Odd sizes are padded by a pixel for 4:2:0 video.
        assert_eq!(text, format!("{},{},4", w + w % 2, h + h % 2), "{name}");
    }
    // An ffmpeg that starts but fails to encode.
    let fake = dir.path().join("bin");
    std::fs::create_dir(&fake).unwrap();
    let script = fake.join("ffmpeg");
    std::fs::write(&script, "#!/bin/sh\n[ \"$1\" = -version ] && exit 0\necho 'Unknown encoder' >&2\nexit 1\n")
        .unwrap();
    std::fs::set_permissions(&script, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let out = dir.path().join("bad.mp4");
    let path = format!("{}:{}", fake.display(), std::env::var("PATH").unwrap_or_default());
    let o = output(Command::new(bin()).env("PATH", path).args([
        "render",
        s(&model),
        "--size",
        "64x48",
        "--frames",
        "3",
        "--out",
        s(&out),
    ]));
    let err = stderr(&o);
    assert!(!o.status.success() && err.contains("ffmpeg failed") && err.contains("Unknown encoder"), "{err}");
    assert_eq!(err.lines().filter(|l| l.contains("ffmpeg failed")).count(), 1, "{err}");
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(!out.exists() && !left.iter().any(|n| n.to_string_lossy().starts_with(".tessera")), "{left:?}");
    // A wall writes an image per display: no movie.
    let wall = dir.path().join("wall.toml");
    std::fs::write(&wall, "columns = 2\nrows = 1\ndisplay_width = 32\ndisplay_height = 32\n").unwrap();
    let o = tessera(&["render", s(&model), "--wall", s(&wall), "--out", s(&dir.path().join("w.mp4"))]);
    assert!(!o.status.success() && stderr(&o).contains("--out must be a .png with --wall"), "{}", stderr(&o));
}

/// Colours and normals survive `decode` to PLY: re-encoding the decoded file gives the same
/// `.bft` bytes, attributes included, and `stats` names each attribute.
#[test]
fn decode_writes_colours_and_normals_back() {
    let dir = tempfile::tempdir().unwrap();
    let (a, ply, b) = (dir.path().join("a.bft"), dir.path().join("a.ply"), dir.path().join("b.bft"));
    let spot = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/spot_colored.ply.gz");
    for (model, expect) in [(spot, "property uchar red"), (mesh("classic/horse.ply.gz"), "property float nx")] {
        for args in [
            ["encode", s(&model), "-o", s(&a), "--chunk-triangles", "0"].as_slice(),
            &["decode", s(&a), "-o", s(&ply)],
            &["encode", s(&ply), "-o", s(&b), "--chunk-triangles", "0"],
        ] {
            let o = tessera(args);
            ok(&o);
        }
        assert!(String::from_utf8_lossy(&std::fs::read(&ply).unwrap()[..400]).contains(expect));
        let (da, db) = (codec::bft::decode_file(&a).unwrap(), codec::bft::decode_file(&b).unwrap());
        if da.attributes.normals.is_empty() {
            assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap(), "{}", model.display());
        } else {
            // Codes on the octahedron's folded border name one direction twice, so a decoded
            // normal may re-quantize to the other code: compare directions there.
            let (ma, mb) = (da.to_mesh(), db.to_mesh());
            assert_eq!((&ma.positions, &ma.triangles), (&mb.positions, &mb.triangles));
            for (x, y) in ma.normals.iter().zip(&mb.normals) {
                assert!((0..3).map(|i| x[i] * y[i]).sum::<f32>() > 0.99999, "{x:?} against {y:?}");
            }
        }
        let stats = String::from_utf8(tessera(&["stats", s(&a)]).stdout).unwrap();
        assert!(stats.contains(if expect.contains("red") { "colours" } else { "normals" }), "{stats}");
    }
}

/// `encode`'s default fits the model: every shared mesh (at most 871k triangles, below the
/// 4M-triangle threshold) is the single-stream file, byte for byte what `--chunk-triangles 0`
/// writes; asking for chunks still gets them.
#[test]
fn encode_s_default_is_one_stream_for_every_shared_mesh() {
    let dir = tempfile::tempdir().unwrap();
    for path in testkit::all_shared_meshes() {
        let (a, b) = (dir.path().join("default.bft"), dir.path().join("single.bft"));
        let o = tessera(&["encode", s(&path), "-o", s(&a)]);
        if !o.status.success() {
            // Meshes the encoder refuses (the degenerate ones it names) are refused either way.
            assert!(!tessera(&["encode", s(&path), "-o", s(&b), "--chunk-triangles", "0"]).status.success());
            continue;
        }
        ok(&tessera(&["encode", s(&path), "-o", s(&b), "--chunk-triangles", "0"]));
        assert!(std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(), "{}", path.display());
    }
    let bunny = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let chunked = dir.path().join("chunked.bft");
    ok(&tessera(&["encode", s(&bunny), "-o", s(&chunked), "--chunk-triangles", "4096"]));
    let o = tessera(&["stats", s(&chunked)]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("chunk"), "{}", String::from_utf8_lossy(&o.stdout));
}

/// `encode --coding prefix` writes prefix-coded streams (a chunked file's chunks too) that
/// decode to what the default, range-coded, file decodes to.
#[test]
fn encode_coding_prefix_decodes_as_range() {
    let dir = tempfile::tempdir().unwrap();
    let bunny = mesh("stanford/bunny_zipper_c3d.obj.gz");
    for chunks in ["0", "4096"] {
        let mut plys = Vec::new();
        for coding in ["range", "prefix"] {
            let (bft, ply) =
                (dir.path().join(format!("{coding}.bft")), dir.path().join(format!("{coding}{chunks}.ply")));
            ok(&tessera(&["encode", s(&bunny), "-o", s(&bft), "--chunk-triangles", chunks, "--coding", coding]));
            let bytes = std::fs::read(&bft).unwrap();
            let first = match codec::bft::chunked::ChunkedFile::open(bytes.clone()) {
                Ok(file) => file.chunk_bft(0).unwrap().into_owned(),
                Err(_) => bytes,
            };
            let want = if coding == "prefix" { codec::bft::Coding::Prefix } else { codec::bft::Coding::Range };
            assert_eq!(codec::bft::Stats::of(&first).unwrap().header.coding, want, "{coding}, chunks {chunks}");
            ok(&tessera(&["decode", s(&bft), "-o", s(&ply)]));
            plys.push(std::fs::read(&ply).unwrap());
        }
        assert!(plys[0] == plys[1], "chunks {chunks}: the prefix-coded file decodes otherwise");
    }
    let o = tessera(&["encode", s(&bunny), "-o", s(&dir.path().join("x.bft")), "--coding", "huffman"]);
    assert!(!o.status.success());
}
