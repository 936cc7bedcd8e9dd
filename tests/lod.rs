//! Level-of-detail `.bft` files (`encode --lod`) end to end: `sort` and `render` draw the
//! cut of `--error-px`, with far fewer triangles, images faithful to the full model's, the
//! same frames under `mpirun` as in one process, and a damaged hierarchy refused in one line
//! naming the chunk before any frame.

mod common;

use common::{alone, json_lines, mpirun, ok, pixels, refused, refused_last_line, refused_one_line, tessera};
use testkit::mesh_arg as mesh;

fn args(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

/// The share of pixels covered in either image whose every colour channel is within `tol`.
fn within(a: &std::path::Path, b: &std::path::Path, tol: u8) -> f64 {
    let (pa, pb) = (pixels(a), pixels(b));
    assert_eq!((pa.0, pa.1), (pb.0, pb.1));
    let covered: Vec<(&[u8], &[u8])> =
        pa.2.chunks(4).zip(pb.2.chunks(4)).filter(|(x, y)| x[3] == 255 || y[3] == 255).collect();
    let close = covered.iter().filter(|(x, y)| (0..4).all(|k| x[k].abs_diff(y[k]) <= tol)).count();
    close as f64 / covered.len().max(1) as f64
}

#[test]
fn the_cut_draws_fewer_triangles_and_faithful_frames() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let bunny = mesh("stanford/bunny_zipper_c3d.obj.gz");
    let full_triangles = 69451.0;
    ok(&alone(&["encode", &bunny, "-o", &p("lod.bft"), "--lod", "--chunk-triangles", "2048"]));
    ok(&alone(&["encode", &bunny, "-o", &p("full.bft")]));
    let view = ["--size", "640x480", "--frames", "2", "--orbit", "--orbit-degrees", "120"];
    let render = |model: &str, out: &str, extra: &[&str]| {
        let mut args = vec!["render", model, "--out", out];
        args.extend(view);
        args.extend(extra);
        args.into_iter().map(String::from).collect::<Vec<_>>()
    };
    ok(&alone(&args(&render(&p("full.bft"), &p("full.png"), &["--tiles", "1x1"]))));
    let one = render(&p("lod.bft"), &p("one.png"), &["--tiles", "1x1", "--error-px", "1", "--stats", &p("s.jsonl")]);
    ok(&alone(&args(&one)));
    for k in 1..=2 {
        let (full, cut) = (dir.path().join(format!("full-{k:04}.png")), dir.path().join(format!("one-{k:04}.png")));
        let share = within(&full, &cut, 8);
        assert!(share >= 0.99, "frame {k}: {:.2}% of covered pixels within 8/255", share * 100.0);
    }
    let lines = json_lines(p("s.jsonl"));
    for l in lines.iter().filter(|l| l["rank"] == 0) {
        let drawn: u64 = l["tiles"].as_array().unwrap().iter().map(|t| t["triangles"].as_u64().unwrap()).sum();
        assert!((drawn as f64) < 0.6 * full_triangles, "{drawn} triangles drawn");
        assert!(l["chunks"]["not_in_cut"].as_u64().unwrap() > 0);
    }
    // The cluster draws the same cut, with the sort shared or not: the frames equal the
    // single process's.
    for (name, extra) in [("np3", vec![]), ("sorters", vec!["--sorters", "2"])] {
        let mut flags = vec!["--tiles", "4x3", "--error-px", "1"];
        flags.extend(extra);
        ok(&mpirun(3, &[], &args(&render(&p("lod.bft"), &p(&format!("{name}.png")), &flags))));
        for k in 1..=2 {
            let (a, b) = (dir.path().join(format!("one-{k:04}.png")), dir.path().join(format!("{name}-{k:04}.png")));
            assert!(pixels(&a) == pixels(&b), "frame {k}: {name} differs from one process");
        }
    }
    // `sort` takes the same cut; a coarser one holds fewer triangles.
    let visible = |error: &str| {
        let o = tessera(&["sort", &p("lod.bft"), "--size", "640x480", "--error-px", error, "--json"]);
        ok(&o);
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        v["totals"]["visible_triangles"].as_u64().unwrap()
    };
    let (fine, coarse) = (visible("1"), visible("8"));
    assert!(coarse < fine && (fine as f64) < full_triangles, "{coarse} at 8 px, {fine} at 1 px");
}

#[test]
fn a_damaged_hierarchy_is_refused_naming_the_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    ok(&alone(&["encode", &mesh("classic/fandisk.obj"), "-o", &p("lod.bft"), "--lod", "--chunk-triangles", "1024"]));
    let mut b = std::fs::read(p("lod.bft")).unwrap();
    let chunks = u32::from_le_bytes(b[24..28].try_into().unwrap()) as usize;
    let start = 16 + 64 + chunks * 56 + 4;
    let groups = u32::from_le_bytes(b[start + 4..start + 8].try_into().unwrap()) as usize;
    let end = start + 8 + 20 * groups + 8 * chunks;
    // Chunk 0's consumer group out of range, the section's checksum refreshed.
    let consumer = start + 8 + 20 * groups + 4;
    b[consumer..consumer + 4].copy_from_slice(&0xFFFF_FF00u32.to_le_bytes());
    let crc = crc32fast::hash(&b[start..end]);
    b[end..end + 4].copy_from_slice(&crc.to_le_bytes());
    std::fs::write(p("bad.bft"), &b).unwrap();
    let needle = "chunk 0: its consumer group 4294967040 is out of range";
    refused_one_line(&tessera(&["sort", &p("bad.bft"), "--error-px", "1"]), needle);
    let out = p("f.png");
    refused_last_line(&alone(&["render", &p("bad.bft"), "--out", &out]), needle);
    refused(&mpirun(2, &[], &["render", &p("bad.bft"), "--out", &out]), needle);
    assert!(!std::path::Path::new(&out).exists(), "no frame written");
}
