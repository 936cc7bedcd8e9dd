//! End-to-end tests of `tessera render` on sorted models (single-stream and chunked `.bft`),
//! under `mpirun` and alone: stitched tiles against a single-process render of the whole frame
//! as one tile, whatever the ranks, tile coding, balancing, worker caches and sorters; a
//! model's colours and normals; decode-only runs; pipelined frames; the stats' timelines.

mod common;

use common::{alone, covered, differing, identical, json_lines, mpirun, ok, pixels, reference};
use testkit::mesh_arg as mesh;

#[test]
fn mpirun_tiles_equal_the_single_process_frame() {
    let dir = tempfile::tempdir().unwrap();
    for (model, size) in
        [(mesh("stanford/bunny_zipper_c3d.obj.gz"), "400x300"), (mesh("odedstein/plane_holes.obj.gz"), "333x201")]
    {
        let reference = reference(&model, size, dir.path());
        assert!(covered(&reference) > 1000, "{model}: the model is in view");
        for (np, flags) in [
            (2, vec!["--tiles", "4x3"]),
            (3, vec!["--tiles", "5x4", "--tile-coding", "range"]),
            // The second frame made again, its tiles balanced by the first's costs.
            (3, vec!["--tiles", "3x3", "--balance", "--frames", "2", "--no-frame-reuse"]),
        ] {
            let out = dir.path().join("tiled.png");
            let mut args = vec!["render", &model, "--size", size, "--out", out.to_str().unwrap()];
            args.extend(&flags);
            ok(&mpirun(np, &[], &args));
            // With --frames 2 the first frame is numbered; without --orbit it is the same view.
            let produced = if flags.contains(&"--frames") { dir.path().join("tiled-0001.png") } else { out.clone() };
            assert_eq!(differing(&produced, &reference), 0, "{model}, -np {np} {flags:?}");
        }
    }
}

/// A model's own colours and normals reach the pixels: frames under `mpirun -np 2` and `-np 3`
/// (chunked and single-stream files, sorted and forwarded chunks) equal the single-process
/// frame pixel for pixel, and a coloured model's frame is not grey.
#[test]
fn colours_and_normals_render_the_same_frames_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let spot = concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/spot_colored.ply.gz");
    let horse = mesh("classic/horse.ply.gz");
    ok(&alone(&["encode", spot, "-o", &p("spot.bft"), "--chunk-triangles", "3000"]));
    ok(&alone(&["encode", &horse, "-o", &p("horse.bft"), "--chunk-triangles", "0", "--normal-bits", "12"]));
    let stats = String::from_utf8(alone(&["stats", &p("spot.bft"), "--json"]).stdout).unwrap();
    assert!(stats.contains("\"color_bytes\"") && !stats.contains("\"color_bytes\": 0,"), "{stats}");
    for model in [p("spot.bft"), p("horse.bft")] {
        let view = ["--size", "320x240", "--view", "three-quarter", "--frames", "2", "--orbit"];
        let (reference, tiled) = (p("ref.png"), p("tiled.png"));
        let mut args = vec!["render", &model, "--out", &reference, "--tiles", "1x1"];
        args.extend(view);
        ok(&alone(&args));
        for (np, tiles, extra) in [(2, "4x3", vec![]), (3, "5x4", vec!["--tile-coding", "range"])] {
            let mut args = vec!["render", &model, "--out", &tiled, "--tiles", tiles];
            args.extend(view);
            args.extend(extra);
            ok(&mpirun(np, &[], &args));
            for k in 1..=2 {
                let (a, b) = (dir.path().join(format!("ref-{k:04}.png")), dir.path().join(format!("tiled-{k:04}.png")));
                assert!(covered(&a) > 1000, "{model}: in view");
                assert!(
                    identical(&a, &b),
                    "{model} frame {k}, -np {np} --tiles {tiles}: {} pixels differ",
                    differing(&a, &b)
                );
            }
        }
        if model.ends_with("spot.bft") {
            let (_, _, px) = pixels(&dir.path().join("ref-0001.png"));
            let tinted = px.chunks(4).filter(|c| c[3] == 255 && c[0] > c[2] + 20).count();
            assert!(tinted > 1000, "the cow is drawn in its colours ({tinted} warm pixels)");
        }
    }
}

/// A chunked model renders the same frame whatever the tiles, ranks, balancing and worker
/// caches: verbatim chunks (sent or kept by the worker), sorted pieces and their border
/// normals together equal the single-process frame pixel for pixel, and the single-stream
/// model's frame within rounding of the normals at chunk borders.
#[test]
fn chunked_models_render_the_same_frames_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    ok(&alone(&["encode", &model, "-o", &p("bunny.bft"), "--chunk-triangles", "1500"]));
    ok(&alone(&["encode", &model, "-o", &p("single.bft"), "--chunk-triangles", "0"]));
    let size = "400x300";
    fn frames<'a>(model: &'a str, out: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
        let mut args = vec!["render", model, "--size", "400x300", "--frames", "3", "--orbit", "--out", out];
        args.extend(extra);
        args
    }
    let (chunked, single) = (p("bunny.bft"), p("single.bft"));
    // References: the whole frame as one tile in one process, chunked and single-stream.
    ok(&alone(&frames(&chunked, &p("ref.png"), &["--tiles", "1x1"])));
    ok(&alone(&frames(&single, &p("one.png"), &["--tiles", "1x1"])));
    let frame = |name: &str, k: u32| dir.path().join(format!("{name}-{k:04}.png"));
    for k in 1..=3 {
        assert!(covered(&frame("ref", k)) > 1000, "the model is in view");
        let px = (400 * 300) as f64;
        let near = differing(&frame("ref", k), &frame("one", k)) as f64;
        assert!(near / px < 1e-3, "frame {k}: {near} pixels differ from the single stream's");
    }
    let stats = p("s.jsonl");
    for (np, flags) in [
        (2, vec!["--tiles", "8x6", "--stats", &stats]),
        (3, vec!["--tiles", "5x4", "--tile-coding", "range"]),
        (3, vec!["--tiles", "3x3", "--balance"]),
        (2, vec!["--tiles", "4x4", "--worker-cache-mb", "0", "--cache-mb", "0"]),
    ] {
        let out = p("t.png");
        ok(&mpirun(np, &[], &frames(&chunked, &out, &flags)));
        for k in 1..=3 {
            assert!(identical(&frame("t", k), &frame("ref", k)), "-np {np} {flags:?}, frame {k}");
        }
    }
    // The 8x6 run: chunks of every kind, and the worker kept chunks from frame to frame.
    let lines = json_lines(&stats);
    let chunks: Vec<&serde_json::Value> = lines.iter().filter(|l| l["rank"] == 0).map(|l| &l["chunks"]).collect();
    assert_eq!(chunks.len(), 3);
    assert!(chunks.iter().all(|c| c["verbatim"].as_u64() > Some(0) && c["straddling"].as_u64() > Some(0)));
    assert!(chunks[0]["kept"] == 0 && chunks[0]["sent"] == chunks[0]["verbatim"]);
    // The same view twice: the second frame names every verbatim chunk the worker kept.
    let still = p("still.jsonl");
    let out = p("still.png");
    ok(&mpirun(
        2,
        &[],
        &["render", &chunked, "--size", size, "--tiles", "8x6", "--frames", "2", "--out", &out, "--stats", &still],
    ));
    assert!(identical(&frame("still", 2), &frame("ref", 1)));
    let lines = json_lines(&still);
    // A still view is the frame before, reused: nothing sorted or sent.
    assert_eq!(lines.iter().filter(|l| l["rank"] == 0).nth(1).unwrap()["reused"], true);
    // A view that moves a little: the second frame names most verbatim chunks the worker kept.
    let nudged = p("nudged.jsonl");
    let args =
        ["render", &chunked, "--size", size, "--tiles", "8x6", "--frames", "2", "--orbit", "--orbit-degrees", "0.2"];
    ok(&mpirun(2, &[], &[&args[..], &["--out", &p("nudged.png"), "--stats", &nudged]].concat()));
    let lines = json_lines(&nudged);
    let second = &lines.iter().filter(|l| l["rank"] == 0).nth(1).unwrap()["chunks"];
    assert!(second["kept"].as_u64() > second["sent"].as_u64(), "{second}");
}

/// `--sorters K`: rank 0 and K-1 more ranks each sort a share of the chunks and send the
/// pieces straight to the workers; the frames are the same for K = 1, 2, 3.
#[test]
fn several_sorters_render_the_same_frames() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let chunked = p("bunny.bft");
    ok(&alone(&["encode", &model, "-o", &chunked, "--chunk-triangles", "1500"]));
    let reference = p("ref.png");
    ok(&alone(&["render", &chunked, "--size", "320x240", "--tiles", "1x1", "--frames", "2", "--out", &reference]));
    for k in ["1", "2", "3"] {
        let out = p(&format!("k{k}.png"));
        // The second frame made again: the sorters name the chunks the workers kept.
        let args = [
            "render",
            &chunked,
            "--size",
            "320x240",
            "--tiles",
            "4x3",
            "--frames",
            "2",
            "--no-frame-reuse",
            "--sorters",
            k,
            "--out",
            &out,
        ];
        ok(&mpirun(4, &[], &args));
        for f in 1..=2 {
            let frame = |name: &str| dir.path().join(format!("{name}-{f:04}.png"));
            assert!(identical(&frame(&format!("k{k}")), &frame("ref")), "--sorters {k}, frame {f}");
        }
    }
    // More sorters than ranks allow, a single-stream model, or no mpirun: refused.
    let o = mpirun(2, &[], &["render", &chunked, "--sorters", "2", "--out", &p("x.png")]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--sorters 2 needs at least 3 ranks"));
    let single = p("single.bft");
    ok(&alone(&["encode", &model, "-o", &single, "--chunk-triangles", "0"]));
    let o = mpirun(3, &[], &["render", &single, "--sorters", "2", "--out", &p("x.png")]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("chunked .bft model"));
    let o = alone(&["render", &chunked, "--sorters", "2", "--out", &p("x.png")]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("needs mpirun"));
}

#[test]
fn alone_more_workers_than_tiles_and_orbit() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/cow.obj");
    let reference = reference(&model, "320x240", dir.path());
    let out = dir.path().join("t.png");
    ok(&alone(&["render", &model, "--size", "320x240", "--tiles", "2x2", "--out", out.to_str().unwrap()]));
    assert_eq!(differing(&out, &reference), 0);
    // Four workers, two tiles: two workers idle.
    ok(&mpirun(5, &[], &["render", &model, "--size", "320x240", "--tiles", "2x1", "--out", out.to_str().unwrap()]));
    assert_eq!(differing(&out, &reference), 0);
    let stats = dir.path().join("s.jsonl");
    let orbit = dir.path().join("o.png");
    ok(&alone(&[
        "render",
        &model,
        "--size",
        "160x120",
        "--tiles",
        "2x2",
        "--frames",
        "3",
        "--orbit",
        "--out",
        orbit.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
    ]));
    let frames: Vec<_> = (1..=3).map(|k| dir.path().join(format!("o-{k:04}.png"))).collect();
    assert!(frames.iter().all(|f| f.exists()));
    assert!(differing(&frames[0], &frames[1]) > 0, "the camera moved");
    // One line per frame per rank, with every stage time.
    let lines = json_lines(&stats);
    assert_eq!(lines.len(), 6);
    for l in &lines {
        let keys: &[&str] = if l["rank"] == 0 {
            &["sort_ms", "send_ms", "composite_ms"]
        } else {
            &["decode_ms", "upload_ms", "render_ms", "readback_ms"]
        };
        for k in keys {
            assert!(l[k].as_f64().is_some(), "{k} in {l}");
        }
    }
    let tile = &lines[0]["tiles"][0];
    assert!(
        tile["bytes"].as_u64().unwrap() > 0
            && tile["tri_bytes"].as_u64().unwrap() == 36 * tile["triangles"].as_u64().unwrap()
    );
}

/// `--decode-only`: the workers decode every tile the master sorts (the same triangles as a
/// rendered frame) but rasterize nothing, so the frame is transparent and the stats show
/// decode time without render time; a progressive mesh is refused, before any work.
#[test]
fn decode_only_measures_the_distribution_without_rasterizing() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let run = |name: &str, extra: &[&str]| {
        let (out, stats) = (dir.path().join(format!("{name}.png")), dir.path().join(format!("{name}.jsonl")));
        let mut args = vec!["render", &model, "--size", "320x240", "--tiles", "4x4"];
        args.extend(extra);
        args.extend(["--out", out.to_str().unwrap(), "--stats", stats.to_str().unwrap()]);
        ok(&alone(&args));
        let lines = json_lines(&stats);
        (out, lines)
    };
    let (drawn, drawn_stats) = run("drawn", &[]);
    let (blank, stats) = run("blank", &["--decode-only"]);
    assert!(covered(&drawn) > 1000);
    assert_eq!(covered(&blank), 0, "a decode-only frame is transparent");
    let worker = |lines: &[serde_json::Value]| lines.iter().find(|l| l["rank"] == 1).unwrap().clone();
    let (w, wd) = (worker(&stats), worker(&drawn_stats));
    assert!(w["decode_ms"].as_f64().unwrap() > 0.0);
    assert_eq!(w["render_ms"].as_f64().unwrap(), 0.0);
    assert!(wd["render_ms"].as_f64().unwrap() > 0.0);
    let triangles = |w: &serde_json::Value| -> u64 {
        w["tiles"].as_array().unwrap().iter().map(|t| t["triangles"].as_u64().unwrap()).sum()
    };
    assert_eq!(triangles(&w), triangles(&wd), "the same tiles are decoded");
    assert!(triangles(&w) >= 69_451);

    let dpm = dir.path().join("b.dpm");
    ok(&alone(&["pm", "build", &model, "-o", dpm.to_str().unwrap()]));
    let o =
        alone(&["render", dpm.to_str().unwrap(), "--decode-only", "--out", dir.path().join("x.png").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--decode-only"), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Pipelined frames (`--frames-in-flight`, rank 0 sorting ahead while workers render and a
/// writer thread writing) give the unpipelined frames pixel for pixel, in order: a sorted
/// model, a progressive mesh (whose workers keep their adaptation from frame to frame) and
/// an `.nsp` model, each along an orbit, under mpirun with two workers.
#[test]
fn pipelined_frames_equal_unpipelined_frames() {
    let dir = tempfile::tempdir().unwrap();
    let bunny = mesh("stanford/bunny_oded_6k.obj");
    let dpm = dir.path().join("b.dpm");
    ok(&alone(&["pm", "build", &bunny, "-o", dpm.to_str().unwrap()]));
    let nsp = dir.path().join("b.nsp");
    ok(&alone(&["nsp", "build", &bunny, "-o", nsp.to_str().unwrap(), "--min-simplices", "800"]));
    for model in [bunny.as_str(), dpm.to_str().unwrap(), nsp.to_str().unwrap()] {
        let mut frames = Vec::new();
        for depth in ["1", "3"] {
            let out = dir.path().join(format!("p{depth}.png"));
            let args = [
                "render",
                model,
                "--size",
                "160x120",
                "--tiles",
                "4x3",
                "--frames",
                "5",
                "--orbit",
                "--frames-in-flight",
                depth,
                "--out",
                out.to_str().unwrap(),
            ];
            ok(&mpirun(3, &[], &args));
            frames.push((1..=5).map(|k| dir.path().join(format!("p{depth}-{k:04}.png"))).collect::<Vec<_>>());
        }
        for (k, (one, three)) in frames[0].iter().zip(&frames[1]).enumerate() {
            assert!(covered(one) > 500, "{model}: frame {k} shows the model");
            assert!(identical(one, three), "{model}: frame {k} differs when pipelined");
        }
        // Frames differ from one another (the orbit moves), so equal frames are in order.
        assert!(!identical(&frames[1][0], &frames[1][2]), "{model}");
    }
}

/// The stats' timelines: on one machine (one clock) each frame's stages follow one another
/// on rank 0, every worker works on a frame between rank 0's sending it and receiving its
/// pixels, and with frames in flight rank 0 sorts a frame before the one before is back.
/// `tessera plot` draws them: one row per rank and one for rank 0's writer.
#[test]
fn timelines_order_the_stages_and_plot_draws_them() {
    let dir = tempfile::tempdir().unwrap();
    let bunny = mesh("stanford/bunny_oded_6k.obj");
    let (out, stats) = (dir.path().join("t.png"), dir.path().join("t.jsonl"));
    let args = [
        "render",
        bunny.as_str(),
        "--size",
        "160x120",
        "--tiles",
        "4x3",
        "--frames",
        "4",
        "--orbit",
        "--frames-in-flight",
        "2",
        "--out",
        out.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
    ];
    ok(&mpirun(3, &[], &args));
    let lines = json_lines(&stats);
    let span = |line: &serde_json::Value, stage: &str| -> (f64, f64) {
        let s = line["timeline"].as_array().unwrap().iter().find(|s| s["stage"] == stage);
        let s = s.unwrap_or_else(|| panic!("no {stage} in {line}"));
        (s["start_ms"].as_f64().unwrap(), s["end_ms"].as_f64().unwrap())
    };
    // Clocks read by different calls: allow a millisecond.
    let eps = 1.0;
    let master: Vec<&serde_json::Value> = lines.iter().filter(|l| l["rank"] == 0).collect();
    assert_eq!(master.len(), 4);
    for m in &master {
        let (sort, send, receive, write) = (span(m, "sort"), span(m, "send"), span(m, "receive"), span(m, "write"));
        assert!(sort.0 >= 0.0 && sort.0 <= sort.1 && sort.1 <= send.0 + eps, "{m}");
        assert!(send.1 <= receive.1 + eps && receive.1 <= write.0 + eps && write.0 <= write.1, "{m}");
        let workers: Vec<&serde_json::Value> =
            lines.iter().filter(|l| l["rank"] != 0 && l["frame"] == m["frame"]).collect();
        assert_eq!(workers.len(), 2, "two workers answer frame {}", m["frame"]);
        for w in workers {
            let (decode, render) = (span(w, "decode"), span(w, "render"));
            assert!(decode.0 + eps >= send.0 && decode.1 <= render.0 + eps, "{w} after {m}");
            assert!(render.1 <= receive.1 + eps, "{w} before {m}'s pixels are in");
        }
    }
    // Pipelined: frame 1 is sorted before frame 0's pixels are all in.
    assert!(span(master[1], "sort").0 < span(master[0], "receive").1, "{} {}", master[0], master[1]);

    let png = dir.path().join("timeline.png");
    ok(&alone(&["plot", stats.to_str().unwrap(), "-o", png.to_str().unwrap(), "--width", "900"]));
    // Rows: rank 0, its writer, ranks 1 and 2.
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let reader = decoder.read_info().unwrap();
    assert_eq!((reader.info().width, reader.info().height), (900, master::commands::plot::Timeline::height(4)));
    let bad = alone(&["plot", &bunny, "-o", png.to_str().unwrap()]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("line 1") && err.lines().count() == 1, "{err}");
}

/// A `--frames` run whose camera stands still reuses the frame before: rank 0 neither sorts
/// nor sends, the workers render nothing, and each later frame's files are the first's, byte
/// for byte; a moving camera's frames are made as before.
#[test]
fn a_still_camera_reuses_the_frame_before() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/spot.obj");
    for (np, wall) in [(1, false), (2, false), (2, true)] {
        let out = dir.path().join(format!("still-{np}-{wall}.png"));
        let stats = out.with_extension("jsonl");
        let wall_file = dir.path().join("wall.toml");
        std::fs::write(&wall_file, "columns = 2\nrows = 1\ndisplay_width = 80\ndisplay_height = 60\nbezel_x = 8\n")
            .unwrap();
        let mut args = vec!["render", model.as_str(), "--size", "160x120", "--tiles", "2x2", "--frames", "4"];
        args.extend(["--out", out.to_str().unwrap(), "--stats", stats.to_str().unwrap()]);
        if wall {
            args.extend(["--wall", wall_file.to_str().unwrap()]);
        }
        ok(&if np == 1 { alone(&args) } else { mpirun(np, &[], &args) });
        let lines = json_lines(&stats);
        let master: Vec<&serde_json::Value> = lines.iter().filter(|l| l["rank"] == 0).collect();
        assert_eq!(master.len(), 4);
        assert!(master[0].get("reused").is_none() && !master[0]["tiles"].as_array().unwrap().is_empty());
        for l in &master[1..] {
            assert_eq!(l["reused"], true, "{l}");
            assert_eq!((l["sort_ms"].as_f64(), l["tiles"].as_array().map(Vec::len)), (Some(0.0), Some(0)), "{l}");
        }
        assert!(lines.iter().filter(|l| l["rank"] != 0).all(|l| l["frame"] == 0), "workers render frame 1 only");
        let stem = out.file_stem().unwrap().to_str().unwrap().to_string();
        let files = |k: u32| -> Vec<Vec<u8>> {
            let base = format!("{stem}-{k:04}");
            let mut names = vec![format!("{base}.png")];
            if wall {
                names.extend(["0-0", "1-0"].map(|d| format!("{base}-display-{d}.png")));
            }
            names.iter().map(|n| std::fs::read(dir.path().join(n)).unwrap()).collect()
        };
        for k in 2..=4 {
            assert!(files(k) == files(1), "frame {k}'s files are frame 1's");
        }
    }
    // An orbit makes every frame.
    let stats = dir.path().join("orbit.jsonl");
    let out = dir.path().join("orbit.png");
    let args = ["render", &model, "--size", "160x120", "--frames", "3", "--orbit", "--orbit-degrees", "30"];
    ok(&alone(&[&args[..], &["--out", out.to_str().unwrap(), "--stats", stats.to_str().unwrap()]].concat()));
    assert!(!std::fs::read_to_string(&stats).unwrap().contains("\"reused\":true"));
}

/// Workers keep the frame before's decoded meshes: along a slow orbit of a chunked model the
/// streams that did not change (verbatim chunks still in view, tiles whose submesh is the
/// same) are not decoded again, and the frames are those of workers that keep nothing.
#[test]
fn workers_reuse_what_they_decoded_the_frame_before() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let bft = dir.path().join("bunny.bft");
    ok(&alone(&["encode", &model, "-o", bft.to_str().unwrap(), "--chunk-triangles", "1500"]));
    let run = |name: &str, cache: &str| {
        let out = dir.path().join(format!("{name}.png"));
        let stats = out.with_extension("jsonl");
        let args = [
            "render",
            bft.to_str().unwrap(),
            "--size",
            "320x240",
            "--tiles",
            "4x3",
            "--frames",
            "4",
            "--orbit",
            "--orbit-degrees",
            "3",
            "--worker-cache-mb",
            cache,
            "--out",
            out.to_str().unwrap(),
            "--stats",
            stats.to_str().unwrap(),
        ];
        ok(&mpirun(3, &[], &args));
        let lines = json_lines(&stats);
        lines.into_iter().filter(|l| l["rank"] != 0).collect::<Vec<_>>()
    };
    let kept = run("kept", "64");
    let none = run("none", "0");
    for k in 1..=4 {
        let (a, b) = (dir.path().join(format!("kept-{k:04}.png")), dir.path().join(format!("none-{k:04}.png")));
        assert!(identical(&a, &b), "frame {k} is the same with or without the workers' caches");
    }
    let sum = |lines: &[serde_json::Value], frame: u64, key: &str| -> u64 {
        lines.iter().filter(|l| l["frame"] == frame).map(|l| l[key].as_u64().unwrap()).sum()
    };
    assert_eq!(sum(&kept, 0, "reused_triangles"), 0, "the first frame decodes everything");
    for f in 1..4 {
        let (reused, decoded) = (sum(&kept, f, "reused_triangles"), sum(&kept, f, "decoded_triangles"));
        assert!(reused * 3 > reused + decoded, "frame {}: reused {reused}, decoded {decoded}", f + 1);
        assert_eq!(sum(&none, f, "reused_triangles"), 0, "no cache, nothing reused");
    }
}
