//! End-to-end tests of a live run's control port (`render --control`), as a program steering
//! it would use it: snapshots equal to `render`'s PNG for the same camera flags, cameras and
//! orbits, several clients with stats subscriptions, malformed lines answered while the run
//! goes on, the token rule, a still view that costs no frame and no CPU, and quit.

mod common;

use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{alone, bin, differing, mpi_env, ok, refused_one_line, LiveRun};
use serde_json::Value;
use testkit::mesh_arg as mesh;

const SIZE: &str = "320x240";

/// A live run alone (rank 0 and one worker thread) of `model` in 2x2 tiles, with `extra`.
fn start_live(model: &str, extra: &[&str]) -> LiveRun {
    start_live_with(model, extra, Stdio::null())
}

fn start_live_with(model: &str, extra: &[&str], stdin: Stdio) -> LiveRun {
    let mut cmd = Command::new(bin());
    mpi_env(&mut cmd).args(["render", model, "--size", SIZE, "--tiles", "2x2", "--control", "127.0.0.1:0"]).args(extra);
    LiveRun::start(&mut cmd, stdin, false)
}

/// A connection to `run`'s control port.
fn client(run: &LiveRun) -> Client {
    let stream = TcpStream::connect(&run.addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    Client { reader: BufReader::new(stream.try_clone().unwrap()), stream }
}

struct Client {
    stream: TcpStream,
    reader: BufReader<TcpStream>,
}

impl Client {
    fn send(&mut self, line: &str) {
        self.stream.write_all(format!("{line}\n").as_bytes()).unwrap();
    }

    fn read(&mut self) -> Value {
        let mut line = String::new();
        assert!(self.reader.read_line(&mut line).unwrap() > 0, "the control port closed");
        serde_json::from_str(&line).unwrap_or_else(|e| panic!("not a JSON line: {line:?}: {e}"))
    }

    /// Sends one command and reads its answer.
    fn ask(&mut self, line: &str) -> Value {
        self.send(line);
        self.read()
    }

    /// Asks for a snapshot of the frame shown, into `path`.
    fn snapshot(&mut self, path: &Path) {
        let answer = self.ask(&format!(r#"{{"cmd":"snapshot","path":"{}"}}"#, s(path)));
        assert_eq!(answer["ok"], "snapshot", "{answer}");
    }

    /// Whether the port closed this connection (EOF).
    fn closed(&mut self) -> bool {
        let mut line = String::new();
        matches!(self.reader.read_line(&mut line), Ok(0))
    }
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `render`'s PNG of `model` with these camera flags, for comparison.
fn rendered(model: &str, flags: &[&str], out: &Path) {
    let mut args = vec!["render", model, "--size", SIZE, "--tiles", "1x1", "--out", s(out)];
    args.extend(flags);
    ok(&alone(&args));
}

#[test]
fn snapshots_equal_render_for_the_same_camera() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let live = start_live(&model, &[]);
    let mut c = client(&live);
    let first = dir.path().join("first.png");
    c.snapshot(&first);
    rendered(&model, &[], &dir.path().join("r0.png"));
    assert_eq!(differing(&first, &dir.path().join("r0.png")), 0, "the first frame is render's");

    let answer = c.ask(r#"{"cmd":"camera","eye":[0.1,0.25,0.4],"target":[-0.02,0.1,0.0]}"#);
    assert_eq!((answer["ok"].as_str(), answer["frame"].as_u64()), (Some("camera"), Some(1)), "{answer}");
    let moved = dir.path().join("moved.png");
    c.snapshot(&moved);
    rendered(&model, &["--eye", "0.1,0.25,0.4", "--target", "-0.02,0.1,0"], &dir.path().join("r1.png"));
    assert_eq!(
        differing(&moved, &dir.path().join("r1.png")),
        0,
        "a camera command's frame is render's with those flags"
    );
    assert!(differing(&moved, &first) > 100, "the view moved");

    let answer = c.ask(r#"{"cmd":"orbit","degrees":90}"#);
    assert_eq!(answer["frame"], 2, "{answer}");
    let status = c.ask(r#"{"cmd":"status"}"#);
    assert_eq!(status["frames"], 3, "{status}");
    let (eye, target): (Vec<f64>, Vec<f64>) = (
        status["eye"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect(),
        status["target"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect(),
    );
    let d = |a: &[f64], b: &[f64]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
    let before = d(&[0.1, 0.25, 0.4], &[-0.02, 0.1, 0.0]);
    assert!((d(&eye, &target) - before).abs() < 1e-4, "an orbit keeps the distance: {status}");

    assert_eq!(c.ask(r#"{"cmd":"quit"}"#)["ok"], "quit");
    assert!(live.wait().success(), "quit ends the run cleanly");
}

#[test]
fn clients_share_the_run_and_bad_lines_are_answered() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let live = start_live(&model, &[]);
    let (mut a, mut b) = (client(&live), client(&live));
    for (line, says) in [
        ("{", "not JSON"),
        (r#"{"cmd":"fly"}"#, "fly"),
        (r#"{"cmd":"camera","fovy":500}"#, "fovy"),
        (r#"[1,2,3]"#, "\"cmd\""),
        (r#"{"cmd":"camera","eye":[0,0,0],"target":[0,0,0]}"#, "camera"),
        (&format!(r#"{{"cmd":"snapshot","path":"{}"}}"#, s(&dir.path().join("no/such/dir/x.png"))), "snapshot"),
    ] {
        let answer = a.ask(line);
        let error = answer["error"].as_str().unwrap_or_else(|| panic!("{line}: {answer}"));
        assert!(error.contains(says) && !error.contains('\n'), "{line}: {error}");
    }
    assert_eq!(b.ask(r#"{"cmd":"subscribe"}"#)["ok"], "subscribe");
    assert_eq!(a.ask(r#"{"cmd":"orbit","degrees":30}"#)["frame"], 1);
    // The subscriber gets the stats line of the frame a's command made (after the first
    // frame's, which may still have been in flight when it subscribed).
    let line = loop {
        let line = b.read();
        if line["frame"] != 0 {
            break line;
        }
    };
    assert_eq!(line["frame"], 1, "{line}");
    assert!(line["tiles"].as_array().is_some_and(|t| !t.is_empty()), "{line}");
    // The same view again costs no frame.
    let status = b.ask(r#"{"cmd":"status"}"#);
    let eye = status["eye"].to_string();
    let answer = a.ask(&format!(r#"{{"cmd":"camera","eye":{eye}}}"#));
    assert_eq!(answer["frame"], 1, "an unchanged view makes no frame: {answer}");
    assert_eq!(b.ask(r#"{"cmd":"quit"}"#)["ok"], "quit");
    assert!(live.wait().success());
}

#[test]
fn a_still_view_costs_no_cpu() {
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let live = start_live(&model, &[]);
    let mut c = client(&live);
    // The first frame is done once a snapshot of it is.
    let dir = tempfile::tempdir().unwrap();
    c.snapshot(&dir.path().join("a.png"));
    let before = live.cpu_seconds();
    std::thread::sleep(Duration::from_secs(5));
    let idle = live.cpu_seconds() - before;
    eprintln!("CPU over 5 idle seconds: {idle:.3} s");
    assert!(idle < 0.25, "a still view used {idle:.3} s of CPU in 5 s");
    assert_eq!(c.ask(r#"{"cmd":"status"}"#)["frames"], 1, "no frame while still");
    assert_eq!(c.ask(r#"{"cmd":"quit"}"#)["ok"], "quit");
    assert!(live.wait().success());
}

#[test]
fn a_port_beyond_loopback_needs_a_token_every_client_presents() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    refused_one_line(&alone(&["render", &model, "--size", SIZE, "--control", "0.0.0.0:0"]), "--control-token-file");
    let token = dir.path().join("token");
    std::fs::write(&token, "short\n").unwrap();
    refused_one_line(
        &alone(&["render", &model, "--size", SIZE, "--control", "0.0.0.0:0", "--control-token-file", s(&token)]),
        "at least 16",
    );
    refused_one_line(&alone(&["render", &model, "--control", "127.0.0.1:0", "--frames", "3"]), "--frames");
    std::fs::write(&token, "0123456789abcdef-secret\n").unwrap();
    let live = start_live(&model, &["--control-token-file", s(&token)]);
    let mut stranger = client(&live);
    let answer = stranger.ask(r#"{"cmd":"status"}"#);
    assert!(answer["error"].as_str().is_some_and(|e| e.contains("token")), "{answer}");
    assert!(stranger.closed(), "a client without the token is disconnected");
    let mut wrong = client(&live);
    assert!(wrong.ask(r#"{"token":"0123456789abcdef-guess"}"#)["error"].is_string());
    let mut friend = client(&live);
    assert_eq!(friend.ask(r#"{"token":"0123456789abcdef-secret"}"#)["ok"], "token");
    assert_eq!(friend.ask(r#"{"cmd":"status"}"#)["ok"], "status");
    assert_eq!(friend.ask(r#"{"cmd":"quit"}"#)["ok"], "quit");
    assert!(live.wait().success());
}

/// A level-of-detail `.bft` takes its cut at the live run's screen error: after
/// `error_px`, the frame is render's with that `--error-px`, and a coarser one.
#[test]
fn a_level_of_detail_file_follows_the_error_live() {
    let dir = tempfile::tempdir().unwrap();
    let lod = dir.path().join("lod.bft");
    let bunny = mesh("stanford/bunny_zipper_c3d.obj.gz");
    ok(&alone(&["encode", &bunny, "-o", s(&lod), "--lod", "--chunk-triangles", "2048"]));
    let live = start_live(s(&lod), &[]);
    let mut c = client(&live);
    let fine = dir.path().join("fine.png");
    c.snapshot(&fine);
    rendered(s(&lod), &[], &dir.path().join("r0.png"));
    assert_eq!(differing(&fine, &dir.path().join("r0.png")), 0, "the first frame is render's at 0.5 px");
    assert_eq!(c.ask(r#"{"cmd":"error_px","value":16}"#)["frame"], 1);
    let coarse = dir.path().join("coarse.png");
    c.snapshot(&coarse);
    rendered(s(&lod), &["--error-px", "16"], &dir.path().join("r16.png"));
    assert_eq!(differing(&coarse, &dir.path().join("r16.png")), 0, "error_px 16 is render's --error-px 16");
    assert!(differing(&coarse, &fine) > 0, "a coarser cut looks different");
    assert_eq!(c.ask(r#"{"cmd":"quit"}"#)["ok"], "quit");
    assert!(live.wait().success());
}

#[test]
fn the_grid_the_error_and_balancing_change_live() {
    let dir = tempfile::tempdir().unwrap();
    let bunny = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let dpm = dir.path().join("bunny.dpm");
    ok(&alone(&["pm", "build", &bunny, "-o", s(&dpm)]));
    let live = start_live(s(&dpm), &[]);
    let (mut c, mut stats) = (client(&live), client(&live));
    assert_eq!(stats.ask(r#"{"cmd":"subscribe"}"#)["ok"], "subscribe");
    // The subscriber's line of frame `k` (the first frame's may come before it).
    let mut line_of = |k: u64| loop {
        let line = stats.read();
        if line["frame"].as_u64() == Some(k) {
            break line;
        }
    };
    // A 3x2 grid: the same picture (tiles are exact), cut into six tiles.
    assert_eq!(c.ask(r#"{"cmd":"tiles","cols":3,"rows":2}"#)["frame"], 1);
    let line = line_of(1);
    assert!(line["tiles"].as_array().unwrap().iter().all(|t| t["index"].as_u64() < Some(6)), "{line}");
    let tiled = dir.path().join("tiled.png");
    c.snapshot(&tiled);
    rendered(s(&dpm), &[], &dir.path().join("r0.png"));
    assert_eq!(differing(&tiled, &dir.path().join("r0.png")), 0, "a regridded frame is render's");
    // A coarser error: the frame render draws with --error-px 8.
    assert_eq!(c.ask(r#"{"cmd":"error_px","value":8}"#)["frame"], 2);
    let coarse = dir.path().join("coarse.png");
    c.snapshot(&coarse);
    rendered(s(&dpm), &["--error-px", "8"], &dir.path().join("r8.png"));
    assert_eq!(differing(&coarse, &dir.path().join("r8.png")), 0, "error_px 8 is render's --error-px 8");
    assert!(differing(&coarse, &tiled) > 0, "a coarser mesh looks different");
    // A grid change while a frame of the old grid is in flight (its tiles have no costs in
    // the new one).
    c.send(r#"{"cmd":"orbit","degrees":5}"#);
    c.send(r#"{"cmd":"tiles","cols":1,"rows":1}"#);
    c.send(r#"{"cmd":"tiles","cols":4,"rows":4}"#);
    for _ in 0..3 {
        assert!(c.read()["ok"].is_string());
    }
    c.send(r#"{"cmd":"tiles","cols":3,"rows":2}"#);
    assert!(c.read()["ok"].is_string());
    assert_eq!(c.ask(r#"{"cmd":"status"}"#)["frames"], 7);
    // Balancing on makes a frame; asking again makes none.
    assert_eq!(c.ask(r#"{"cmd":"balance","on":true}"#)["frame"], 7);
    assert_eq!(line_of(7)["frame"], 7);
    assert_eq!(c.ask(r#"{"cmd":"balance","on":true}"#)["frame"], 7);
    for (line, says) in [
        (r#"{"cmd":"tiles","cols":0,"rows":2}"#, "tiles"),
        (r#"{"cmd":"error_px","value":-1}"#, "error_px"),
        (r#"{"cmd":"balance"}"#, "on"),
    ] {
        let answer = c.ask(line);
        assert!(answer["error"].as_str().is_some_and(|e| e.contains(says)), "{line}: {answer}");
    }
    assert_eq!(c.ask(r#"{"cmd":"quit"}"#)["ok"], "quit");
    assert!(live.wait().success());
}

#[test]
fn another_model_of_any_kind_loads_without_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let bunny = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let (bft, dpm) = (dir.path().join("bunny.bft"), dir.path().join("bunny.dpm"));
    // A chunked .bft (the bunny is one stream by default).
    ok(&alone(&["encode", &bunny, "-o", s(&bft), "--chunk-triangles", "4096"]));
    ok(&alone(&["pm", "build", &bunny, "-o", s(&dpm)]));
    let cow = mesh("classic/cow.obj");
    let live = start_live(s(&bft), &[]);
    let mut c = client(&live);
    // .bft to .dpm, to a mesh file, and back to the .bft: each frame is render's of that
    // model with the flags' camera.
    for (k, model) in [(1, s(&dpm)), (2, cow.as_str()), (3, s(&bft))] {
        let answer = c.ask(&format!(r#"{{"cmd":"load","path":"{model}"}}"#));
        assert_eq!((answer["ok"].as_str(), answer["frame"].as_u64()), (Some("load"), Some(k)), "{model}: {answer}");
        let shot = dir.path().join(format!("shot-{k}.png"));
        c.snapshot(&shot);
        let reference = dir.path().join(format!("ref-{k}.png"));
        rendered(model, &[], &reference);
        assert_eq!(differing(&shot, &reference), 0, "{model}: the loaded model's frame is render's");
    }
    // A file that is no model is refused, and the run goes on with the one it has.
    let junk = dir.path().join("junk.bft");
    std::fs::write(&junk, b"not a model").unwrap();
    let answer = c.ask(&format!(r#"{{"cmd":"load","path":"{}"}}"#, s(&junk)));
    assert!(answer["error"].as_str().is_some_and(|e| e.starts_with("load: ") && !e.contains('\n')), "{answer}");
    assert_eq!(c.ask(r#"{"cmd":"orbit","degrees":10}"#)["frame"], 4);
    assert_eq!(c.ask(r#"{"cmd":"quit"}"#)["ok"], "quit");
    assert!(live.wait().success());
}

/// The run's status once `done` holds of it (`what` says what was awaited).
fn wait_status(c: &mut Client, what: &str, done: impl Fn(&Value) -> bool) -> Value {
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let status = c.ask(r#"{"cmd":"status"}"#);
        if done(&status) {
            return status;
        }
        assert!(Instant::now() < deadline, "{what}: {status}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits until the run has made `frames` frames (its status).
fn wait_frames(c: &mut Client, frames: u64) {
    wait_status(c, &format!("no frame {frames}"), |s| s["frames"].as_u64() >= Some(frames));
}

#[test]
fn a_head_tracker_streams_the_eye_of_a_placed_wall() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/spot.obj");
    let wall = dir.path().join("wall.toml");
    std::fs::write(
        &wall,
        "eye = [0.0, 0.0, 2.5]\n\
         [plane]\nbottom_left = [-0.9, -0.6, 0.6]\nbottom_right = [0.9, -0.6, 0.6]\ntop_left = [-0.9, 0.6, 0.6]\n\
         [[display]]\nname = \"left\"\nx = 6\ny = 10\nwidth = 48\nheight = 64\nbezel = 4\n\
         [[display]]\nname = \"right\"\nx = 66\ny = 4\nwidth = 48\nheight = 40\nbezel = [4, 4, 6, 36]\n",
    )
    .unwrap();
    // render's files for each tracked eye: the overview and each display.
    let reference = |eye: &str, name: &str| {
        let eyes = dir.path().join(format!("{name}.txt"));
        std::fs::write(&eyes, format!("{eye}\n")).unwrap();
        let out = dir.path().join(format!("{name}.png"));
        ok(&alone(&["render", &model, "--wall", s(&wall), "--tiles", "2x2", "--eye-path", s(&eyes), "--out", s(&out)]));
        out
    };
    let same = |a: &Path, b: &Path| {
        for suffix in ["", "-display-left", "-display-right"] {
            let with = |p: &Path| p.with_file_name(format!("{}{suffix}.png", p.file_stem().unwrap().to_str().unwrap()));
            assert_eq!(differing(&with(a), &with(b)), 0, "{} against {}", with(a).display(), with(b).display());
        }
    };
    // From standard input: two positions written at once make one frame, of the last.
    let mut live = start_live_with(&model, &["--wall", s(&wall), "--eye-stream", "-"], Stdio::piped());
    let mut c = client(&live);
    let mut stdin = live.child.stdin.take().unwrap();
    stdin.write_all(b"0.3 0.1 2.2\nnot an eye\n0.7,0.5,2.0\n").unwrap();
    stdin.flush().unwrap();
    wait_frames(&mut c, 2);
    let shot = dir.path().join("stdin.png");
    c.snapshot(&shot);
    same(&shot, &reference("0.7 0.5 2.0", "ref-stdin"));
    // The control port's eye command does the same.
    assert_eq!(c.ask(r#"{"cmd":"eye","position":[-0.5,0.2,1.8]}"#)["ok"], "eye");
    let shot = dir.path().join("cmd.png");
    c.snapshot(&shot);
    same(&shot, &reference("-0.5 0.2 1.8", "ref-cmd"));
    assert_eq!(c.ask(r#"{"cmd":"quit"}"#)["ok"], "quit");
    drop(stdin);
    assert!(live.wait().success());

    // From UDP datagrams, on loopback.
    let port = std::net::UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let stream = format!("udp:127.0.0.1:{port}");
    let live = start_live(&model, &["--wall", s(&wall), "--eye-stream", &stream]);
    let mut c = client(&live);
    let tracker = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    tracker.send_to(b"0.2 -0.3 2.4", ("127.0.0.1", port)).unwrap();
    wait_frames(&mut c, 2);
    // The same position again makes no frame.
    tracker.send_to(b"0.2,-0.3,2.4", ("127.0.0.1", port)).unwrap();
    let shot = dir.path().join("udp.png");
    c.snapshot(&shot);
    same(&shot, &reference("0.2 -0.3 2.4", "ref-udp"));
    assert_eq!(c.ask(r#"{"cmd":"quit"}"#)["ok"], "quit");
    assert!(live.wait().success());
    // Beyond loopback without a token: refused.
    refused_one_line(
        &alone(&["render", &model, "--wall", s(&wall), "--control", "127.0.0.1:0", "--eye-stream", "udp:0.0.0.0:0"]),
        "--control-token-file",
    );
}

/// The status once a timed move has ended.
fn wait_still(c: &mut Client) -> Value {
    wait_status(c, "the move did not end", |s| s["animating"] == false)
}

#[test]
fn a_timed_move_shows_frames_along_the_way_and_ends_where_it_was_asked() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let live = start_live(&model, &[]);
    let mut c = client(&live);
    let v = |s: &Value, k: &str| -> Vec<f64> { s[k].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect() };
    let yaw = |s: &Value| {
        let (e, t) = (v(s, "eye"), v(s, "target"));
        (e[0] - t[0]).atan2(e[2] - t[2]).to_degrees()
    };
    let first = c.ask(r#"{"cmd":"status"}"#);
    // An orbit of 60 degrees over 1.5 s: several frames on the way, and it ends 60 degrees round.
    let answer = c.ask(r#"{"cmd":"animate","seconds":1.5,"degrees":60}"#);
    assert_eq!((answer["ok"].as_str(), answer["frame"].as_u64()), (Some("animate"), Some(1)), "{answer}");
    let end = wait_still(&mut c);
    let frames = end["frames"].as_u64().unwrap();
    assert!(frames >= 3, "frames along the way: {end}");
    let turned = (yaw(&end) - yaw(&first) + 540.0) % 360.0 - 180.0;
    assert!((turned.abs() - 60.0).abs() < 0.01, "turned {turned}: {first} -> {end}");
    // The last frame is render's with the camera it ended at.
    let last = dir.path().join("last.png");
    c.snapshot(&last);
    let flag = |k: &str| v(&end, k).iter().map(f64::to_string).collect::<Vec<_>>().join(",");
    rendered(&model, &["--eye", &flag("eye"), "--target", &flag("target")], &dir.path().join("r.png"));
    assert_eq!(differing(&last, &dir.path().join("r.png")), 0, "the move's last frame is render's");
    // A flight to an eye and target ends there.
    assert_eq!(
        c.ask(r#"{"cmd":"animate","seconds":0.5,"eye":[0.1,0.25,0.4],"target":[-0.02,0.1,0.0]}"#)["ok"],
        "animate"
    );
    let there = wait_still(&mut c);
    let close = |a: Vec<f64>, b: [f64; 3]| (0..3).all(|i| (a[i] - b[i]).abs() < 1e-5);
    assert!(close(v(&there, "eye"), [0.1, 0.25, 0.4]) && close(v(&there, "target"), [-0.02, 0.1, 0.0]), "{there}");
    // A steering command takes over from a move in progress.
    assert_eq!(c.ask(r#"{"cmd":"animate","seconds":60,"degrees":360}"#)["ok"], "animate");
    assert_eq!(c.ask(r#"{"cmd":"zoom","factor":0.9}"#)["ok"], "zoom");
    assert_eq!(c.ask(r#"{"cmd":"status"}"#)["animating"], false);
    // Malformed moves are answered with an error, the run goes on.
    for bad in [
        r#"{"cmd":"animate","seconds":0,"degrees":10}"#,
        r#"{"cmd":"animate","seconds":1}"#,
        r#"{"cmd":"animate","seconds":1,"degrees":10,"eye":[0,0,1]}"#,
        r#"{"cmd":"animate","seconds":1e39,"degrees":10}"#,
    ] {
        let e = c.ask(bad);
        assert!(e["error"].as_str().is_some_and(|e| e.starts_with("animate")), "{bad}: {e}");
    }
    assert_eq!(c.ask(r#"{"cmd":"quit"}"#)["ok"], "quit");
    assert!(live.wait().success());
}
