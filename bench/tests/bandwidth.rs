//! The bandwidth experiment's binary, end to end.

use std::process::{Command, Output};

use codec::bft::tile_sort::{Boxes, Sorter};
use codec::bft::{Coding, EncodeOptions};
use codec::view::TileGrid;
use master::camera::CameraSpec;
use master::commands::sort::sort_frame;
use master::model::load_model;
use testkit::{arg as s, mesh_path as mesh, stderr};

fn bandwidth(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bandwidth")).args(args).output().expect("runs bandwidth")
}

#[test]
fn writes_the_figure_8_table_and_plot() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cow = mesh("classic/cow.obj");
    let (csv, png) = (d.join("out/report.csv"), d.join("out/report.png"));
    let o = bandwidth(&[s(&cow), "--tiles", "1x1,4x4", "--out", s(&csv), "--plot", s(&png)]);
    assert!(o.status.success(), "{}", stderr(&o));

    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        header,
        [
            "model",
            "triangles",
            "width",
            "height",
            "cols",
            "rows",
            "tile_width",
            "tile_height",
            "tri_bytes",
            "tiled_tri_bytes",
            "bft_bytes",
            "tiled_bft_bytes",
            "draco_per_tile_bytes",
            "meshopt_per_tile_bytes",
            "bft_sort_ms",
            "tri_sort_ms",
            "draco_retile_ms",
            "tiled_bft_prefix_bytes",
            "bft_prefix_sort_ms",
            "chunks",
            "chunked_tiled_bft_bytes",
            "chunked_sort_ms",
            "chunked_orbit_bytes"
        ]
    );
    let rows: Vec<std::collections::HashMap<&str, &str>> =
        lines.map(|l| header.iter().copied().zip(l.split(',')).collect()).collect();
    assert_eq!(rows.len(), 2, "{text}");
    let n = |row: &std::collections::HashMap<&str, &str>, k: &str| row[k].parse::<f64>().unwrap();
    for (row, tiles) in rows.iter().zip(["1x1", "4x4"]) {
        assert_eq!(row["model"], "cow");
        assert_eq!(format!("{}x{}", row["cols"], row["rows"]), tiles);
        assert!(n(row, "tiled_tri_bytes") >= n(row, "tri_bytes"), "{row:?}");
        for k in [
            "tri_bytes",
            "bft_bytes",
            "tiled_bft_bytes",
            "draco_per_tile_bytes",
            "meshopt_per_tile_bytes",
            "tiled_bft_prefix_bytes",
        ] {
            assert!(n(row, k) > 0.0, "{k}: {row:?}");
        }
        for k in ["bft_sort_ms", "tri_sort_ms", "draco_retile_ms", "bft_prefix_sort_ms"] {
            assert!(n(row, k) >= 0.0, "{k}: {row:?}");
        }
    }
    // On one tile every visible triangle travels once.
    assert_eq!(n(&rows[0], "tiled_tri_bytes"), n(&rows[0], "tri_bytes"));
    // The cow (5,804 triangles) makes 2 chunks of at most 4096; on one tile both are
    // forwarded verbatim, and a worker that kept them is sent nothing along the orbit.
    for row in &rows {
        assert_eq!(n(row, "chunks"), 2.0, "{row:?}");
        assert!(n(row, "chunked_tiled_bft_bytes") > 0.0, "{row:?}");
    }
    assert_eq!(n(&rows[0], "chunked_orbit_bytes"), 0.0);
    assert!(n(&rows[1], "chunked_orbit_bytes") > 0.0, "pieces of straddling chunks travel every frame");

    // The same 14-bit model through the tile sort of `tessera sort`: the same totals.
    let model = load_model(&cow, EncodeOptions { quant_bits: 14, ..Default::default() }).unwrap();
    for row in &rows {
        let grid = TileGrid::new(1920, 1080, n(row, "cols") as u32, n(row, "rows") as u32).unwrap();
        let cam = model.camera(&CameraSpec::default(), &grid).unwrap();
        let (mut sorter, mut boxes) = (Sorter::new(Coding::Range), Boxes::default());
        let t =
            sort_frame(&model, "cow", &cam, &grid, &mut sorter, &mut boxes, &mut Default::default()).unwrap().0.totals;
        let tiles = format!("{}x{}", row["cols"], row["rows"]);
        assert_eq!(n(row, "tiled_tri_bytes"), 36.0 * t.tiled_triangles as f64, "{tiles}");
        assert_eq!(n(row, "tiled_bft_bytes"), t.tiled_bft_bytes as f64, "{tiles}");
        assert_eq!(n(row, "bft_bytes"), model.bytes.len() as f64);
    }

    let image = std::fs::read(&png).unwrap();
    assert!(image.starts_with(b"\x89PNG\r\n\x1a\n"), "not a PNG");

    // A bad request fails at once, naming the problem, and writes nothing.
    let fresh = (d.join("bad.csv"), d.join("bad.png"));
    for (args, message) in [
        (vec![s(&cow), "--tiles", "1x1,0x4"], "0x4"),
        (vec![s(&cow), "--tiles", "4000x2"], "does not fit"),
        (vec!["missing.obj"], "missing.obj"),
    ] {
        let mut all = args;
        all.extend(["--out", s(&fresh.0), "--plot", s(&fresh.1)]);
        let o = bandwidth(&all);
        assert_eq!(o.status.code(), Some(1), "{all:?}");
        assert!(stderr(&o).contains(message), "{all:?}: {}", stderr(&o));
        assert!(!fresh.0.exists() && !fresh.1.exists());
    }
}

#[test]
fn an_output_that_is_an_input_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("m.obj");
    std::fs::copy(mesh("classic/woody.obj"), &obj).unwrap();
    let original = std::fs::read(&obj).unwrap();
    let hard_csv = dir.path().join("m.csv");
    std::fs::hard_link(&obj, &hard_csv).unwrap();
    let plot = dir.path().join("p.png");
    let o = bandwidth(&[s(&obj), "--tiles", "1x1", "--out", s(&hard_csv), "--plot", s(&plot)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("same file"), "{}", stderr(&o));
    assert_eq!(std::fs::read(&obj).unwrap(), original);
    assert!(!plot.exists());
}
