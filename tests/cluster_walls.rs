//! End-to-end tests of tile walls under `mpirun` and alone: each display is its crop of the
//! frame or the render of its own off-axis frustum (bezels, listed displays, head tracking,
//! displays at an angle), stereo eyes, display ranks behind a swap barrier, sixteen workers.

mod common;

use std::path::Path;

use common::{alone, covered, identical, json_lines, mpirun, ok, pixels, reference};
use testkit::mesh_arg as mesh;

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

fn vec3(v: glam::Vec3) -> String {
    format!("{},{},{}", v.x, v.y, v.z)
}

/// The camera flags of an off-axis frustum built by the wall (eye, target, up, field of
/// view, shift), for a mono render of it.
fn frustum_flags(a: &master::camera::CameraSpec) -> Vec<String> {
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
/// frustum from that frame's eye (the flags from [`master::wall::Wall::camera_args`]),
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
    let wall = master::wall::Wall::parse(text).unwrap();
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
        let lines = json_lines(&stats);
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
    let wall = master::wall::Wall::parse(text).unwrap();
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

/// Every display's pixels of one frame of `out` (`OUT-display-NAME.png`), RGBA.
fn display_pixels(out: &Path, names: &[&str]) -> Vec<Vec<u8>> {
    let stem = out.file_stem().unwrap().to_str().unwrap();
    names.iter().map(|n| pixels(&out.with_file_name(format!("{stem}-display-{n}.png"))).2).collect()
}

#[test]
fn pixel_codecs_keep_the_frames_and_say_their_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/spot.obj");
    let wall = dir.path().join("wall.toml");
    std::fs::write(
        &wall,
        "[[display]]\nname = \"a\"\nx = 0\ny = 0\nwidth = 96\nheight = 80\nbezel = [0, 0, 4, 0]\n\
         [[display]]\nname = \"b\"\nx = 104\ny = 0\nwidth = 96\nheight = 80\nbezel = [4, 0, 0, 0]\n",
    )
    .unwrap();
    let names = ["a", "b"];
    // One frame with `codec`, under mpirun with `np` ranks (and two display ranks when 5):
    // rank 0's stats line, and the lines of its workers.
    let run = |np: usize, codec: &str| {
        let out = dir.path().join(format!("{}-{np}.png", codec.replace(':', "-")));
        let stats = out.with_extension("jsonl");
        let mut args = vec!["render", model.as_str(), "--wall", wall.to_str().unwrap(), "--tiles", "4x2"];
        args.extend(["--pixel-codec", codec, "--out", out.to_str().unwrap(), "--stats", stats.to_str().unwrap()]);
        if np == 5 {
            args.extend(["--display-ranks", "2"]);
        }
        ok(&mpirun(np, &[], &args));
        let lines = json_lines(&stats);
        (display_pixels(&out, &names), lines)
    };
    let (raw, raw_stats) = run(3, "raw");
    let (lz4, lz4_stats) = run(3, "lz4");
    let (jpeg, jpeg_stats) = run(3, "jpeg:75");
    let (direct, direct_stats) = run(5, "lz4");
    // Lossless: the same displays, composited by rank 0 or by display ranks.
    assert_eq!(lz4, raw, "LZ4 keeps every pixel");
    assert_eq!(direct, raw, "LZ4 to display ranks keeps every pixel");
    // JPEG: the coverage exact, the colour close.
    for (j, r) in jpeg.iter().zip(&raw) {
        let mut error = 0u64;
        for (a, b) in j.chunks_exact(4).zip(r.chunks_exact(4)) {
            assert_eq!(a[3], b[3], "JPEG keeps the alpha plane");
            error += (0..3).map(|k| (a[k] as i64 - b[k] as i64).unsigned_abs()).sum::<u64>();
        }
        let mean = error as f64 / (j.len() / 4 * 3) as f64;
        assert!(mean < 4.0, "mean colour error {mean}");
    }
    // Stats: bytes as sent and raw, encode and decode ms.
    let master = |lines: &[serde_json::Value]| lines.iter().find(|l| l["rank"] == 0).unwrap().clone();
    let f = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap();
    let (r, l, j, d) = (master(&raw_stats), master(&lz4_stats), master(&jpeg_stats), master(&direct_stats));
    assert_eq!(r["pixel_codec"], "raw");
    assert_eq!(j["pixel_codec"], "jpeg:75");
    assert_eq!(f(&r, "pixel_coded_bytes"), f(&r, "pixel_raw_bytes"), "{r}");
    assert_eq!(f(&l, "pixel_raw_bytes"), f(&r, "pixel_raw_bytes"));
    assert!(f(&l, "pixel_coded_bytes") < f(&r, "pixel_coded_bytes") / 2.0, "{l}");
    assert!(f(&j, "pixel_coded_bytes") < f(&r, "pixel_coded_bytes"), "{j}");
    assert!(f(&l, "pixel_decode_ms") > 0.0 && f(&l, "pixel_bytes") == f(&l, "pixel_coded_bytes"), "{l}");
    let encode: f64 = lz4_stats.iter().filter(|w| w["rank"] != 0).map(|w| f(w, "encode_ms")).sum();
    assert!(encode > 0.0, "workers time their coding");
    // With display ranks: rank 0 gets no pixels, but counts what went to the displays.
    assert_eq!(f(&d, "pixel_bytes"), 0.0);
    assert!(f(&d, "pixel_coded_bytes") > 0.0 && d["displays"]["pixel_decode_ms"].as_f64().unwrap() > 0.0, "{d}");
    // A codec that is none of the three is refused by name.
    let o = alone(&["render", &model, "--pixel-codec", "jpeg:0"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("1 to 100"));
}
