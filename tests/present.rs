//! End-to-end tests of `render --present`, a live wall in windows, on an X server without a
//! screen (Xvfb): under mpirun the display ranks open one window per display where the wall
//! file places them, each showing exactly `render`'s PNG of its display, in lockstep; input
//! in the first display's window steers the whole cluster; a display rank slow to open its
//! window does not stall the start-up nor count as dead; rank 0 opens the windows itself
//! without display ranks; without `DISPLAY` the run fails with one line naming it.

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::xvfb::{as_shown, Xvfb};
use common::{alone, bin, mpi_env, ok, refused, refused_one_line, LiveRun};
use serde_json::Value;
use testkit::mesh_arg as mesh;

/// Two 320x240 displays side by side with 20 pixels of bezel between them; the wall's pixel
/// (0, 0) at (10, 20) on the X screen, so the windows open at (10, 20) and (350, 20).
const WALL: &str = "[window]\nx = 10\ny = 20\n\
                    [[display]]\nname = \"left\"\nx = 0\ny = 0\nwidth = 320\nheight = 240\nbezel = [0, 0, 10, 0]\n\
                    [[display]]\nname = \"right\"\nx = 340\ny = 0\nwidth = 320\nheight = 240\nbezel = [10, 0, 0, 0]\n";

/// `render`'s frame of `model` on `wall` (4x2 tiles) with the camera of a run's `status`,
/// as `out` and its `-display-NAME.png` files.
fn render_at(model: &str, wall: &str, status: &Value, out: &Path) {
    let v = |k: &str| (0..3).map(|i| status[k][i].as_f64().unwrap().to_string()).collect::<Vec<_>>().join(",");
    let (eye, target) = (v("eye"), v("target"));
    let args = ["render", model, "--wall", wall, "--tiles", "4x2", "--eye", &eye, "--target", &target];
    ok(&alone(&[&args[..], &["--out", out.to_str().unwrap()]].concat()));
}

/// The window whose title ends with `display NAME`, with its position and size.
fn window(x: &Xvfb, name: &str) -> (String, String) {
    let id = x.xdotool(&["search", "--sync", "--name", &format!("display {name}$")]);
    let id = id.lines().next().unwrap().to_string();
    let geometry = x.xdotool(&["getwindowgeometry", &id]);
    (id, geometry)
}

/// Waits until every window shows its display of `render`'s frame `reference` (its
/// `-display-NAME.png` files).
fn wait_shown(x: &Xvfb, windows: &[(&str, &str)], reference: &Path, what: &str) {
    let expected: Vec<Vec<u32>> = windows
        .iter()
        .map(|(name, _)| {
            let stem = reference.file_stem().unwrap().to_str().unwrap();
            as_shown(&reference.with_file_name(format!("{stem}-display-{name}.png")))
        })
        .collect();
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let differing: Vec<usize> = windows
            .iter()
            .zip(&expected)
            .map(|((_, id), want)| {
                let (w, h, shown) = x.pixels_of(id);
                assert_eq!((w, h), (320, 240), "a window has its display's size");
                shown.iter().zip(want).filter(|(a, b)| a != b).count()
            })
            .collect();
        if differing.iter().all(|&d| d == 0) {
            return;
        }
        assert!(Instant::now() < deadline, "{what}: pixels differing from render's displays: {differing:?}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// CPU seconds used by `run`'s process and its descendants (mpirun and its ranks, which
/// mpirun puts in process groups of their own).
fn tree_cpu_seconds(run: &LiveRun) -> f64 {
    // pid -> (parent, user and system ticks).
    let mut procs = std::collections::HashMap::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else { continue };
        let Ok(stat) = std::fs::read_to_string(entry.path().join("stat")) else { continue };
        let Some((_, rest)) = stat.rsplit_once(')') else { continue };
        let fields: Vec<&str> = rest.split_whitespace().collect();
        // The parent is field 4 of the line, 1 after the command; utime and stime 14 and 15.
        let ticks = fields[11].parse::<f64>().unwrap() + fields[12].parse::<f64>().unwrap();
        procs.insert(pid, (fields[1].parse::<u32>().unwrap(), ticks));
    }
    let in_tree = |mut pid: u32| loop {
        if pid == run.child.id() {
            return true;
        }
        match procs.get(&pid) {
            Some(&(parent, _)) if parent > 1 => pid = parent,
            _ => return false,
        }
    };
    let ticks: f64 = procs.iter().filter(|(&pid, _)| in_tree(pid)).map(|(_, &(_, t))| t).sum();
    ticks / unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64
}

#[test]
fn a_wall_under_mpirun_shows_each_display_in_its_window_in_lockstep() {
    let dir = tempfile::tempdir().unwrap();
    let wall = dir.path().join("wall.toml");
    std::fs::write(&wall, WALL).unwrap();
    let (wall, model) = (wall.to_str().unwrap(), mesh("stanford/bunny_zipper_c3d.obj.gz"));
    let reference = dir.path().join("reference.png");
    ok(&alone(&["render", &model, "--wall", wall, "--tiles", "4x2", "--out", reference.to_str().unwrap()]));

    let x = Xvfb::start();
    // Rank 0, a worker and two display ranks; the second display rank (rank 3) takes 5 s to
    // open its window, past the 3 s --timeout: its heartbeats keep it alive, and no rank
    // waits on it but rank 0.
    let mut cmd = Command::new("mpirun");
    mpi_env(&mut cmd)
        .args(["--oversubscribe", "-np", "4", "-x", &format!("DISPLAY={}", x.display)])
        .args(["-x", "TESSERA_FAULT=window:3:5000", bin(), "render", &model, "--wall", wall])
        .args(["--display-ranks", "2", "--present", "--control", "127.0.0.1:0", "--tiles", "4x2", "--timeout", "3"]);
    let run = LiveRun::start(&mut cmd, Stdio::null(), true);
    let first = run.wait_frames(1);

    // Two windows, at their places on the wall, each showing its display of render's frame.
    let (left, left_at) = window(&x, "left");
    let (right, right_at) = window(&x, "right");
    assert!(left_at.contains("Position: 10,20") && left_at.contains("Geometry: 320x240"), "{left_at}");
    assert!(right_at.contains("Position: 350,20") && right_at.contains("Geometry: 320x240"), "{right_at}");
    let windows = [("left", left.as_str()), ("right", right.as_str())];
    wait_shown(&x, &windows, &reference, "the first frame");

    // Still: nothing is sorted, sent or drawn, on any rank.
    std::thread::sleep(Duration::from_millis(500));
    let before = tree_cpu_seconds(&run);
    std::thread::sleep(Duration::from_secs(5));
    let idle = tree_cpu_seconds(&run) - before;
    eprintln!("present: CPU of mpirun and its 4 ranks over 5 idle seconds: {idle:.3} s");
    assert!(idle < 0.5, "an idle wall used {idle:.3} s of CPU in 5 s");

    // A program steers: both displays show render's frame of the new camera.
    let turned = run.ask(r#"{"cmd":"orbit","degrees":30}"#);
    assert_eq!(turned["ok"], "orbit", "{turned}");
    let status = run.wait_frames(2);
    let orbited = dir.path().join("orbited.png");
    render_at(&model, wall, &status, &orbited);
    wait_shown(&x, &windows, &orbited, "after an orbit command");

    // A person steers from the first display's window: a drag of 60 pixels orbits the eye
    // 18 degrees, and the other display follows.
    x.xdotool(&["windowfocus", "--sync", &left]);
    x.xdotool(&["mousemove", "--window", &left, "100", "120", "mousedown", "1"]);
    for dx in [120, 140, 160] {
        x.xdotool(&["mousemove", "--window", &left, &dx.to_string(), "120"]);
    }
    x.xdotool(&["mouseup", "1"]);
    let yaw = |s: &Value| {
        let c = |k: &str, i: usize| s[k][i].as_f64().unwrap();
        (c("eye", 0) - c("target", 0)).atan2(c("eye", 2) - c("target", 2)).to_degrees()
    };
    let deadline = Instant::now() + Duration::from_secs(60);
    let dragged = loop {
        let now = run.wait_frames(3);
        if ((yaw(&now) - yaw(&status)).abs() - 18.0).abs() < 0.01 {
            break now;
        }
        assert!(Instant::now() < deadline, "the drag turned {first} -> {status} -> {now}");
        std::thread::sleep(Duration::from_millis(100));
    };
    let after = dir.path().join("dragged.png");
    render_at(&model, wall, &dragged, &after);
    wait_shown(&x, &windows, &after, "after a drag in the first display's window");

    // Snapshots need rank 0's frame, which display ranks never send it: refused, the run goes on.
    let snap = run.ask(&format!(r#"{{"cmd":"snapshot","path":"{}"}}"#, dir.path().join("s.png").display()));
    assert!(snap["error"].as_str().unwrap().contains("display ranks hold the frames"), "{snap}");

    // Q in the other display's window ends every rank, cleanly.
    x.xdotool(&["windowfocus", "--sync", &right]);
    x.xdotool(&["key", "q"]);
    assert!(run.wait().success(), "Q ends the wall cleanly");
}

#[test]
fn without_display_ranks_rank_0_opens_the_wall_s_windows() {
    let dir = tempfile::tempdir().unwrap();
    let wall = dir.path().join("wall.toml");
    std::fs::write(&wall, WALL).unwrap();
    let (wall, model) = (wall.to_str().unwrap(), mesh("stanford/bunny_zipper_c3d.obj.gz"));
    let reference = dir.path().join("reference.png");
    ok(&alone(&["render", &model, "--wall", wall, "--tiles", "4x2", "--out", reference.to_str().unwrap()]));
    // Alone (rank 0 and a worker thread), then under mpirun with one worker rank.
    for np in [0, 2] {
        let x = Xvfb::start();
        let mut cmd = Command::new(if np == 0 { bin() } else { "mpirun" });
        mpi_env(&mut cmd);
        if np > 0 {
            cmd.args(["--oversubscribe", "-np", "2", "-x", &format!("DISPLAY={}", x.display), bin()]);
        }
        cmd.env("DISPLAY", &x.display).args(["render", &model, "--wall", wall, "--present"]);
        let run = LiveRun::start(cmd.args(["--control", "127.0.0.1:0", "--tiles", "4x2"]), Stdio::null(), true);
        run.wait_frames(1);
        let (left, left_at) = window(&x, "left");
        let (right, right_at) = window(&x, "right");
        assert!(left_at.contains("Position: 10,20") && right_at.contains("Position: 350,20"), "{left_at} {right_at}");
        wait_shown(&x, &[("left", &left), ("right", &right)], &reference, "rank 0's windows");
        assert_eq!(run.ask(r#"{"cmd":"quit"}"#)["ok"], "quit");
        assert!(run.wait().success(), "quit ends the run cleanly (np {np})");
    }
}

#[test]
fn without_a_display_present_fails_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let wall = dir.path().join("wall.toml");
    std::fs::write(&wall, WALL).unwrap();
    let (wall, model) = (wall.to_str().unwrap(), mesh("stanford/bunny_zipper_c3d.obj.gz"));
    let out =
        common::output(mpi_env(&mut Command::new(bin())).env_remove("DISPLAY").args(["render", &model, "--present"]));
    refused_one_line(&out, "DISPLAY");
    // Under mpirun, the display rank that cannot open its windows ends every rank, naming why.
    let mut cmd = Command::new("mpirun");
    mpi_env(&mut cmd).env_remove("DISPLAY").args(["--oversubscribe", "-np", "4", bin(), "render", &model]);
    let out = common::output(cmd.args(["--wall", wall, "--display-ranks", "2", "--present", "--tiles", "4x2"]));
    refused(&out, "the windows need an X display, and DISPLAY is not set");
    // Display ranks in a run that is not live write files, as before; in a live run they need windows.
    refused_one_line(
        &alone(&["render", &model, "--wall", wall, "--display-ranks", "2", "--control", "127.0.0.1:0"]),
        "--display-ranks",
    );
}

#[test]
fn a_window_opens_on_the_monitor_the_wall_file_names() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let x = Xvfb::start();
    let wall = |window: &str| {
        let path = dir.path().join("wall.toml");
        std::fs::write(
            &path,
            format!("[[display]]\nname = \"only\"\nx = 0\ny = 0\nwidth = 320\nheight = 240\n{window}\n"),
        )
        .unwrap();
        path.to_str().unwrap().to_string()
    };
    // Xvfb's one monitor, by index: the window at (30, 40) from its top-left corner.
    let w = wall("window = { monitor = 0, x = 30, y = 40 }");
    let mut cmd = Command::new(bin());
    mpi_env(&mut cmd).env("DISPLAY", &x.display).args([
        "render",
        &model,
        "--wall",
        &w,
        "--present",
        "--control",
        "127.0.0.1:0",
        "--tiles",
        "2x2",
    ]);
    let run = LiveRun::start(&mut cmd, Stdio::null(), false);
    run.wait_frames(1);
    let (_, at) = window(&x, "only");
    assert!(at.contains("Position: 30,40") && at.contains("Geometry: 320x240"), "{at}");
    assert_eq!(run.ask(r#"{"cmd":"quit"}"#)["ok"], "quit");
    assert!(run.wait().success());
    // A monitor the X display does not have: one line naming the monitors it has.
    let w = wall("window = { monitor = \"no-such\", fullscreen = true }");
    let out = common::output(mpi_env(&mut Command::new(bin())).env("DISPLAY", &x.display).args([
        "render",
        &model,
        "--wall",
        &w,
        "--present",
    ]));
    refused_one_line(
        &out,
        "the window of Tessera: bunny_zipper_c3d.obj.gz, display only: no monitor no-such on this X display (it has ",
    );
}
