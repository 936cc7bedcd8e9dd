//! Issue 12's hostile inputs and flags, each a regression test: outputs that never destroy
//! anything, sizes checked before allocation, bounded reads, timeouts that mean silence,
//! stats that survive, and warnings where images would be garbage. Special files are ones
//! the test makes itself (a FIFO, a private `mknod` copy of the null device), never the
//! system's own.

mod common;

use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::{bin, cmd, ok, output, pixels, refused, tessera, tessera_env};
use testkit::{arg as s, mesh_arg as mesh, stderr};

fn mkfifo(path: &Path) {
    assert!(Command::new("mkfifo").arg(path).status().unwrap().success());
}

/// Reads a FIFO to its end on another thread.
fn drain(path: &Path) -> std::thread::JoinHandle<Vec<u8>> {
    let path = path.to_path_buf();
    std::thread::spawn(move || {
        let mut v = Vec::new();
        std::fs::File::open(path).unwrap().read_to_end(&mut v).unwrap();
        v
    })
}

fn is_fifo(p: &Path) -> bool {
    std::os::unix::fs::FileTypeExt::is_fifo(&std::fs::symlink_metadata(p).unwrap().file_type())
}

fn leftovers(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".tessera-"))
        .collect()
}

/// Waits until `stats` holds at least `lines` lines, at most `limit`.
fn wait_for_lines(stats: &Path, lines: usize, limit: Duration, what: &str) {
    let start = Instant::now();
    while std::fs::read_to_string(stats).map_or(0, |t| t.lines().count()) < lines {
        assert!(start.elapsed() < limit, "{what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Sends SIGINT (`-INT`) or another signal to `child` and returns its exit code.
fn send_signal(child: &mut std::process::Child, sig: &str) -> Option<i32> {
    assert!(Command::new("kill").args([sig, &child.id().to_string()]).status().unwrap().success());
    child.wait().unwrap().code()
}

#[test]
fn special_outputs_are_written_in_place() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/woody.obj");
    // A FIFO gets the bytes and stays a FIFO.
    let fifo = dir.path().join("out.bft");
    mkfifo(&fifo);
    let reader = drain(&fifo);
    ok(&tessera(&["encode", &model, "-o", s(&fifo)]));
    let bytes = reader.join().unwrap();
    assert!(is_fifo(&fifo));
    assert!(codec::bft::decode(&bytes).is_ok(), "the FIFO's reader got a whole .bft");
    // A private copy of the null device stays a device (as root; skipped where mknod is not
    // allowed).
    let null = dir.path().join("null.bft");
    if Command::new("mknod").arg(&null).args(["c", "1", "3"]).status().is_ok_and(|s| s.success()) {
        ok(&tessera(&["encode", &model, "-o", s(&null)]));
        let t = std::fs::symlink_metadata(&null).unwrap().file_type();
        assert!(std::os::unix::fs::FileTypeExt::is_char_device(&t), "still a device");
    }
    // A symlink to a FIFO stays a symlink; `--stats` lines go through it.
    let stats_fifo = dir.path().join("stats-fifo");
    mkfifo(&stats_fifo);
    let link = dir.path().join("stats.jsonl");
    std::os::unix::fs::symlink(&stats_fifo, &link).unwrap();
    let reader = drain(&stats_fifo);
    let png = dir.path().join("f.png");
    ok(&tessera(&["render", &model, "--size", "32x24", "--tiles", "1x1", "--out", s(&png), "--stats", s(&link)]));
    let lines = String::from_utf8(reader.join().unwrap()).unwrap();
    assert_eq!(lines.lines().count(), 2, "{lines}");
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    // `-` is standard output, and the summary moves to stderr.
    let o = tessera(&["encode", &model, "-o", "-"]);
    ok(&o);
    assert!(codec::bft::decode(&o.stdout).is_ok());
    assert!(stderr(&o).contains("triangles"));
    assert!(leftovers(dir.path()).is_empty());
}

#[test]
fn outputs_never_overwrite_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("m.obj");
    std::fs::copy(mesh("classic/woody.obj"), &obj).unwrap();
    let original = std::fs::read(&obj).unwrap();
    let same = |o: &Output| refused(o, "same file");
    // The extension check comes first; a hard link with the right extension is caught by inode.
    refused(&tessera(&["encode", s(&obj), "-o", s(&obj)]), "must end in .bft");
    let hard_bft = dir.path().join("m.bft");
    std::fs::hard_link(&obj, &hard_bft).unwrap();
    same(&tessera(&["encode", s(&obj), "-o", s(&hard_bft)]));
    let hard_dpm = dir.path().join("m.dpm");
    std::fs::hard_link(&obj, &hard_dpm).unwrap();
    same(&tessera(&["pm", "build", s(&obj), "-o", s(&hard_dpm)]));
    // A symlink to the input, under another name.
    let link = dir.path().join("link.ply");
    std::os::unix::fs::symlink(&obj, &link).unwrap();
    let dpm = dir.path().join("s.dpm");
    ok(&tessera(&["pm", "build", s(&obj), "-o", s(&dpm)]));
    let dpm_bytes = std::fs::read(&dpm).unwrap();
    let dpm_ply = dir.path().join("s.ply");
    std::fs::hard_link(&dpm, &dpm_ply).unwrap();
    same(&tessera(&["pm", "adapt", s(&dpm), "--full", "-o", s(&dpm_ply)]));
    // Two outputs of one command that are the same file.
    let png = dir.path().join("f.png");
    refused(&tessera(&["render", s(&obj), "--size", "32x24", "--out", s(&png), "--stats", s(&png)]), "twice");
    let png2 = dir.path().join("./f.png");
    refused(&tessera(&["render", s(&obj), "--size", "32x24", "--out", s(&png), "--stats", s(&png2)]), "same file");
    refused(&tessera(&["render", s(&link), "--size", "32x24", "--out", s(&png), "--stats", s(&obj)]), "same file");
    assert_eq!(std::fs::read(&obj).unwrap(), original);
    assert_eq!(std::fs::read(&dpm).unwrap(), dpm_bytes);
    assert!(!png.exists());
}

#[test]
fn output_formats_follow_the_extension() {
    let dir = tempfile::tempdir().unwrap();
    let dpm = dir.path().join("w.dpm");
    ok(&tessera(&["pm", "build", &mesh("classic/woody.obj"), "-o", s(&dpm)]));
    let obj = dir.path().join("a.obj");
    ok(&tessera(&["pm", "adapt", s(&dpm), "--full", "-o", s(&obj)]));
    let text = std::fs::read_to_string(&obj).expect("an OBJ is text");
    assert!(text.lines().any(|l| l.starts_with("v ")) && text.lines().any(|l| l.starts_with("f ")));
    let m = codec::load_path(&obj).unwrap();
    assert!(!m.triangles.is_empty());
    refused(&tessera(&["pm", "adapt", s(&dpm), "--full", "-o", s(&dir.path().join("a.stl"))]), ".ply or .obj");
    refused(&tessera(&["pm", "build", &mesh("classic/woody.obj"), "-o", s(&dir.path().join("x.bft"))]), ".dpm");
    refused(&tessera(&["decode", s(&dpm), "-o", s(&dir.path().join("x.png"))]), ".ply or .obj");
}

#[test]
fn an_interrupted_write_leaves_no_temporary_file() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.bft");
    for signal in ["-TERM", "-INT"] {
        let mut child = cmd()
            .env("TESSERA_FAULT", "slow-write:20000")
            .args(["encode", &mesh("classic/woody.obj"), "-o", s(&out)])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let start = Instant::now();
        while leftovers(dir.path()).is_empty() {
            assert!(start.elapsed() < Duration::from_secs(30), "no temporary file appeared");
            std::thread::sleep(Duration::from_millis(20));
        }
        assert_eq!(send_signal(&mut child, signal), Some(130), "{signal}");
        assert!(leftovers(dir.path()).is_empty(), "{signal}: {:?}", leftovers(dir.path()));
        assert!(!out.exists());
    }
}

#[test]
fn dumps_clear_only_their_own_files() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("dump");
    let model = mesh("classic/woody.obj");
    ok(&tessera(&["sort", &model, "--size", "64x64", "--tiles", "4x4", "--dump", s(&dump)]));
    let tiles =
        |d: &Path| std::fs::read_dir(d).unwrap().filter(|e| e.as_ref().unwrap().file_name() != "summary.json").count();
    assert!(tiles(&dump) > 1);
    ok(&tessera(&["sort", &model, "--size", "64x64", "--tiles", "1x1", "--dump", s(&dump)]));
    assert_eq!(tiles(&dump), 1, "no stale tiles from the earlier dump");
    std::fs::write(dump.join("notes.txt"), b"mine").unwrap();
    refused(&tessera(&["sort", &model, "--size", "64x64", "--tiles", "2x2", "--dump", s(&dump)]), "notes.txt");
    assert_eq!(std::fs::read(dump.join("notes.txt")).unwrap(), b"mine");
    assert!(dump.join("tile-0.ply").exists(), "a refused dump removes nothing");
}

#[test]
fn sizes_are_checked_before_allocation() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("f.png");
    let model = mesh("classic/woody.obj");
    for size in ["192000x108000", "4294967295x4294967295", "16385x16"] {
        let start = Instant::now();
        refused(&tessera(&["render", &model, "--size", size, "--out", s(&png)]), "at most 16384");
        assert!(start.elapsed() < Duration::from_secs(5));
        refused(&tessera(&["sort", &model, "--size", size]), "at most 16384");
    }
    for (text, needle) in [
        ("columns = 2\nrows = 1\ndisplay_width = 2147483649\ndisplay_height = 10\n", "4294967298x10"),
        ("columns = 2\nrows = 1\ndisplay_width = 50\ndisplay_height = 10\nbezel_x = 4294967196\n", "at most 16384"),
        ("columns = 9\nrows = 1\ndisplay_width = 1920\ndisplay_height = 1080\n", "at most 16384"),
    ] {
        let wall = dir.path().join("wall.toml");
        std::fs::write(&wall, text).unwrap();
        refused(&tessera(&["render", &model, "--wall", s(&wall), "--out", s(&png)]), needle);
    }
    // A frame larger than a worker's texture limit is refused at the handshake, before the
    // first frame (the hook makes rank 1 report a 64-pixel limit).
    let o = tessera_env(&[("TESSERA_FAULT", "texture:1:64")], &["render", &model, "--size", "96x48", "--out", s(&png)]);
    refused(&o, "largest texture side is 64");
    assert!(!stderr(&o).contains("frame 1"));
    assert!(!png.exists());
}

#[test]
fn reads_are_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let start = Instant::now();
    refused(&tessera(&["stats", "/dev/zero"]), "not a regular file");
    let zero = dir.path().join("zero.obj");
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    refused(&tessera(&["encode", s(&zero), "-o", s(&dir.path().join("z.bft"))]), "character device");
    let fifo = dir.path().join("m.obj");
    mkfifo(&fifo);
    refused(&tessera(&["encode", s(&fifo), "-o", s(&dir.path().join("z.bft"))]), "FIFO");
    assert!(start.elapsed() < Duration::from_secs(10));
    // 3 MB of newlines behind 3 KB of gzip: refused at the cap, with the flag that raises it.
    let gz = dir.path().join("nl.obj.gz");
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    std::io::Write::write_all(&mut enc, &vec![b'\n'; 3 << 20]).unwrap();
    std::fs::write(&gz, enc.finish().unwrap()).unwrap();
    let o = tessera(&["encode", s(&gz), "-o", s(&dir.path().join("z.bft")), "--max-decompressed", "1M"]);
    refused(&o, "--max-decompressed");
    let o = tessera(&["encode", s(&gz), "-o", s(&dir.path().join("z.bft")), "--max-decompressed", "4M"]);
    assert!(!stderr(&o).contains("--max-decompressed"), "under the cap the file is parsed: {}", stderr(&o));
}

#[test]
fn numeric_flags_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/woody.obj");
    let png = dir.path().join("f.png");
    for v in ["1e20", "inf", "-inf", "nan", "-0", "0", "-1", "1e-40"] {
        for flag in ["--fovy", "--near", "--far"] {
            let o = tessera(&["sort", &model, "--size", "32x24", "--tiles", "1x1", flag, v]);
            assert!(!stderr(&o).contains("panicked") && o.status.code() != Some(101), "{flag} {v}: {}", stderr(&o));
        }
        for flag in ["--timeout", "--frames", "--max-passes", "--error-px", "--c-lod", "--normal-weight"] {
            let o = tessera(&["render", &model, "--size", "16x16", "--tiles", "1x1", "--out", s(&png), flag, v]);
            assert!(!stderr(&o).contains("panicked") && o.status.code() != Some(101), "{flag} {v}: {}", stderr(&o));
        }
        for flag in ["--error-px", "--normal-weight"] {
            let o = tessera(&["pm", "adapt", "missing.dpm", "-o", s(&dir.path().join("a.ply")), flag, v]);
            assert!(!stderr(&o).contains("panicked") && o.status.code() != Some(101), "{flag} {v}: {}", stderr(&o));
        }
    }
    refused(&tessera(&["render", &model, "--timeout", "1e20", "--out", s(&png)]), "--timeout");
}

#[test]
fn a_busy_worker_is_not_dead() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("f.png");
    // The worker works 3 s on its first frame, three times the timeout, sending heartbeats.
    let o = tessera_env(
        &[("TESSERA_FAULT", "slow:1:3000")],
        &["render", &mesh("classic/woody.obj"), "--size", "32x24", "--timeout", "1", "--out", s(&png)],
    );
    ok(&o);
    assert!(png.exists());
}

#[test]
fn without_mpirun_the_timeout_ends_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("f.png");
    let start = Instant::now();
    let o = tessera_env(
        &[("TESSERA_FAULT", "hang:1")],
        &["render", &mesh("classic/woody.obj"), "--size", "32x24", "--timeout", "2", "--out", s(&png)],
    );
    let took = start.elapsed();
    refused(&o, "sent nothing for 2 s");
    assert!(took < Duration::from_secs(15), "took {took:?}");
    assert!(!png.exists());
}

#[test]
fn stats_survive_an_interrupted_run() {
    let dir = tempfile::tempdir().unwrap();
    // An unwritable stats path fails before the first frame.
    let o = tessera(&[
        "render",
        &mesh("classic/woody.obj"),
        "--size",
        "32x24",
        "--out",
        s(&dir.path().join("f.png")),
        "--stats",
        s(&dir.path().join("missing/s.jsonl")),
    ]);
    refused(&o, "missing");
    assert!(!stderr(&o).contains("frame 1"));
    // Lines are flushed frame by frame: interrupt a long run after its second frame.
    let stats = dir.path().join("s.jsonl");
    let mut child = cmd()
        .args(["render", &mesh("classic/woody.obj"), "--size", "32x24", "--tiles", "2x2", "--frames", "100000"])
        .args(["--orbit", "--out", s(&dir.path().join("f.png")), "--stats", s(&stats)])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for_lines(&stats, 4, Duration::from_secs(60), "no stats lines appeared");
    assert_eq!(send_signal(&mut child, "-INT"), Some(130));
    let text = std::fs::read_to_string(&stats).unwrap();
    let lines: Vec<serde_json::Value> =
        text.lines().map(|l| serde_json::from_str(l).expect("whole JSON lines")).collect();
    assert!(lines.len() >= 4 && lines.len().is_multiple_of(2), "{} lines", lines.len());
    assert_eq!(lines[0]["rank"], 0);
    assert_eq!(lines[1]["rank"], 1);
    assert_eq!(lines[2]["frame"], 1);
    assert!(leftovers(dir.path()).is_empty());
}

#[test]
fn cameras_that_would_give_garbage_are_refused() {
    let model = mesh("classic/woody.obj");
    refused(&tessera(&["sort", &model, "--size", "64x48", "--near", "1e-30"]), "far/near");
    refused(&tessera(&["sort", &model, "--size", "64x48", "--fovy", "1e-30"]), "field of view");
    let o = tessera(&["sort", &model, "--size", "64x48", "--near", "1e-5", "--far", "10"]);
    ok(&o);
    assert!(stderr(&o).contains("warning: far/near"), "{}", stderr(&o));
}

#[test]
fn a_non_finite_model_box_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let bft = dir.path().join("m.bft");
    ok(&tessera(&["encode", &mesh("classic/woody.obj"), "-o", s(&bft)]));
    let mut b = std::fs::read(&bft).unwrap();
    // The header's bbox_max.x, then its checksum made valid again: only the box is wrong.
    // Layout in codec/bft/src/format.rs: the 72-byte header at 12, its CRC-32 at 84.
    b[12 + 60..12 + 64].copy_from_slice(&f32::NAN.to_le_bytes());
    let crc = crc32fast::hash(&b[12..84]);
    b[84..88].copy_from_slice(&crc.to_le_bytes());
    std::fs::write(&bft, &b).unwrap();
    refused(&tessera(&["stats", s(&bft)]), "m.bft");
    let o = tessera(&["sort", s(&bft), "--size", "64x48"]);
    refused(&o, "m.bft");
    assert!(!stderr(&o).contains("bad camera"), "{}", stderr(&o));
}

#[test]
fn a_progressive_mesh_in_many_tiles_costs_no_more_memory() {
    let dir = tempfile::tempdir().unwrap();
    let dpm = dir.path().join("spot.dpm");
    ok(&tessera(&["pm", "build", &mesh("classic/spot.obj"), "-o", s(&dpm)]));
    let peak_kb = |tiles: &str| -> u64 {
        let o = output(
            Command::new("/usr/bin/time")
                .args(["-f", "peak %M"])
                .arg(bin())
                .args(["render", s(&dpm), "--size", "320x180", "--tiles", tiles, "--out"])
                .arg(dir.path().join(format!("f-{tiles}.png")))
                .env("XDG_RUNTIME_DIR", std::env::temp_dir()),
        );
        ok(&o);
        let err = stderr(&o);
        let line = err.lines().find_map(|l| l.strip_prefix("peak ")).expect("a peak line");
        line.trim().parse().unwrap()
    };
    let one = peak_kb("1x1");
    let many = peak_kb("64x64");
    eprintln!("peak memory: 1x1 {one} kB, 64x64 {many} kB ({:.2}x)", many as f64 / one as f64);
    assert!(many <= 2 * one, "64x64 tiles took {many} kB, 1x1 {one} kB");
    // Grouped tiles meet the same error bound: the images agree on almost every pixel.
    let (a, b) = (pixels(&dir.path().join("f-1x1.png")).2, pixels(&dir.path().join("f-64x64.png")).2);
    let (mut covered, mut matching) = (0, 0);
    for (x, y) in a.chunks(4).zip(b.chunks(4)) {
        if x[3] == 0 && y[3] == 0 {
            continue;
        }
        covered += 1;
        matching += usize::from(x[3] == y[3] && x.iter().zip(y).all(|(p, q)| p.abs_diff(*q) <= 8));
    }
    let fraction = matching as f64 / covered as f64;
    eprintln!("{matching} of {covered} covered pixels within 8/255 ({fraction:.4})");
    assert!(covered > 1000 && fraction > 0.99, "{fraction}");
}

/// A damaged chunked model: a directory that does not add up is refused when the file is
/// opened, before any worker starts; a damaged chunk stream is named where it is read, by
/// rank 0 when the chunk straddles a tile border (its tables are built there) and by the
/// worker when it is forwarded verbatim; either way the run ends, and no image is written.
#[test]
fn damaged_chunked_models_name_the_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let bft = dir.path().join("b.bft");
    ok(&tessera(&["encode", &mesh("classic/cow.obj"), "-o", s(&bft), "--chunk-triangles", "500"]));
    let bytes = std::fs::read(&bft).unwrap();
    let file = codec::bft::chunked::ChunkedFile::open(bytes.clone()).expect("a chunked file");
    assert!(file.entries.len() >= 4);
    let hlen = u16::from_le_bytes([bytes[10], bytes[11]]) as usize;
    let out = dir.path().join("f.png");

    // The directory: chunk 2's triangle count off by one (checksum refreshed).
    let mut b = bytes.clone();
    let entry = 16 + hlen + 2 * codec::bft::chunked::ENTRY_LEN + 16;
    b[entry] = b[entry].wrapping_add(1);
    let dir_end = 16 + hlen + file.entries.len() * codec::bft::chunked::ENTRY_LEN;
    let crc = crc32fast::hash(&b[16 + hlen..dir_end]);
    b[dir_end..dir_end + 4].copy_from_slice(&crc.to_le_bytes());
    let bad = dir.path().join("dir.bft");
    std::fs::write(&bad, &b).unwrap();
    for args in [vec!["stats", s(&bad)], vec!["render", s(&bad), "--out", s(&out)]] {
        refused(&tessera(&args), "chunk 3: its first triangle or slot disagrees");
    }

    // A chunk's stream: a byte flipped in the middle of chunk 1.
    let mut b = bytes.clone();
    let e = file.entries[1];
    b[e.offset as usize + e.bft_len as usize / 2] ^= 0x55;
    let bad = dir.path().join("chunk.bft");
    std::fs::write(&bad, &b).unwrap();
    refused(&tessera(&["stats", s(&bad)]), "chunk 1");
    // 1x1: every chunk is forwarded verbatim and the worker decodes it; 8x8: most straddle.
    for tiles in ["1x1", "8x8"] {
        let o = tessera(&["render", s(&bad), "--size", "320x240", "--tiles", tiles, "--out", s(&out)]);
        assert!(!o.status.success(), "{tiles}: must fail");
        assert!(stderr(&o).contains("chunk 1"), "{tiles}: {}", stderr(&o));
        assert!(!out.exists(), "{tiles}: no image");
    }
}

// Issue 47: hostile inputs, round two (outputs, hangs, signals, bounds, cameras).

#[test]
fn a_broken_pipe_ends_quietly() {
    // The reader is gone before the first byte: every write to standard output fails.
    let mut child = cmd()
        .args(["sort", &mesh("classic/woody.obj"), "--size", "256x256", "--tiles", "16x16", "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(141), "the status a shell gives a command ended by SIGPIPE");
    assert_eq!(stderr(&o), "", "quietly");
}

#[test]
fn signals_are_taken_by_one_thread_and_end_the_run_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let stats = dir.path().join("s.jsonl");
    for round in 0..3 {
        let mut command = cmd();
        // SIGHUP as a terminal's run has it, whatever this test inherited: under nohup (a CI
        // started in the background) it arrives ignored, and tessera keeps it so.
        // Safety: signal() is async-signal-safe, and the closure touches nothing else.
        unsafe {
            command.pre_exec(|| {
                libc::signal(libc::SIGHUP, libc::SIG_DFL);
                Ok(())
            })
        };
        let child = command
            .env("TESSERA_FAULT", "slow-write:400")
            .args(["render", &mesh("classic/woody.obj"), "--size", "32x24", "--frames", "1000", "--orbit"])
            .args(["--out", s(&dir.path().join("f.png")), "--stats", s(&stats)])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let start = Instant::now();
        while leftovers(dir.path()).is_empty() {
            assert!(start.elapsed() < Duration::from_secs(60), "no frame is being written");
            std::thread::sleep(Duration::from_millis(10));
        }
        // Every thread (the writer, the worker, rayon's, lavapipe's) blocks the three
        // signals but one, which waits for them.
        let mut open = Vec::new();
        for task in std::fs::read_dir(format!("/proc/{}/task", child.id())).unwrap() {
            let status = std::fs::read_to_string(task.unwrap().path().join("status")).unwrap_or_default();
            let blocked = status.lines().find_map(|l| l.strip_prefix("SigBlk:")).map(str::trim).unwrap_or("0");
            let mask = u64::from_str_radix(blocked, 16).unwrap();
            let all = [libc::SIGINT, libc::SIGTERM, libc::SIGHUP].iter().all(|&s| mask & (1 << (s - 1)) != 0);
            if !all {
                open.push(status.lines().next().unwrap_or("").to_string());
            }
        }
        assert_eq!(open.len(), 1, "threads that take SIGINT, SIGTERM or SIGHUP: {open:?}");
        let signal = ["-INT", "-TERM", "-HUP"][round];
        assert!(Command::new("kill").arg(signal).arg(child.id().to_string()).status().unwrap().success());
        let o = child.wait_with_output().unwrap();
        assert_eq!(o.status.code(), Some(130), "{signal}: {}", stderr(&o));
        assert!(stderr(&o).ends_with("tessera: interrupted\n"), "{signal}: {}", stderr(&o));
        assert!(leftovers(dir.path()).is_empty(), "{signal}: {:?}", leftovers(dir.path()));
        let text = std::fs::read_to_string(&stats).unwrap();
        assert!(text.lines().all(|l| serde_json::from_str::<serde_json::Value>(l).is_ok()), "whole lines");
    }
}

/// A movie of `frames` frames of woody into `out`.
fn movie(out: &Path, frames: &str) -> Output {
    let model = mesh("classic/woody.obj");
    tessera(&["render", &model, "--size", "32x24", "--frames", frames, "--orbit", "--out", s(out)])
}

#[test]
fn movies_follow_the_output_rules() {
    let dir = tempfile::tempdir().unwrap();
    // A symlink to a movie: the file it names is replaced, the link stays.
    let real = dir.path().join("real.mp4");
    std::fs::write(&real, b"old").unwrap();
    let link = dir.path().join("link.mp4");
    std::os::unix::fs::symlink(&real, &link).unwrap();
    ok(&movie(&link, "3"));
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    let bytes = std::fs::read(&real).unwrap();
    assert!(bytes.len() > 100 && &bytes[4..8] == b"ftyp", "an MP4 in the linked file");
    // A FIFO gets the movie's bytes and stays a FIFO.
    let fifo = dir.path().join("pipe.mp4");
    mkfifo(&fifo);
    let reader = drain(&fifo);
    ok(&movie(&fifo, "3"));
    assert_eq!(&reader.join().unwrap()[4..8], b"ftyp");
    assert!(is_fifo(&fifo));
    // A private copy of the null device stays a device.
    let null = dir.path().join("null.mp4");
    assert!(Command::new("mknod").arg(&null).args(["c", "1", "3"]).status().unwrap().success());
    ok(&movie(&null, "2"));
    assert!(std::os::unix::fs::FileTypeExt::is_char_device(&std::fs::symlink_metadata(&null).unwrap().file_type()));
    assert!(leftovers(dir.path()).is_empty() && leftovers(&std::env::temp_dir()).iter().all(|n| !n.contains("movie")));
}

#[test]
fn a_movie_pipe_that_stops_draining_ends_the_run() {
    // An "ffmpeg" that answers -version, then never reads a frame.
    let dir = tempfile::tempdir().unwrap();
    let fake = dir.path().join("ffmpeg");
    std::fs::write(&fake, "#!/bin/sh\n[ \"$1\" = -version ] && exit 0\nexec sleep 120\n").unwrap();
    std::fs::set_permissions(&fake, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let path = format!("{}:{}", dir.path().display(), std::env::var("PATH").unwrap_or_default());
    let out = dir.path().join("m.mp4");
    let start = Instant::now();
    // 256 KB frames: the pipe's buffer fills on the first.
    let model = mesh("classic/woody.obj");
    let args = ["render", &model, "--size", "256x256", "--frames", "8", "--timeout", "2", "--out", s(&out)];
    let o = tessera_env(&[("PATH", &path)], &args);
    refused(&o, "ffmpeg read nothing of frame");
    assert!(start.elapsed() < Duration::from_secs(60), "took {:?}", start.elapsed());
    assert!(!out.exists() && leftovers(dir.path()).is_empty());
}

#[test]
fn standard_output_takes_one_image() {
    let model = mesh("classic/woody.obj");
    refused(&tessera(&["render", &model, "--size", "32x24", "--frames", "2", "--out", "-"]), "--out - takes one image");
    refused(
        &tessera(&["render", &model, "--size", "32x24", "--stereo", "0.1", "--out", "-"]),
        "--out - takes one image",
    );
    let o = tessera(&["render", &model, "--size", "32x24", "--out", "-"]);
    ok(&o);
    assert!(o.stdout.starts_with(b"\x89PNG"));
    assert!(!std::path::Path::new("--0002.png").exists());
}

#[test]
fn two_runs_cannot_share_a_stats_file() {
    use std::os::fd::AsRawFd;
    let dir = tempfile::tempdir().unwrap();
    let stats = dir.path().join("s.jsonl");
    std::fs::write(&stats, b"{\"a run\": 1}\n").unwrap();
    // Another run holds the file (as a running tessera does).
    let held = std::fs::OpenOptions::new().append(true).open(&stats).unwrap();
    assert_eq!(unsafe { libc::flock(held.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) }, 0);
    let model = mesh("classic/woody.obj");
    let png = dir.path().join("f.png");
    let o = tessera(&["render", &model, "--size", "32x24", "--out", s(&png), "--stats", s(&stats)]);
    refused(&o, "being written by another tessera run");
    assert_eq!(std::fs::read(&stats).unwrap(), b"{\"a run\": 1}\n", "the other run's lines are untouched");
    assert!(!png.exists());
    drop(held);
    ok(&tessera(&["render", &model, "--size", "32x24", "--out", s(&png), "--stats", s(&stats)]));
    assert!(std::fs::read_to_string(&stats).unwrap().lines().all(|l| l.contains("\"frame\"")));
}

#[test]
fn an_unwritable_output_folder_is_found_before_the_work() {
    // /proc takes no new files, for root too.
    let model = mesh("stanford/bunny_zipper_c3d.obj.gz");
    for args in [
        vec!["encode", &model, "-o", "/proc/tessera-out.bft"],
        vec!["pm", "build", &model, "-o", "/proc/tessera-out.dpm"],
        vec!["render", &model, "--size", "32x24", "--out", "/proc/tessera-out.png"],
        vec!["nsp", "build", &model, "-o", "/proc/tessera-out.nsp"],
    ] {
        let start = Instant::now();
        let o = tessera(&args);
        refused(&o, "its folder /proc is not writable");
        assert!(start.elapsed() < Duration::from_secs(5), "{args:?}: took {:?}", start.elapsed());
    }
}

#[test]
fn dumps_clear_only_the_files_they_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/woody.obj");
    // A user's file named like a tile is not a dump's.
    let mine = dir.path().join("mine");
    std::fs::create_dir(&mine).unwrap();
    std::fs::write(mine.join("tile-7.ply"), b"ply mine").unwrap();
    refused(&tessera(&["sort", &model, "--size", "64x64", "--tiles", "4x4", "--dump", s(&mine)]), "tile-7.ply");
    assert_eq!(std::fs::read(mine.join("tile-7.ply")).unwrap(), b"ply mine");
    // And neither is a summary.json of the user's, whatever it lists.
    std::fs::write(mine.join("summary.json"), b"{\"dump_files\": []}").unwrap();
    refused(&tessera(&["sort", &model, "--size", "64x64", "--tiles", "4x4", "--dump", s(&mine)]), "tile-7.ply");
    std::fs::write(mine.join("summary.json"), b"{\"totals\": {}}").unwrap();
    std::fs::remove_file(mine.join("tile-7.ply")).unwrap();
    refused(&tessera(&["sort", &model, "--size", "64x64", "--tiles", "4x4", "--dump", s(&mine)]), "not written by");
    assert_eq!(std::fs::read(mine.join("summary.json")).unwrap(), b"{\"totals\": {}}");
    // A dump records its files; the next one removes exactly those.
    let dump = dir.path().join("dump");
    ok(&tessera(&["sort", &model, "--size", "64x64", "--tiles", "4x4", "--dump", s(&dump)]));
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dump.join("summary.json")).unwrap()).unwrap();
    let recorded: Vec<&str> = summary["dump_files"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    let mut on_disk: Vec<String> = std::fs::read_dir(&dump)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != "summary.json")
        .collect();
    on_disk.sort();
    let mut sorted = recorded.clone();
    sorted.sort();
    assert_eq!(on_disk, sorted);
    assert!(recorded.len() > 1);
    ok(&tessera(&["sort", &model, "--size", "64x64", "--tiles", "1x1", "--dump", s(&dump)]));
    assert_eq!(std::fs::read_dir(&dump).unwrap().count(), 2, "summary.json and tile-0.ply");
}

#[test]
fn plots_are_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("t.png");
    let stats = |ranks: usize| {
        let path = dir.path().join(format!("s{ranks}.jsonl"));
        let mut text = String::new();
        for rank in 0..ranks {
            text += &format!(
                "{{\"frame\":0,\"rank\":{rank},\"timeline\":[{{\"stage\":\"render\",\"start_ms\":0,\"end_ms\":1}}]}}\n"
            );
        }
        std::fs::write(&path, text).unwrap();
        path
    };
    let start = Instant::now();
    let many = stats(200_000);
    refused(&tessera(&["plot", s(&many), "-o", s(&png)]), "200000 timeline rows");
    assert!(start.elapsed() < Duration::from_secs(20), "took {:?}", start.elapsed());
    let wide = stats(256);
    refused(&tessera(&["plot", s(&wide), "-o", s(&png), "--width", "16384"]), "--width 16384");
    assert!(!png.exists());
    ok(&tessera(&["plot", s(&stats(3)), "-o", s(&png)]));
}

#[test]
fn walls_have_a_bounded_number_of_displays() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("f.png");
    let model = mesh("classic/woody.obj");
    let wall = dir.path().join("wall.toml");
    let start = Instant::now();
    std::fs::write(&wall, "columns = 400\nrows = 400\ndisplay_width = 1\ndisplay_height = 1\n").unwrap();
    refused(&tessera(&["render", &model, "--wall", s(&wall), "--out", s(&png)]), "at most 1024");
    let listed: String =
        (0..1100).map(|i| format!("[[display]]\nx = {}\ny = 0\nwidth = 1\nheight = 1\n", i * 2)).collect();
    std::fs::write(&wall, listed).unwrap();
    refused(&tessera(&["render", &model, "--wall", s(&wall), "--out", s(&png)]), "at most 1024");
    assert!(start.elapsed() < Duration::from_secs(10), "took {:?}", start.elapsed());
}

#[test]
fn start_up_does_not_depend_on_frames() {
    let dir = tempfile::tempdir().unwrap();
    let stats = dir.path().join("s.jsonl");
    let mut child = cmd()
        .args(["render", &mesh("classic/woody.obj"), "--size", "32x24", "--frames", "4294967295"])
        .args(["--out", s(&dir.path().join("f.png")), "--stats", s(&stats)])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for_lines(&stats, 2, Duration::from_secs(30), "no first frame");
    assert_eq!(send_signal(&mut child, "-INT"), Some(130));
    assert!(dir.path().join("f-0001.png").exists());
}

#[test]
fn every_camera_of_a_run_is_checked() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("f.png");
    let model = mesh("classic/woody.obj");
    let render = |extra: &[&str]| {
        let mut args = vec!["render", &model, "--size", "64x48", "--out", s(&png)];
        args.extend(extra);
        tessera(&args)
    };
    // Stereo eyes this far apart look through a window a trillion frames off their axis.
    let o = render(&["--stereo", "1e30"]);
    refused(&o, "lens shift");
    assert!(stderr(&o).contains("left eye"), "{}", stderr(&o));
    // The last frame of this zoom has its near plane at 1e-30 of the first's.
    let o = render(&["--frames", "3", "--zoom", "1e-30"]);
    refused(&o, "far/near");
    assert!(stderr(&o).contains("frame 3"), "{}", stderr(&o));
    assert!(!dir.path().join("f-0001.png").exists(), "refused before the first frame");
    ok(&render(&["--stereo", "0.05"]));
}

#[test]
fn errors_are_one_line_in_the_users_terms() {
    let dir = tempfile::tempdir().unwrap();
    let model = mesh("classic/woody.obj");
    let png = dir.path().join("f.png");
    let bad_wall = dir.path().join("bad.toml");
    std::fs::write(&bad_wall, "columns = 2\nrows = x\n").unwrap();
    let wall = dir.path().join("wall.toml");
    std::fs::write(
        &wall,
        "plane = { bottom_left = [0,0,0], bottom_right = [1,0,0], top_left = [0,1,0] }\n\
         columns = 2\nrows = 1\ndisplay_width = 64\ndisplay_height = 64\n",
    )
    .unwrap();
    let eyes = dir.path().join("eyes.txt");
    std::fs::write(&eyes, "0 0.5 2\nfoo\n").unwrap();
    for (args, needle) in [
        (vec!["render", &model, "--wall", s(&bad_wall), "--out", s(&png)], "bad.toml: not a valid wall description"),
        (
            vec!["render", &model, "--wall", s(&wall), "--eye-path", s(&eyes), "--out", s(&png)],
            "eyes.txt: line 2: expected x,y,z, got 'foo'",
        ),
    ] {
        let o = tessera(&args);
        refused(&o, needle);
        assert_eq!(stderr(&o).trim_end().lines().count(), 1, "one line: {}", stderr(&o));
    }
}

#[test]
fn an_interrupt_ends_the_run_even_when_it_was_ignored_at_start() {
    // A shell without job control starts background commands with SIGINT ignored.
    let dir = tempfile::tempdir().unwrap();
    let stats = dir.path().join("s.jsonl");
    let script = format!(
        "trap '' INT; exec {} render {} --size 32x24 --frames 100000 --out {} --stats {}",
        bin(),
        mesh("classic/woody.obj"),
        s(&dir.path().join("f.png")),
        s(&stats)
    );
    let xdg = std::env::temp_dir().join("tessera-xdg");
    let mut child = Command::new("sh")
        .args(["-c", &script])
        .env("XDG_RUNTIME_DIR", xdg)
        .env_remove("TESSERA_FAULT")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for_lines(&stats, 2, Duration::from_secs(60), "no stats lines appeared");
    assert_eq!(send_signal(&mut child, "-INT"), Some(130));
    assert!(leftovers(dir.path()).is_empty());
}
