//! Issue 47's hostile builds, each a regression test on files the test makes itself: `nsp
//! build` flags that would cut a model into more cells than a reader opens, `.nsp` headers
//! and counts that do not fit `f32` or the cap, a full temporary folder, interrupted builds
//! that must leave no temporary folder, and `pm build` refusing up front a model whose edge
//! has more faces than one `.dpm` operation adds. Every message is one line, names the
//! file and field for a file's content and the flags only for the flags.

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{cmd, entries, ok, refused_one_line, tessera, tessera_env};
use testkit::{arg as s, stderr};

/// A bumpy `n x n` grid as OBJ: `2 (n - 1)^2` triangles.
fn grid_obj(path: &Path, n: usize) {
    let mut out = String::new();
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
            out += &format!("v {x} {y} {}\n", 0.25 * (6.0 * x).sin() * (5.0 * y).cos());
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let v = j * n + i + 1;
            out += &format!("f {} {} {}\nf {} {} {}\n", v, v + 1, v + n + 1, v, v + n + 1, v + n);
        }
    }
    std::fs::write(path, out).unwrap();
}

/// The same grid as binary STL (which `nsp build` loads whole and builds in core).
fn grid_stl(path: &Path, n: usize) {
    let p = |i: usize, j: usize| {
        let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
        [x, y, 0.25 * (6.0 * x).sin() * (5.0 * y).cos()]
    };
    let mut tris = Vec::new();
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            tris.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
            tris.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
    let mut out = vec![0u8; 80];
    out.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in tris {
        out.extend_from_slice(&[0u8; 12]);
        for c in t.iter().flatten() {
            out.extend_from_slice(&c.to_le_bytes());
        }
        out.extend_from_slice(&[0, 0]);
    }
    std::fs::write(path, out).unwrap();
}

#[test]
fn nsp_build_flags_that_cut_a_model_into_too_many_cells_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    // 6,962 triangles, about the spot.obj (5,856), out of core (OBJ) and in core
    // (STL): both accepted flag values together split every occupied cell into 4,096 down
    // to the last level, which aborted at 2.5 GB.
    let obj = dir.path().join("grid.obj");
    grid_obj(&obj, 60);
    let stl = dir.path().join("grid.stl");
    grid_stl(&stl, 60);
    let out = dir.path().join("m.nsp");
    for input in [&obj, &stl] {
        let t = Instant::now();
        let o = tessera(&["nsp", "build", s(input), "--splits", "16", "--min-simplices", "1", "-o", s(&out)]);
        refused_one_line(&o, "--splits 16 with --min-simplices 1 cuts this model into at least ");
        assert!(stderr(&o).contains("raise --min-simplices or lower --splits"), "{}", stderr(&o));
        assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
        assert!(!out.exists());
    }
    // The cap follows --max-decompressed: the default build of the same model is refused
    // under a cap of a few cells.
    let o = tessera(&["nsp", "build", s(&obj), "--min-simplices", "200", "--max-decompressed", "4K", "-o", s(&out)]);
    refused_one_line(&o, "--splits 4 with --min-simplices 200 cuts this model into at least ");
    ok(&tessera(&["nsp", "build", s(&obj), "--min-simplices", "200", "-o", s(&out)]));
    assert_eq!(entries(dir.path()), ["grid.obj", "grid.stl", "m.nsp"]);
}

/// Puts `v` at byte `at` of an `.nsp` file's header and makes its checksum match (the
/// header is bytes 8..136, its CRC-32 the next four).
fn patch_header(bytes: &mut [u8], at: usize, v: f64) {
    bytes[at..at + 8].copy_from_slice(&v.to_le_bytes());
    let crc = crc32fast::hash(&bytes[8..136]);
    bytes[136..140].copy_from_slice(&crc.to_le_bytes());
}

#[test]
fn nsp_files_whose_header_or_counts_do_not_fit_are_refused_by_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("grid.obj");
    grid_obj(&obj, 40);
    let good = dir.path().join("good.nsp");
    ok(&tessera(&["nsp", "build", s(&obj), "--min-simplices", "200", "-o", s(&good)]));
    let bytes = std::fs::read(&good).unwrap();
    let ply = dir.path().join("out.ply");
    ok(&tessera(&["nsp", "adapt", s(&good), "--full", "-o", s(&ply)]));

    // The cube's origin (x at byte 16, y at 24) and side (40): finite as f64, beyond f32; a
    // side of 1e38 and an origin of 3e38 each fit, their sum does not.
    for (name, patches, field) in [
        ("origin.nsp", &[(16, 1e300)][..], "header: the cube's origin 1e300 and side "),
        (
            "corner.nsp",
            &[(24, 3e38), (40, 1e38)][..],
            "header: the cube's origin 3e38 and side 1e38 on y do not fit f32",
        ),
        ("side.nsp", &[(40, f64::NAN)][..], "header: the cube's side is NaN"),
    ] {
        let mut b = bytes.clone();
        for &(at, v) in patches {
            patch_header(&mut b, at, v);
        }
        let path = dir.path().join(name);
        std::fs::write(&path, b).unwrap();
        for args in [vec!["nsp", "stats", s(&path)], vec!["nsp", "adapt", s(&path), "--full", "-o", s(&ply)]] {
            let o = tessera(&args);
            refused_one_line(&o, &format!("{}: not an .nsp file: {field}", path.display()));
        }
    }
    // The footer's count of cells against --max-decompressed, before the table is read.
    let o = tessera(&["nsp", "stats", s(&good), "--max-decompressed", "4K"]);
    refused_one_line(&o, &format!("{}: the footer counts ", good.display()));
    assert!(stderr(&o).contains("raise it with --max-decompressed"), "{}", stderr(&o));
    ok(&tessera(&["nsp", "stats", s(&good)]));
}

#[test]
fn a_full_temporary_folder_is_one_error_naming_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("grid.obj");
    grid_obj(&obj, 60);
    let temp = dir.path().join("temp");
    std::fs::create_dir(&temp).unwrap();
    let out = dir.path().join("m.nsp");
    // Full from the first write (the positions), and full later (the buckets or after).
    for budget in ["0", "100000", "400000"] {
        let t = Instant::now();
        let o = tessera_env(
            &[("TESSERA_FAULT", &format!("temp-full:{budget}"))],
            &["nsp", "build", s(&obj), "--temp-dir", s(&temp), "-o", s(&out)],
        );
        refused_one_line(
            &o,
            &format!(
                "error: cannot build {}: cannot write temporary files in {}: No space left on device",
                obj.display(),
                temp.display()
            ),
        );
        assert!(!stderr(&o).contains("tessera-nsp"), "no temporary names: {}", stderr(&o));
        assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
        assert!(entries(&temp).is_empty(), "{:?}", entries(&temp));
        assert_eq!(entries(dir.path()), ["grid.obj", "temp"]);
    }
    ok(&tessera(&["nsp", "build", s(&obj), "--temp-dir", s(&temp), "-o", s(&out)]));
    assert!(entries(&temp).is_empty());
}

/// Starts `args` with `fault`, waits until `ready` holds, signals it, and checks it ends
/// with 130 and "interrupted".
fn interrupt(fault: &str, args: &[&str], signal: &str, ready: impl Fn() -> bool) {
    let mut child =
        cmd().env("TESSERA_FAULT", fault).args(args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let start = Instant::now();
    while !ready() {
        assert!(start.elapsed() < Duration::from_secs(30), "{signal}: the build never got there");
        assert!(child.try_wait().unwrap().is_none(), "{signal}: the build ended early");
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(Command::new("kill").arg(signal).arg(child.id().to_string()).status().unwrap().success());
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{signal}: {}", stderr(&o));
    assert!(stderr(&o).ends_with("tessera: interrupted\n"), "{signal}: {}", stderr(&o));
}

#[test]
fn an_interrupted_nsp_build_leaves_no_temporary_folder() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("grid.obj");
    grid_obj(&obj, 60);
    let temp = dir.path().join("temp");
    std::fs::create_dir(&temp).unwrap();
    let out = dir.path().join("m.nsp");
    for signal in ["-INT", "-TERM"] {
        // The hook pauses the build once its folder holds the buckets and the canonical
        // simplices' file: a build's folder with files in it.
        let has_files = || {
            std::fs::read_dir(&temp).unwrap().any(|e| {
                let p = e.unwrap().path();
                p.join("canonical").exists() && p.join("b").is_dir()
            })
        };
        let args = ["nsp", "build", s(&obj), "--temp-dir", s(&temp), "-o", s(&out)];
        interrupt("slow-build:20000", &args, signal, has_files);
        assert!(entries(&temp).is_empty(), "{signal}: {:?}", entries(&temp));
        assert_eq!(entries(dir.path()), ["grid.obj", "temp"], "{signal}");
    }
}

#[test]
fn an_interrupted_spilling_pm_build_leaves_its_spill_folder_as_it_was() {
    // Spill files are unnamed (O_TMPFILE): the folder holds nothing of the build's at any
    // time, so a signal has nothing to remove there. The spill folder must be on a disk.
    let dir = tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).unwrap();
    let obj = dir.path().join("grid.obj");
    grid_obj(&obj, 120);
    let spill = dir.path().join("spill");
    std::fs::create_dir(&spill).unwrap();
    let out = dir.path().join("m.dpm");
    let temp_output = || entries(dir.path()).iter().any(|n| n.starts_with(".tessera-"));
    let args = ["pm", "build", s(&obj), "--spill-dir", s(&spill), "--spill-min-mb", "0", "-o", s(&out)];
    interrupt("slow-write:20000", &args, "-INT", temp_output);
    assert!(entries(&spill).is_empty(), "{:?}", entries(&spill));
    assert_eq!(entries(dir.path()), ["grid.obj", "spill"]);
}

#[test]
fn pm_build_refuses_up_front_an_edge_of_more_faces_than_an_operation_adds() {
    let dir = tempfile::tempdir().unwrap();
    const PAGES: usize = 66_000;
    // A book: 66,000 triangles on the edge between vertices 0 and 1. Its collapse would
    // remove them all in one operation (a .dpm operation adds at most 65,535 faces).
    let mut book = String::from("v 0 0 0\nv 0 0 1\n");
    for i in 0..PAGES {
        let t = i as f32 / PAGES as f32 * std::f32::consts::TAU;
        book += &format!("v {} {} 0.5\n", t.cos(), t.sin());
    }
    for i in 0..PAGES {
        book += &format!("f 1 2 {}\n", i + 3);
    }
    let path = dir.path().join("book.obj");
    std::fs::write(&path, book).unwrap();
    let out = dir.path().join("book.dpm");
    let t = Instant::now();
    let o = tessera(&["pm", "build", s(&path), "-o", s(&out)]);
    refused_one_line(
        &o,
        &format!(
            "error: cannot build {}: vertices 0 and 1 share 66000 faces; a .dpm operation adds at most 65535",
            path.display()
        ),
    );
    assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
    assert!(!out.exists());
    // A fan of as many faces around one vertex builds: each of its edges has two.
    let mut fan = String::from("v 0 0 1\n");
    for i in 0..PAGES {
        let t = i as f32 / PAGES as f32 * std::f32::consts::TAU;
        fan += &format!("v {} {} 0\n", t.cos(), t.sin());
    }
    for i in 0..PAGES {
        fan += &format!("f 1 {} {}\n", i + 2, (i + 1) % PAGES + 2);
    }
    let path = dir.path().join("fan.obj");
    std::fs::write(&path, fan).unwrap();
    ok(&tessera(&["pm", "build", s(&path), "-o", s(&dir.path().join("fan.dpm"))]));
}
