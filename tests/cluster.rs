//! End-to-end tests of `tessera render`: under `mpirun` and alone, stitched tiles against
//! a single-process render of the whole frame as one tile, tile walls, and faults.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use testkit::mesh_arg as mesh;

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_tessera")
}

fn env(cmd: &mut Command) -> &mut Command {
    let xdg = std::env::temp_dir().join("tessera-xdg");
    std::fs::create_dir_all(&xdg).unwrap();
    cmd.env("XDG_RUNTIME_DIR", xdg)
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env("OMPI_MCA_rmaps_base_oversubscribe", "1")
}

/// `tessera ARGS` without mpirun: the master and one in-process worker.
fn alone(args: &[&str]) -> Output {
    env(&mut Command::new(bin())).args(args).output().expect("runs tessera")
}

/// `mpirun -np N tessera ARGS`.
fn mpirun(n: usize, extra_env: &[(&str, &str)], args: &[&str]) -> Output {
    let mut cmd = Command::new("mpirun");
    env(&mut cmd).args(["--oversubscribe", "-np", &n.to_string()]);
    for (k, v) in extra_env {
        cmd.args(["-x", &format!("{k}={v}")]);
    }
    cmd.arg(bin()).args(args).output().expect("mpirun is installed (scripts/setup.sh)")
}

fn ok(o: &Output) {
    assert!(
        o.status.success(),
        "failed: {}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Decoded RGBA pixels of a PNG.
fn pixels(path: &Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

/// Pixels differing by more than 2/255 in some channel.
fn differing(a: &Path, b: &Path) -> usize {
    let (pa, pb) = (pixels(a), pixels(b));
    assert_eq!((pa.0, pa.1), (pb.0, pb.1));
    pa.2.chunks(4).zip(pb.2.chunks(4)).filter(|(x, y)| x.iter().zip(*y).any(|(u, v)| u.abs_diff(*v) > 2)).count()
}

fn covered(path: &Path) -> usize {
    let (_, _, px) = pixels(path);
    assert!(px.chunks(4).all(|p| p[3] == 0 || p[3] == 255), "alpha is 0 or 255");
    px.chunks(4).filter(|p| p[3] == 255).count()
}

/// The reference: the whole frame as one tile, in one process.
fn reference(model: &str, size: &str, dir: &Path) -> PathBuf {
    let out = dir.join("reference.png");
    ok(&alone(&["render", model, "--size", size, "--tiles", "1x1", "--out", out.to_str().unwrap()]));
    out
}

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
            (3, vec!["--tiles", "3x3", "--balance", "--frames", "2"]),
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

/// Exactly equal images (every byte of every pixel).
fn identical(a: &Path, b: &Path) -> bool {
    pixels(a) == pixels(b)
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
    let lines: Vec<serde_json::Value> =
        std::fs::read_to_string(&stats).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
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
    let lines: Vec<serde_json::Value> =
        std::fs::read_to_string(&still).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let second = &lines.iter().filter(|l| l["rank"] == 0).nth(1).unwrap()["chunks"];
    assert!(second["kept"].as_u64() > Some(0) && second["sent"] == 0, "{second}");
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
        let args =
            ["render", &chunked, "--size", "320x240", "--tiles", "4x3", "--frames", "2", "--sorters", k, "--out", &out];
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
    let lines: Vec<serde_json::Value> =
        std::fs::read_to_string(&stats).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
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

#[test]
fn tile_wall_writes_each_display_and_an_overview() {
    let dir = tempfile::tempdir().unwrap();
    let wall = dir.path().join("wall.toml");
    std::fs::write(
        &wall,
        "columns = 3\nrows = 2\ndisplay_width = 120\ndisplay_height = 90\nbezel_x = 12\nbezel_y = 10\n",
    )
    .unwrap();
    let out = dir.path().join("wall.png");
    let model = mesh("classic/spot.obj");
    ok(&mpirun(
        3,
        &[],
        &["render", &model, "--wall", wall.to_str().unwrap(), "--tiles", "3x3", "--out", out.to_str().unwrap()],
    ));
    let (w, h, overview) = pixels(&out);
    assert_eq!((w, h), (3 * 120 + 2 * 12, 2 * 90 + 10));
    // The same frame rendered whole: each display is its crop, the bezels are hidden.
    let whole = dir.path().join("whole.png");
    ok(&alone(&["render", &model, "--size", &format!("{w}x{h}"), "--tiles", "1x1", "--out", whole.to_str().unwrap()]));
    let (_, _, full) = pixels(&whole);
    for r in 0..2u32 {
        for c in 0..3u32 {
            let (dw, dh, d) = pixels(&dir.path().join(format!("wall-display-{c}-{r}.png")));
            assert_eq!((dw, dh), (120, 90));
            for y in 0..dh {
                let (fx, fy) = (c * 132, r * 100 + y);
                let row = &full[((fy * w + fx) * 4) as usize..((fy * w + fx + dw) * 4) as usize];
                assert_eq!(&d[(y * dw * 4) as usize..((y + 1) * dw * 4) as usize], row, "display {c},{r} row {y}");
            }
        }
    }
    let bezel = ((50 * w + 125) * 4) as usize;
    assert_eq!(&overview[bezel..bezel + 4], &[0, 0, 0, 255]);
}

fn assert_fast_failure(o: &Output, started: Instant, needle: &str) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "must fail");
    assert!(started.elapsed() < Duration::from_secs(10), "took {:?}", started.elapsed());
    assert!(err.contains(needle), "stderr should mention '{needle}': {err}");
}

#[test]
fn a_dying_or_failing_worker_ends_every_rank() {
    let model = mesh("classic/cow.obj");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("f.png");
    let args = ["render", &model, "--size", "160x120", "--tiles", "2x2", "--out", out.to_str().unwrap()];
    let started = Instant::now();
    let o = mpirun(3, &[("TESSERA_FAULT", "fail:2")], &args);
    assert_fast_failure(&o, started, "rank 2 failed: injected failure");
    let started = Instant::now();
    let o = mpirun(3, &[("TESSERA_FAULT", "die:1")], &args);
    assert_fast_failure(&o, started, "rank 1");
    assert!(!out.exists(), "no frame from a failed run");
}

#[test]
fn under_mpirun_the_timeout_measures_silence() {
    let model = mesh("classic/cow.obj");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("f.png");
    let args =
        ["render", &model, "--size", "160x120", "--tiles", "2x2", "--timeout", "1", "--out", out.to_str().unwrap()];
    // Rank 1 works three times the timeout on its first frame, with heartbeats: no death.
    let o = mpirun(3, &[("TESSERA_FAULT", "slow:1:3000")], &args);
    ok(&o);
    assert!(out.exists());
    std::fs::remove_file(&out).unwrap();
    // Rank 2 falls silent: every rank ends soon after the timeout.
    let args =
        ["render", &model, "--size", "160x120", "--tiles", "2x2", "--timeout", "2", "--out", out.to_str().unwrap()];
    let started = Instant::now();
    let o = mpirun(3, &[("TESSERA_FAULT", "hang:2")], &args);
    assert_fast_failure(&o, started, "rank 2 sent nothing for 2 s");
    assert!(!out.exists());
}

#[test]
fn a_silent_worker_ends_the_run_at_any_frames_in_flight() {
    // The bunny's tiles are far larger than MPI sends at once, so with frames in flight rank
    // 0 is sending frame 2 to the silent rank when frame 1's pixels fail to come: the send
    // must give up after the timeout as the receive does.
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("f.png");
    for depth in ["1", "2", "3"] {
        let args = [
            "render",
            &model,
            "--size",
            "640x480",
            "--tiles",
            "2x2",
            "--frames",
            "4",
            "--frames-in-flight",
            depth,
            "--timeout",
            "2",
            "--out",
            out.to_str().unwrap(),
        ];
        let started = Instant::now();
        let o = mpirun(3, &[("TESSERA_FAULT", "hang:2")], &args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "--frames-in-flight {depth}: must fail");
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "--frames-in-flight {depth}: took {:?}",
            started.elapsed()
        );
        // One frame in flight: rank 0 waits for the pixels; more: it is still sending.
        let needle = if depth == "1" {
            "rank 2 sent nothing for 2 s"
        } else {
            "rank 2 took no message and sent nothing for 2 s"
        };
        assert!(err.contains(needle), "--frames-in-flight {depth}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
}

#[test]
fn bad_input_is_reported_before_any_traffic() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.png");
    let started = Instant::now();
    let o = mpirun(2, &[], &["render", "/nonexistent/model.obj", "--out", out.to_str().unwrap()]);
    assert_fast_failure(&o, started, "model.obj");
    let o = alone(&[
        "render",
        &mesh("classic/cow.obj"),
        "--size",
        "10x10",
        "--tiles",
        "20x1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("does not fit"));
    let o = alone(&[
        "render",
        &mesh("classic/cow.obj"),
        "--eye",
        "1,1,1",
        "--target",
        "1,1,1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("eye and target"));
    let wall = dir.path().join("bad.toml");
    std::fs::write(&wall, "columns = 0\nrows = 1\ndisplay_width = 10\ndisplay_height = 10\n").unwrap();
    let o =
        alone(&["render", &mesh("classic/cow.obj"), "--wall", wall.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("bad.toml"));
    assert!(!out.exists());
}

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
            vec![(2, "4x3", vec![]), (3, "3x2", vec!["--balance", "--frames", "2"])],
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
        let lines: Vec<serde_json::Value> =
            std::fs::read_to_string(&stats).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
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

/// An `.nsp` model under mpirun equals the single-process frame of the same model as one
/// tile, pixel for pixel: rank 0 chooses the cells from the cell table and sends each worker
/// only the streams it lacks; every worker draws the cells reaching its tiles with the border
/// rule against the whole selection. Along an orbit, later frames send only new cells.
#[test]
fn nsp_frames_under_mpirun_equal_the_single_process_frame() {
    // Without and with the geometry advance (whose positions depend on each cell's prologue).
    for (advance, runs) in [("0", &[(2, "4x3"), (3, "5x4")][..]), ("2", &[(3, "5x4")][..])] {
        nsp_cluster_frames(advance, runs);
    }
}

fn nsp_cluster_frames(advance: &str, runs: &[(usize, &str)]) {
    let dir = tempfile::tempdir().unwrap();
    let nsp = dir.path().join("d.nsp");
    let nsp = nsp.to_str().unwrap();
    let build = ["nsp", "build", &mesh("stanford/dragon_vrip_res2.ply.gz"), "-o", nsp, "--min-simplices", "2000"];
    ok(&alone(&[&build[..], &["--advance", advance]].concat()));
    let view = ["--size", "480x360", "--error-px", "1", "--frames", "3", "--orbit", "--orbit-degrees", "20"];
    let single = dir.path().join("single.png");
    let mut args = vec!["render", nsp, "--tiles", "1x1", "--out", single.to_str().unwrap()];
    args.extend(view);
    ok(&alone(&args));
    for &(np, tiles) in runs {
        let out = dir.path().join(format!("np{np}.png"));
        let stats = dir.path().join(format!("np{np}.jsonl"));
        let mut args =
            vec!["render", nsp, "--tiles", tiles, "--out", out.to_str().unwrap(), "--stats", stats.to_str().unwrap()];
        args.extend(view);
        ok(&mpirun(np, &[], &args));
        for k in 1..=3 {
            let (a, b) = (dir.path().join(format!("single-{k:04}.png")), dir.path().join(format!("np{np}-{k:04}.png")));
            assert!(covered(&a) > 5_000, "the model is in view");
            assert_eq!(
                pixels(&a),
                pixels(&b),
                "--advance {advance} -np {np} --tiles {tiles}, frame {k}: differs from the single process"
            );
        }
        let lines: Vec<serde_json::Value> = std::fs::read_to_string(&stats)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .filter(|l| l["rank"] == 0)
            .collect();
        let sent: Vec<u64> = lines.iter().map(|l| l["nsp"]["bytes_sent"].as_u64().unwrap()).collect();
        let file = std::fs::metadata(nsp).unwrap().len();
        eprintln!("--advance {advance} -np {np}: bytes sent per frame {sent:?} of a {file}-byte file");
        assert!(sent[0] > 0 && sent[1] < sent[0] && sent[2] < sent[0], "{sent:?}");
        assert!(lines.iter().all(|l| l["nsp"]["selected"].as_u64().unwrap() > 0));
    }
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
    let lines: Vec<serde_json::Value> =
        std::fs::read_to_string(&stats).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
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
    assert_eq!((reader.info().width, reader.info().height), (900, master::plot::Timeline::height(4)));
    let bad = alone(&["plot", &bunny, "-o", png.to_str().unwrap()]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("line 1") && err.lines().count() == 1, "{err}");
}

fn vec3(v: glam::Vec3) -> String {
    format!("{},{},{}", v.x, v.y, v.z)
}

/// The camera flags of an off-axis frustum built by the wall (eye, target, up, field of
/// view, shift), for a mono render of it.
fn frustum_flags(a: &master::cli::CameraArgs) -> Vec<String> {
    let [sx, sy] = a.shift.unwrap();
    vec![
        "--eye".into(),
        vec3(a.eye.unwrap()),
        "--target".into(),
        vec3(a.target.unwrap()),
        "--up".into(),
        vec3(a.up.unwrap()),
        "--fovy".into(),
        a.fovy.unwrap().to_string(),
        "--shift".into(),
        format!("{sx},{sy}"),
    ]
}

/// `tessera render MODEL --size SIZE --tiles 1x1 FLAGS --out OUT`, alone.
fn render_alone(model: &str, size: &str, flags: &[String], out: &Path) {
    let mut args = vec!["render", model, "--size", size, "--tiles", "1x1"];
    args.extend(flags.iter().map(String::as_str));
    args.extend(["--out", out.to_str().unwrap()]);
    ok(&alone(&args));
}

/// `--stereo`: each eye equals a mono render from that eye with the same off-axis frustum
/// (the camera flags built by [`codec::view::Camera::stereo_eye`]); the two eyes differ;
/// side by side is the left eye beside the right, under mpirun too.
#[test]
fn stereo_eyes_equal_mono_renders_of_their_frusta() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/spot.obj");
    let (eye, target) = (glam::Vec3::new(1.2, 0.8, 2.6), glam::Vec3::new(0.0, 0.4, 0.0));
    let (near, far) = ("0.5", "10");
    let base = [
        "--size",
        "96x64",
        "--tiles",
        "3x2",
        "--eye",
        &vec3(eye),
        "--target",
        &vec3(target),
        "--near",
        near,
        "--far",
        far,
    ];
    let out = dir.path().join("s.png");
    let run = |extra: &[&str], out: &Path| {
        let mut args = vec!["render", model.as_str()];
        args.extend(base);
        args.extend(extra);
        args.extend(["--out", out.to_str().unwrap()]);
        ok(&alone(&args));
    };
    run(&["--stereo", "0.3"], &out);
    let cam = codec::view::Camera {
        eye,
        target,
        up: glam::Vec3::Y,
        fovy: codec::view::Camera::DEFAULT_FOVY,
        near: 0.5,
        far: 10.0,
        shift: [0.0; 2],
    };
    for (name, offset) in [("left", -0.15f32), ("right", 0.15)] {
        let e = cam.stereo_eye(offset, eye.distance(target), 96.0 / 64.0);
        let mono = dir.path().join(format!("mono-{name}.png"));
        let mut args =
            vec!["render", model.as_str(), "--size", "96x64", "--tiles", "1x1", "--near", near, "--far", far];
        let (ev, tv, sv) = (vec3(e.eye), vec3(e.target), format!("{},{}", e.shift[0], e.shift[1]));
        args.extend(["--eye", &ev, "--target", &tv, "--shift", &sv, "--out", mono.to_str().unwrap()]);
        ok(&alone(&args));
        let stereo = dir.path().join(format!("s-{name}.png"));
        assert!(covered(&stereo) > 300, "{name} shows the model");
        assert!(identical(&stereo, &mono), "the {name} eye equals its mono render");
    }
    assert!(!identical(&dir.path().join("s-left.png"), &dir.path().join("s-right.png")));
    let sbs = dir.path().join("sbs.png");
    let args = [
        &["render", model.as_str()][..],
        &base,
        &["--stereo", "0.3", "--stereo-output", "side-by-side", "--out", sbs.to_str().unwrap()],
    ]
    .concat();
    ok(&mpirun(3, &[], &args));
    let ((w, h, both), (_, _, l), (_, _, r)) =
        (pixels(&sbs), pixels(&dir.path().join("s-left.png")), pixels(&dir.path().join("s-right.png")));
    assert_eq!((w, h), (192, 64));
    for y in 0..64usize {
        assert_eq!(&both[y * 768..y * 768 + 384], &l[y * 384..(y + 1) * 384], "left half, row {y}");
        assert_eq!(&both[y * 768 + 384..(y + 1) * 768], &r[y * 384..(y + 1) * 384], "right half, row {y}");
    }
}

/// A wall of listed displays placed in the world, head tracked along `--eye-path`: every
/// display of every frame equals the crop of one mono render with the wall's off-axis
/// frustum from that frame's eye (the flags from [`master::composite::Wall::camera_args`]),
/// under `mpirun -np 3`; the picture moves as the eye does.
#[test]
fn a_head_tracked_wall_shows_each_eyes_window() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/spot.obj");
    let text =
        "[plane]\nbottom_left = [-0.9, -0.6, 0.6]\nbottom_right = [0.9, -0.6, 0.6]\ntop_left = [-0.9, 0.6, 0.6]\n\
                [[display]]\nname = \"left\"\nx = 6\ny = 10\nwidth = 48\nheight = 64\nbezel = 4\n\
                [[display]]\nname = \"right\"\nx = 66\ny = 4\nwidth = 48\nheight = 40\nbezel = [4, 4, 6, 36]\n";
    let wall_path = dir.path().join("wall.toml");
    std::fs::write(&wall_path, text).unwrap();
    let wall = master::composite::Wall::parse(text).unwrap();
    assert_eq!(wall.frame_size(), (120, 80));
    let eyes = [glam::Vec3::new(0.0, 0.0, 2.5), glam::Vec3::new(0.7, 0.5, 2.0)];
    let eye_path = dir.path().join("eyes.txt");
    std::fs::write(
        &eye_path,
        format!("# x y z\n{} {} {}\n{},{},{}\n", eyes[0].x, eyes[0].y, eyes[0].z, eyes[1].x, eyes[1].y, eyes[1].z),
    )
    .unwrap();
    let out = dir.path().join("w.png");
    let args = [
        "render",
        model.as_str(),
        "--wall",
        wall_path.to_str().unwrap(),
        "--eye-path",
        eye_path.to_str().unwrap(),
        "--frames",
        "2",
        "--tiles",
        "4x2",
        "--out",
        out.to_str().unwrap(),
    ];
    ok(&mpirun(3, &[], &args));
    for (k, &eye) in eyes.iter().enumerate() {
        let a = wall.camera_args(&Default::default(), eye).unwrap();
        let whole = dir.path().join(format!("whole{k}.png"));
        render_alone(&model, "120x80", &frustum_flags(&a), &whole);
        let (_, _, full) = pixels(&whole);
        for d in &wall.displays {
            let shown = dir.path().join(format!("w-{:04}-display-{}.png", k + 1, d.name));
            let (dw, dh, px) = pixels(&shown);
            let [x0, y0, x1, y1] = d.rect;
            assert_eq!((dw, dh), (x1 - x0, y1 - y0));
            for y in 0..dh {
                let at = (((y0 + y) * 120 + x0) * 4) as usize;
                let row = &px[(y * dw * 4) as usize..((y + 1) * dw * 4) as usize];
                assert_eq!(row, &full[at..at + (dw * 4) as usize], "frame {k}, display {}, row {y}", d.name);
            }
        }
        assert!(covered(&dir.path().join(format!("w-{:04}-display-left.png", k + 1))) > 100, "frame {k}");
    }
    let displays = |k: u32| pixels(&dir.path().join(format!("w-{k:04}-display-left.png"))).2;
    assert_ne!(displays(1), displays(2), "the picture moves with the eye");
    // An eye behind the wall is named with its line.
    std::fs::write(&eye_path, "0 0 3\n0 0 -2\n").unwrap();
    let bad = alone(&args);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("eyes.txt: line 2") && err.contains("not in front of it"), "{err}");
}

/// Sixteen workers (`mpirun --oversubscribe -np 17`): a 64-tile frame equals the
/// single-process frame, and a wall of 16 displays shows its crops of it.
#[test]
fn sixteen_workers_on_64_tiles_and_16_displays() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/spot.obj");
    let reference = reference(&model, "128x96", dir.path());
    assert!(covered(&reference) > 1000);
    let out = dir.path().join("np17.png");
    ok(&mpirun(17, &[], &["render", &model, "--size", "128x96", "--tiles", "8x8", "--out", out.to_str().unwrap()]));
    assert!(identical(&out, &reference), "-np 17, 8x8 tiles");
    let wall = dir.path().join("wall16.toml");
    std::fs::write(&wall, "columns = 4\nrows = 4\ndisplay_width = 32\ndisplay_height = 24\n").unwrap();
    let walled = dir.path().join("wall.png");
    let args =
        ["render", &model, "--wall", wall.to_str().unwrap(), "--tiles", "8x4", "--out", walled.to_str().unwrap()];
    ok(&mpirun(17, &[], &args));
    assert!(identical(&walled, &reference), "the overview of a bezel-less wall is the frame");
    let (_, _, full) = pixels(&reference);
    for r in 0..4u32 {
        for c in 0..4u32 {
            let (dw, dh, d) = pixels(&dir.path().join(format!("wall-display-{c}-{r}.png")));
            assert_eq!((dw, dh), (32, 24));
            for y in 0..24 {
                let at = (((r * 24 + y) * 128 + c * 32) * 4) as usize;
                assert_eq!(&d[(y * 128) as usize..((y + 1) * 128) as usize], &full[at..at + 128], "display {c},{r}");
            }
        }
    }
}

/// Direct send (`--display-ranks`): the display ranks write every display of every frame
/// (and of each stereo eye) exactly as rank 0 composites them; rank 0 receives no pixel and
/// writes no overview; the stats give each view's displays' completion spread and a swap
/// after the last display is complete, in frame order.
#[test]
fn display_ranks_write_the_same_displays_behind_a_swap_barrier() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/spot.obj");
    let wall = dir.path().join("wall.toml");
    std::fs::write(
        &wall,
        "[[display]]\nname = \"tall\"\nx = 4\ny = 4\nwidth = 40\nheight = 72\nbezel = 4\n\
         [[display]]\nname = \"a\"\nx = 52\ny = 4\nwidth = 60\nheight = 34\nbezel = [4, 4, 4, 2]\n\
         [[display]]\nname = \"b\"\nx = 52\ny = 42\nwidth = 60\nheight = 34\nbezel = [4, 2, 4, 4]\n",
    )
    .unwrap();
    let names = ["tall", "a", "b"];
    let run = |np: usize, out: &str, extra: &[&str]| {
        let out = dir.path().join(out);
        let stats = out.with_extension("jsonl");
        let mut args = vec!["render", model.as_str(), "--wall", wall.to_str().unwrap(), "--tiles", "4x3"];
        args.extend(extra);
        args.extend(["--out", out.to_str().unwrap(), "--stats", stats.to_str().unwrap()]);
        ok(&mpirun(np, &[], &args));
        let lines: Vec<serde_json::Value> =
            std::fs::read_to_string(&stats).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        lines.into_iter().filter(|l| l["rank"] == 0).collect::<Vec<_>>()
    };
    let frames = ["--frames", "3", "--orbit"];
    let composited = run(3, "a.png", &frames);
    let direct = run(5, "b.png", &[&frames[..], &["--display-ranks", "2"]].concat());
    for k in 1..=3 {
        for name in names {
            let (a, b) = (format!("a-{k:04}-display-{name}.png"), format!("b-{k:04}-display-{name}.png"));
            assert!(identical(&dir.path().join(&a), &dir.path().join(&b)), "{b} equals {a}");
        }
        assert!(dir.path().join(format!("a-{k:04}.png")).exists());
        assert!(!dir.path().join(format!("b-{k:04}.png")).exists(), "rank 0 writes no overview");
    }
    assert!(covered(&dir.path().join("b-0001-display-a.png")) > 200);
    assert!(composited.iter().all(|l| l["pixel_bytes"].as_u64().unwrap() > 0 && l.get("displays").is_none()));
    let mut last_swap = 0.0;
    for l in &direct {
        assert_eq!(l["pixel_bytes"], 0, "rank 0 carries no display pixels: {l}");
        let d = &l["displays"];
        assert_eq!(d["displays"], 3);
        let (first, last, swap) = (
            d["first_ready_ms"].as_f64().unwrap(),
            d["last_ready_ms"].as_f64().unwrap(),
            d["swap_ms"].as_f64().unwrap(),
        );
        assert!((d["spread_ms"].as_f64().unwrap() - (last - first)).abs() < 1e-6 && first <= last, "{l}");
        assert!(swap + 1.0 >= last && swap > last_swap, "the swap follows every display, in frame order: {l}");
        last_swap = swap;
    }
    // Stereo: each eye's displays.
    run(3, "c.png", &["--stereo", "0.2"]);
    run(4, "d.png", &["--stereo", "0.2", "--display-ranks", "1"]);
    for eye in ["left", "right"] {
        for name in names {
            let (c, d) = (format!("c-{eye}-display-{name}.png"), format!("d-{eye}-display-{name}.png"));
            assert!(identical(&dir.path().join(&c), &dir.path().join(&d)), "{d} equals {c}");
        }
    }
    let bad = alone(&["render", &model, "--display-ranks", "2", "--out", dir.path().join("x.png").to_str().unwrap()]);
    assert!(!bad.status.success() && String::from_utf8_lossy(&bad.stderr).contains("--display-ranks needs a --wall"));
}

/// A wall whose displays stand at an angle (two walls of a CAVE, meeting in a corner), each
/// with its corners in the world: every display gets a frame and an off-axis frustum of its
/// own, and equals a mono render with that frustum (the flags from
/// `Wall::display_camera_args`) pixel for pixel, alone and in stereo under mpirun; the model
/// seen through the corner shows on both.
#[test]
fn displays_at_an_angle_each_get_their_own_frustum() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/spot.obj");
    let text = "eye = [-1.5, 0.0, 1.5]\n\
                [[display]]\nname = \"front\"\nx = 0\ny = 0\nwidth = 64\nheight = 48\nbezel = [0, 0, 4, 0]\n\
                corners = { bottom_left = [-3.0, -2.25, -3.0], bottom_right = [3.0, -2.25, -3.0], top_left = [-3.0, 2.25, -3.0] }\n\
                [[display]]\nname = \"side\"\nx = 68\ny = 0\nwidth = 64\nheight = 48\n\
                corners = { bottom_left = [3.0, -2.25, -3.0], bottom_right = [3.0, -2.25, 3.0], top_left = [3.0, 2.25, -3.0] }\n";
    let wall_path = dir.path().join("cave.toml");
    std::fs::write(&wall_path, text).unwrap();
    let wall = master::composite::Wall::parse(text).unwrap();
    assert!(wall.per_display());
    let mono = |i: usize, eye: glam::Vec3, out: &Path| {
        let a = wall.display_camera_args(i, &Default::default(), eye).unwrap();
        render_alone(&model, "64x48", &frustum_flags(&a), out);
    };
    let out = dir.path().join("cave.png");
    ok(&alone(&[
        "render",
        &model,
        "--wall",
        wall_path.to_str().unwrap(),
        "--tiles",
        "2x2",
        "--out",
        out.to_str().unwrap(),
    ]));
    let eye = glam::Vec3::new(-1.5, 0.0, 1.5);
    for (i, name) in ["front", "side"].into_iter().enumerate() {
        let expected = dir.path().join(format!("mono-{name}.png"));
        mono(i, eye, &expected);
        let shown = dir.path().join(format!("cave-display-{name}.png"));
        assert!(covered(&shown) > 100, "{name} shows part of the model");
        assert!(identical(&shown, &expected), "display {name} equals its own frustum's render");
    }
    let (w, h, overview) = pixels(&out);
    assert_eq!((w, h), (132, 48));
    let (_, _, side) = pixels(&dir.path().join("cave-display-side.png"));
    assert_eq!(&overview[(10 * 132 + 68) * 4..(10 * 132 + 132) * 4], &side[10 * 64 * 4..11 * 64 * 4]);
    // Stereo under mpirun: each eye's displays.
    let sep = 0.4f32;
    let args = [
        "render",
        model.as_str(),
        "--wall",
        wall_path.to_str().unwrap(),
        "--tiles",
        "2x2",
        "--stereo",
        "0.4",
        "--out",
        out.to_str().unwrap(),
    ];
    ok(&mpirun(3, &[], &args));
    let right = wall.right().unwrap();
    for (eye_name, at) in [("left", eye - right * sep * 0.5), ("right", eye + right * sep * 0.5)] {
        for (i, name) in ["front", "side"].into_iter().enumerate() {
            let expected = dir.path().join(format!("mono-{eye_name}-{name}.png"));
            mono(i, at, &expected);
            let shown = dir.path().join(format!("cave-{eye_name}-display-{name}.png"));
            assert!(identical(&shown, &expected), "{eye_name} eye, display {name}");
        }
    }
}
