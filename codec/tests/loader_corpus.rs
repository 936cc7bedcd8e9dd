//! The loaders on a corpus of small hand-made files, one per case real exporters produce
//! (`tests/corpus/`): each loads to the expected mesh, or fails with a one-line error that
//! names the file and says what is wrong; the in-core and streaming readers agree.

use std::path::{Path, PathBuf};

use codec::load::stream::{for_each_triangle, read_vertices};
use codec::load::{load_path_counted, Loaded};
use codec::Mesh;

fn corpus(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus").join(name)
}

/// Two triangles on the unit square, as every readable file of the corpus holds them.
fn square() -> Mesh {
    Mesh {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        ..Default::default()
    }
}

fn load(name: &str) -> Result<Loaded, String> {
    let path = corpus(name);
    let loaded = load_path_counted(&path).map_err(|e| e.to_string());
    if let Err(e) = &loaded {
        assert!(!e.contains('\n'), "{name}: a multi-line error: {e}");
        assert!(e.starts_with(&path.display().to_string()), "{name}: the error does not name the file: {e}");
    }
    // PLY and OBJ stream too, to the same mesh or an error.
    if codec::load::stream::can_stream(&path) {
        let streamed = read_vertices(&path, &mut |_| {}).and_then(|mut mesh| {
            let mut triangles = Vec::new();
            let counts = for_each_triangle(
                &path,
                &mesh.positions,
                &mut |t| {
                    triangles.push(t);
                    Ok(())
                },
                &mut |_| {},
            )?;
            mesh.triangles = triangles;
            Ok((mesh, counts.ignored))
        });
        match (&loaded, streamed) {
            (Ok(l), Ok((m, ignored))) => assert_eq!((&l.mesh, l.ignored), (&m, ignored), "{name}: the readers differ"),
            (Err(_), Err(_)) => {}
            (l, s) => panic!("{name}: in core {l:?}, streamed {s:?}"),
        }
    }
    loaded
}

#[test]
fn every_readable_case_gives_the_square() {
    for name in [
        "ply_lf.ply",
        "ply_crlf.ply",
        "ply_cr.ply",
        "ply_tabs_spaces.ply",
        "ply_comments.ply",
        "ply_big_endian_all_types.ply",
        "ply_unknown_colours_normals.ply",
        "ply_named_obj.obj",
        "obj_relative.obj",
        "obj_vt_vn.obj",
        "obj_inline_comments.obj",
        "obj_tex_normal_out_of_range.obj",
        "obj_colours.obj",
        "stl_bare_solid.stl",
        "stl_upper_case_tabs.stl",
        "stl_binary_header_solid.stl",
    ] {
        let l = load(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        let shape = Mesh::new(l.mesh.positions.clone(), l.mesh.triangles.clone());
        assert_eq!(shape, square(), "{name}");
        assert_eq!(l.ignored, 0, "{name}");
        match name {
            "ply_unknown_colours_normals.ply" => {
                assert_eq!(l.mesh.colors, vec![[255, 128, 0, 255]; 4], "{name}");
                assert_eq!(l.mesh.normals, vec![[0.0, 0.0, 1.0]; 4], "{name}");
            }
            "obj_colours.obj" => {
                let want = [[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255], [255, 255, 255, 255]];
                assert_eq!(l.mesh.colors, want, "{name}");
                assert!(l.mesh.normals.is_empty());
            }
            _ => assert!(l.mesh.colors.is_empty() && l.mesh.normals.is_empty(), "{name}"),
        }
    }
}

#[test]
fn points_and_lines_are_skipped_and_counted() {
    let l = load("obj_points_lines.obj").unwrap();
    assert_eq!(l.mesh.triangles, square().triangles);
    assert_eq!(l.ignored, 4, "l, p, f of two corners, f of one");
}

#[test]
fn bad_files_get_one_line_naming_the_problem() {
    for (name, expected) in [
        ("obj_lines_only.obj", "no triangles, only points or lines (2 elements"),
        ("obj_empty.obj", "no triangles (an empty file or a point cloud is not a mesh)"),
        ("ply_point_cloud.ply", "no triangles"),
        ("obj_nan.obj", "line 2: a 'v' line with a non-finite coordinate"),
        ("obj_index_out_of_range.obj", "line 5: a face uses vertex 9"),
        ("stl_binary_truncated.stl", "binary with 2 triangles should be 184 bytes, the file has 120"),
        ("stl_nan.stl", "facet 0, corner 1: a non-finite coordinate"),
    ] {
        let e = load(name).map(|l| l.mesh).expect_err(name);
        assert!(e.contains(expected), "{name}: {e}");
    }
}

/// Loading speed on the dragon's PLY (decompressed in memory first, so gzip is not timed),
/// ours against ply-rs in the same run, best of three each:
/// `cargo test --release -p tessera-codec --test loader_corpus -- --ignored --nocapture`
#[test]
#[ignore = "times the 871k-triangle dragon; run in release"]
fn loading_speed_against_ply_rs() {
    use std::io::Read;
    use std::time::Instant;

    use ply_rs_bw::parser::Parser;
    use ply_rs_bw::ply::DefaultElement;

    let path = testkit::mesh_path("stanford/dragon_vrip.ply.gz");
    let mut bytes = Vec::new();
    flate2::read::MultiGzDecoder::new(std::fs::File::open(&path).unwrap()).read_to_end(&mut bytes).unwrap();
    let best = |f: &mut dyn FnMut() -> usize| {
        (0..3)
            .map(|_| {
                let t = Instant::now();
                let n = f();
                (t.elapsed().as_secs_f64(), n)
            })
            .fold((f64::MAX, 0), |a, b| if b.0 < a.0 { b } else { a })
    };
    let (ours, n) =
        best(&mut || codec::load::load_bytes(&path, &bytes, codec::load::Format::Ply).unwrap().triangles.len());
    let (peer, faces) = best(&mut || {
        let ply = Parser::<DefaultElement>::new().read_ply(&mut std::io::Cursor::new(&bytes)).unwrap();
        ply.payload["face"].len()
    });
    println!(
        "dragon PLY ({} MB): ours {ours:.3} s ({n} triangles), ply-rs {peer:.3} s ({faces} faces, not triangulated): \
         ply-rs takes {:.2}x ours",
        bytes.len() >> 20,
        peer / ours
    );
    assert_eq!(n, faces, "the dragon's faces are triangles");
}
