//! End-to-end tests of `tessera view`, as a person uses it, on an X server without a screen
//! (Xvfb, which `scripts/setup.sh` installs): the window's pixels, read back from the server
//! with `xwd`, equal `render`'s PNG of the same frame; a drag and keys sent with `xdotool`
//! move the camera as the guide says, take a screenshot equal to `render`'s and quit; an idle
//! window costs no CPU; without `DISPLAY` the command fails with one line naming it.

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::xvfb::{as_shown, Xvfb};
use common::{alone, bin, mpi_env, ok, pixels, refused_one_line, LiveRun};
use serde_json::Value;
use testkit::mesh_arg as mesh;

const SIZE: (u32, u32) = (320, 240);

/// `tessera view` on `x`, with a control port to read its state from.
fn start_view(x: &Xvfb, model: &str, out: &Path) -> LiveRun {
    let mut cmd = Command::new(bin());
    mpi_env(&mut cmd)
        .env("DISPLAY", &x.display)
        .args(["view", model, "--size", &format!("{}x{}", SIZE.0, SIZE.1), "--tiles", "2x2"])
        .args(["--out", out.to_str().unwrap(), "--control", "127.0.0.1:0"]);
    LiveRun::start(&mut cmd, Stdio::null(), true)
}

/// The eye's direction from the target, in degrees about +Y.
fn yaw(status: &Value) -> f64 {
    let v = |k: &str, i: usize| status[k][i].as_f64().unwrap();
    (v("eye", 0) - v("target", 0)).atan2(v("eye", 2) - v("target", 2)).to_degrees()
}

#[test]
fn the_window_shows_render_s_frame_and_input_steers_it() {
    let dir = tempfile::tempdir().unwrap();
    let x = Xvfb::start();
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let view = start_view(&x, &model, &dir.path().join("shot.png"));
    let first = view.wait_frames(1);
    let window = x.xdotool(&["search", "--sync", "--name", "^Tessera: bunny_zipper_c3d"]);
    let window = window.lines().next().unwrap().to_string();
    x.xdotool(&["windowfocus", "--sync", &window]);

    // Idle: the frame is shown and nothing changes.
    std::thread::sleep(Duration::from_millis(500));
    let before = view.cpu_seconds();
    std::thread::sleep(Duration::from_secs(5));
    let idle = view.cpu_seconds() - before;
    eprintln!("view: CPU over 5 idle seconds: {idle:.3} s");
    assert!(idle < 0.25, "an idle window used {idle:.3} s of CPU in 5 s");

    // The heads-up line off (H), the window's pixels are render's frame.
    let reference = dir.path().join("reference.png");
    let size = format!("{}x{}", SIZE.0, SIZE.1);
    ok(&alone(&["render", &model, "--size", &size, "--tiles", "1x1", "--out", reference.to_str().unwrap()]));
    let expected = as_shown(&reference);
    x.xdotool(&["key", "h"]);
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let (w, h, shown) = x.pixels_of(&window);
        assert_eq!((w, h), SIZE, "the window has the frame's size");
        let differing = shown.iter().zip(&expected).filter(|(a, b)| a != b).count();
        if differing == 0 {
            break;
        }
        if Instant::now() >= deadline {
            let rows: Vec<usize> = (0..SIZE.1 as usize)
                .filter(|y| {
                    (0..SIZE.0 as usize).any(|x| shown[y * SIZE.0 as usize + x] != expected[y * SIZE.0 as usize + x])
                })
                .collect();
            panic!(
                "{differing} of the window's pixels differ from render's frame, in rows {:?} to {:?}; {}",
                rows.first(),
                rows.last(),
                view.ask(r#"{"cmd":"status"}"#)
            );
        }
        std::thread::sleep(Duration::from_millis(100));
    }

    // P: a screenshot, equal to render's PNG.
    x.xdotool(&["key", "p"]);
    let shot = dir.path().join("shot-0001.png");
    let deadline = Instant::now() + Duration::from_secs(20);
    while !shot.exists() {
        assert!(Instant::now() < deadline, "no screenshot");
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(pixels(&shot), pixels(&reference), "the screenshot is render's frame");

    // A drag of 60 pixels to the right orbits the eye by 18 degrees (0.3 a pixel), one frame.
    let (cx, cy) = (SIZE.0 / 2, SIZE.1 / 2);
    let at = |dx: u32| [(cx + dx).to_string(), cy.to_string()];
    let [x0, y0] = at(0);
    x.xdotool(&["mousemove", "--window", &window, &x0, &y0, "mousedown", "1"]);
    for dx in [20, 40, 60] {
        let [x1, y1] = at(dx);
        x.xdotool(&["mousemove", "--window", &window, &x1, &y1]);
    }
    x.xdotool(&["mouseup", "1"]);
    // The drag's moves join frames as they come (one frame, or a few): the eye ends 18
    // degrees around, and the window shows it.
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let moved = view.wait_frames(2);
        let turned = yaw(&moved) - yaw(&first);
        if (turned.abs() - 18.0).abs() < 0.01 {
            break;
        }
        assert!(Instant::now() < deadline, "turned {turned} degrees: {first} -> {moved}");
        std::thread::sleep(Duration::from_millis(100));
    }
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let (_, _, after) = x.pixels_of(&window);
        if after.iter().zip(&expected).filter(|(a, b)| a != b).count() > 100 {
            break;
        }
        assert!(Instant::now() < deadline, "the window does not show the new view");
        std::thread::sleep(Duration::from_millis(100));
    }

    // A larger window re-plans the frame at its size: render's frame of that camera there.
    x.xdotool(&["windowsize", "--sync", &window, "400", "300"]);
    let resized = view.wait_frames(3);
    let v = |k: &str| {
        let a: Vec<String> = (0..3).map(|i| resized[k][i].as_f64().unwrap().to_string()).collect();
        a.join(",")
    };
    let big = dir.path().join("big.png");
    ok(&alone(&[
        "render",
        &model,
        "--size",
        "400x300",
        "--tiles",
        "1x1",
        "--eye",
        &v("eye"),
        "--target",
        &v("target"),
        "--out",
        big.to_str().unwrap(),
    ]));
    let expected = as_shown(&big);
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let (w, h, shown) = x.pixels_of(&window);
        if (w, h) == (400, 300) && shown == expected {
            break;
        }
        assert!(Instant::now() < deadline, "the resized window does not show render's 400x300 frame");
        std::thread::sleep(Duration::from_millis(100));
    }
    // G: the tile grid over the frame, its 2x2 tiles outlined in their cost's tint.
    x.xdotool(&["key", "g"]);
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let (_, _, shown) = x.pixels_of(&window);
        // The left edge of the tile at the top right, at x = 200: a pure red-to-green tint.
        let edge = shown[150 * 400 + 200];
        let (r, g, b) = (edge >> 16, (edge >> 8) & 255, edge & 255);
        if b == 0 && r + g >= 254 && r + g <= 256 && shown != expected {
            break;
        }
        assert!(Instant::now() < deadline, "no tile grid: {edge:06x}");
        std::thread::sleep(Duration::from_millis(100));
    }

    // Q quits, cleanly.
    x.xdotool(&["key", "q"]);
    assert!(view.wait().success(), "Q ends the view cleanly");
}

#[test]
fn without_a_display_the_view_fails_naming_it() {
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let out = common::output(mpi_env(&mut Command::new(bin())).env_remove("DISPLAY").args(["view", &model]));
    refused_one_line(&out, "DISPLAY");
    refused_one_line(&alone(&["view", &model, "--frames", "2"]), "--frames");
}
