//! Issue 47's hostile inputs to the nSP-tree store, each a regression test on files the test
//! makes itself: header floats that do not fit `f32` refused as corrupt, every count of the
//! file checked against the cap on decompressed input before it is allocated, builds whose
//! flags would make more cells than a reader opens refused before the tree is made, and a
//! full temporary folder that ends the out-of-core build at its first failed write.
//!
//! The cap is process-wide: every test here holds [`LOCK`], so that one test's lowered cap
//! never meets another's file.

use std::io::Write;
use std::path::Path;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use codec::input::{set_max_decompressed_bytes, DEFAULT_MAX_DECOMPRESSED_BYTES};
use codec::nsp::format::{self, CELL_BYTES, FOOTER_LEN, HEADER_LEN, PREFIX_LEN};
use codec::nsp::ooc::{self, Limits, Scratch};
use codec::nsp::{self, Canonical, NspError, NspFile, Params};
use codec::Mesh;

static LOCK: Mutex<()> = Mutex::new(());

/// Holds the lock with the default cap, and restores it when dropped.
struct Settings(#[allow(dead_code)] MutexGuard<'static, ()>);

fn settings() -> Settings {
    let guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    set_max_decompressed_bytes(DEFAULT_MAX_DECOMPRESSED_BYTES);
    Settings(guard)
}

impl Drop for Settings {
    fn drop(&mut self) {
        set_max_decompressed_bytes(DEFAULT_MAX_DECOMPRESSED_BYTES);
    }
}

/// A bumpy `n x n` grid: `2 (n - 1)^2` triangles spread over all three axes.
fn grid(n: usize) -> Mesh {
    let mut positions = Vec::with_capacity(n * n);
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
            positions.push([x, y, 0.25 * (6.0 * x).sin() * (5.0 * y).cos()]);
        }
    }
    let mut triangles = Vec::new();
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let v = (j * n + i) as u32;
            let n = n as u32;
            triangles.push([v, v + 1, v + n + 1]);
            triangles.push([v, v + n + 1, v + n]);
        }
    }
    Mesh { positions, triangles, ..Default::default() }
}

fn built(mesh: &Mesh, params: Params) -> Vec<u8> {
    let canon = Canonical::of_mesh(mesh, params.bits).unwrap();
    nsp::encode(&canon, params, &|_| {}).unwrap().bytes
}

fn one_line(e: &str) {
    assert!(!e.contains('\n') && !e.is_empty(), "one line: {e}");
    for debug in ["{ ", "Some(", "Err(", "Error {", "kind:"] {
        assert!(!e.contains(debug), "no Debug output: {e}");
    }
}

/// Writes `mesh` as a binary little-endian PLY.
fn write_ply(path: &Path, mesh: &Mesh) {
    let mut out = Vec::new();
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangles.len()
    )
    .unwrap();
    for p in &mesh.positions {
        for c in p {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    for t in &mesh.triangles {
        out.push(3);
        for v in t {
            out.extend_from_slice(&(*v as i32).to_le_bytes());
        }
    }
    std::fs::write(path, out).unwrap();
}

fn write_obj(path: &Path, mesh: &Mesh) {
    let mut out = String::new();
    for p in &mesh.positions {
        out += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    for t in &mesh.triangles {
        out += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    std::fs::write(path, out).unwrap();
}

/// Puts `v` at byte `at` of the header and makes the header's checksum match.
fn patch_header(bytes: &mut [u8], at: usize, v: f64) {
    bytes[at..at + 8].copy_from_slice(&v.to_le_bytes());
    let crc = crc32fast::hash(&bytes[8..8 + HEADER_LEN]);
    bytes[8 + HEADER_LEN..PREFIX_LEN].copy_from_slice(&crc.to_le_bytes());
}

/// File offsets of the header's floats (the header starts at byte 8).
const ORIGIN: usize = 8 + 8;
const SIDE: usize = 8 + 32;
const EXTENT: usize = 8 + 96;

#[test]
fn header_floats_that_do_not_fit_f32_are_corrupt() {
    let _s = settings();
    let bytes = built(&grid(12), Params::default());
    let file = NspFile::from_bytes(bytes.clone()).unwrap();
    let drawn = nsp::decode_all(&file).unwrap();
    assert!(drawn.positions.iter().flatten().all(|c| c.is_finite()));
    let side = file.header.cube.side;
    let cases: [(&str, usize, f64, &str); 8] = [
        ("an origin beyond f32", ORIGIN, 1e300, "origin"),
        ("a far corner beyond f32", ORIGIN + 8, 3.4e38, "origin"),
        ("a NaN origin", ORIGIN + 16, f64::NAN, "origin"),
        ("a NaN side", SIDE, f64::NAN, "side"),
        ("an infinite side", SIDE, f64::INFINITY, "side"),
        ("a negative side", SIDE, -1.0, "side"),
        ("an infinite extent", EXTENT + 16, f64::INFINITY, "extent"),
        ("an extent beyond the side", EXTENT, 2.0 * side, "extent"),
    ];
    for (what, at, v, field) in cases {
        let mut b = bytes.clone();
        patch_header(&mut b, at, v);
        // A side of 1e38 that fits f32, with an origin of 3.4e38 (also one), overflows only
        // at the far corner.
        if at == ORIGIN + 8 {
            patch_header(&mut b, SIDE, 1e38);
            patch_header(&mut b, EXTENT, 0.0);
            patch_header(&mut b, EXTENT + 8, 0.0);
            patch_header(&mut b, EXTENT + 16, 0.0);
        }
        let e = match NspFile::from_bytes(b) {
            Err(NspError::Format(e)) => e,
            Err(e) => panic!("{what}: refused as {e}, not as corrupt"),
            Ok(f) => panic!("{what}: opened, would draw at {:?}", nsp::decode_all(&f).map(|d| d.positions[0])),
        };
        assert!(e.starts_with("header: ") && e.contains(field), "{what}: {e}");
        one_line(&e);
    }
}

/// Rewrites the cell table of `bytes` with `edit` applied to its rows.
fn edit_rows(bytes: &[u8], edit: impl FnOnce(&mut Vec<format::CellEntry>)) -> Vec<u8> {
    let n = bytes.len();
    let (_, _, start) = format::read_prefix(&bytes[..n - FOOTER_LEN]).unwrap();
    let (offset, _) = format::read_footer(&bytes[n - FOOTER_LEN..], n as u64, start).unwrap();
    let mut entries = format::read_entries(&bytes[offset as usize..n - FOOTER_LEN], offset, start).unwrap();
    edit(&mut entries);
    let mut out = bytes[..offset as usize].to_vec();
    out.extend_from_slice(&format::write_cell_table(&entries, offset));
    out
}

#[test]
fn counts_of_the_file_are_checked_against_the_cap_before_allocation() {
    let s = settings();
    let params = Params { min_simplices: 200, ..Params::default() };
    let bytes = built(&grid(40), params);
    let cells = NspFile::from_bytes(bytes.clone()).unwrap().entries.len() as u64;
    assert!(cells > 64, "{cells} cells");

    // The footer's count of cells, against the cap: refused one byte below what they take,
    // not at it (from memory and from disk; the rows' own figures are checked next).
    set_max_decompressed_bytes(cells * CELL_BYTES - 1);
    let e = NspFile::from_bytes(bytes.clone()).err().expect("refused under the cap").to_string();
    assert!(e.contains(&format!("the footer counts {cells} cells")) && e.contains("--max-decompressed"), "{e}");
    one_line(&e);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.nsp");
    std::fs::write(&path, &bytes).unwrap();
    let e = NspFile::open(&path).err().expect("refused under the cap").to_string();
    assert!(e.contains(&format!("the footer counts {cells} cells")), "{e}");
    set_max_decompressed_bytes(cells * CELL_BYTES);
    for r in [NspFile::from_bytes(bytes.clone()).err(), NspFile::open(&path).err()] {
        let e = r.map(|e| e.to_string()).unwrap_or_default();
        assert!(!e.contains("footer") && !e.contains("cell table is"), "{e}");
    }
    set_max_decompressed_bytes(DEFAULT_MAX_DECOMPRESSED_BYTES);
    NspFile::open(&path).unwrap();

    // A footer that names 2^32 - 1 cells is refused before any row is read.
    let mut b = bytes.clone();
    let f = b.len() - FOOTER_LEN;
    b[f + 8..f + 12].copy_from_slice(&u32::MAX.to_le_bytes());
    let crc = crc32fast::hash(&b[f..f + 12]);
    b[f + 12..f + 16].copy_from_slice(&crc.to_le_bytes());
    let t = Instant::now();
    let e = NspFile::from_bytes(b).err().expect("refused").to_string();
    assert!(e.contains("4294967295 cells"), "{e}");
    assert!(t.elapsed() < Duration::from_secs(1));

    // A row's "at most" figures bound what its decoder allocates: each is checked.
    let first = |es: &mut Vec<format::CellEntry>| es.iter().position(|e| e.len > 0).unwrap();
    for (field, words) in [("kd-cells", "kd-cells"), ("tops", "top-simplices")] {
        let mut at = 0;
        let b = edit_rows(&bytes, |es| {
            at = first(es);
            match field {
                "kd-cells" => es[at].max_cells = u32::MAX,
                _ => es[at].max_tops = u32::MAX,
            }
        });
        let e = match NspFile::from_bytes(b) {
            Err(e @ NspError::TooLarge(_)) => e.to_string(),
            other => panic!("{field}: {:?}", other.err()),
        };
        assert!(e.starts_with(&format!("cell {at}: ")) && e.contains(&format!("4294967295 {words}")), "{e}");
        assert!(e.contains("--max-decompressed"), "{e}");
        one_line(&e);
    }
    drop(s);
}

#[test]
fn builds_that_would_make_more_cells_than_a_reader_opens_are_refused_before_the_tree() {
    let _s = settings();
    // A 6,962-triangle model, the size of the spot.obj: with --splits 16 and
    // --min-simplices 1 (both accepted) every occupied cell splits into 4,096 down to the
    // last level, which took the in-core partition to an abort at 2.5 GB.
    let mesh = grid(60);
    let params = Params { splits: 16, min_simplices: 1, ..Params::default() };
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("grid.obj");
    write_obj(&obj, &mesh);
    let t = Instant::now();
    let canon = Canonical::of_mesh(&mesh, params.bits).unwrap();
    let in_core = nsp::encode(&canon, params, &|_| {}).err().expect("refused in core");
    let mut sink = Vec::new();
    let out_of_core =
        ooc::build_file(&obj, params, Some(dir.path()), &mut sink, &|_, _, _| {}).err().expect("refused out of core");
    assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
    for e in [in_core, out_of_core] {
        assert!(matches!(e, NspError::TooManyCells(_)), "{e}");
        let e = e.to_string();
        assert!(e.starts_with("--splits 16 with --min-simplices 1 cuts this model into at least "), "{e}");
        assert!(e.contains("raise --min-simplices or lower --splits"), "{e}");
        one_line(&e);
    }
    assert!(sink.is_empty(), "nothing written");

    // The build's cap is the reader's: a tree of exactly the cells a reader opens builds,
    // one cell more does not, in core and out of core alike.
    let params = Params { min_simplices: 200, ..Params::default() };
    let cells = NspFile::from_bytes(built(&mesh, params)).unwrap().entries.len() as u64;
    for (cap, builds) in [(cells * CELL_BYTES, true), (cells * CELL_BYTES - 1, false)] {
        set_max_decompressed_bytes(cap);
        let in_core = nsp::encode(&canon, params, &|_| {});
        let mut out = Vec::new();
        let ooc = ooc::build_file(&obj, params, Some(dir.path()), &mut out, &|_, _, _| {});
        assert_eq!(in_core.is_ok(), builds, "in core, cap {cap}: {:?}", in_core.err());
        assert_eq!(ooc.is_ok(), builds, "out of core, cap {cap}: {:?}", ooc.err());
        if builds {
            assert_eq!(out, in_core.unwrap().bytes);
        } else {
            let e = in_core.err().unwrap().to_string();
            assert!(e.contains(&format!("at least {} cells", cells)), "{e}");
        }
    }
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left, vec![std::ffi::OsString::from("grid.obj")], "temporary folders removed");
}

/// Runs an out-of-core build of `input` whose temporary files fail as on a full disk after
/// `budget` bytes; returns its result and the most bytes of the input each stage reported
/// reading.
fn build_full_after(input: &Path, budget: u64) -> (Result<ooc::Built, NspError>, [u64; 2]) {
    let scratch = tempfile::tempdir().unwrap();
    let shown = Path::new("/the/folder/shown");
    let most = Mutex::new([0u64; 2]);
    let progress = |stage: &str, done: u64, _: u64| {
        let k = match stage {
            "reading vertices" => 0,
            "reading triangles" => 1,
            _ => return,
        };
        let mut m = most.lock().unwrap();
        m[k] = m[k].max(done);
    };
    let s = Scratch { dir: scratch.path(), shown, full_after: Some(budget) };
    let r = ooc::build_in(input, Params::default(), s, &mut Vec::new(), &progress, Limits::default());
    let most = *most.lock().unwrap();
    (r, most)
}

fn assert_full(r: &Result<ooc::Built, NspError>) {
    match r {
        Err(e @ NspError::Temp { write: true, .. }) => {
            let e = e.to_string();
            assert_eq!(e, "cannot write temporary files in /the/folder/shown: No space left on device (os error 28)");
        }
        Err(e) => panic!("not the full disk: {e}"),
        Ok(_) => panic!("built"),
    }
}

#[test]
fn a_full_temporary_folder_ends_the_build_at_its_first_failed_write() {
    let _s = settings();
    let dir = tempfile::tempdir().unwrap();
    // Positions first: 400k vertices (4.8 MB of PLY) and one triangle. The first write
    // fails once the positions' 1 MB buffer fills; the pass ends there instead of failing
    // once more per position to the end of the vertices.
    let mut mesh = grid(632);
    mesh.triangles.truncate(1);
    let ply = dir.path().join("points.ply");
    write_ply(&ply, &mesh);
    let len = std::fs::metadata(&ply).unwrap().len();
    let (r, most) = build_full_after(&ply, 0);
    assert_full(&r);
    assert!(most[0] < len / 2, "read {} of {len} bytes after the disk was full", most[0]);
    assert_eq!(most[1], 0, "the triangles were not read");

    // Triangles next: the positions fit, the first bucket's write fails, and the pass ends
    // there instead of failing once per triangle to the end of the file.
    let mesh = grid(400);
    let ply = dir.path().join("grid.ply");
    write_ply(&ply, &mesh);
    let len = std::fs::metadata(&ply).unwrap().len();
    let (r, most) = build_full_after(&ply, 12 * mesh.positions.len() as u64);
    assert_full(&r);
    assert!(most[1] < len * 2 / 3, "read {} of {len} bytes after the disk was full", most[1]);

    // Every later stage (canonical simplices, batches, decisions) fails the same way, at
    // budgets doubling until the build fits.
    let obj = dir.path().join("small.obj");
    write_obj(&obj, &grid(60));
    let mut budget = 1000;
    loop {
        let t = Instant::now();
        let (r, _) = build_full_after(&obj, budget);
        assert!(t.elapsed() < Duration::from_secs(10));
        if r.is_ok() {
            break;
        }
        assert_full(&r);
        budget *= 2;
    }
    assert!(budget > 100_000, "the sweep reached the later stages: {budget}");
}
