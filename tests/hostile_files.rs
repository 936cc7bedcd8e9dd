//! Issue 47's hostile files, through the `tessera` binary: glTF buffers outside the model's
//! folder, forged counts in chunked `.bft` headers, headers that do not fit `f32`, a chunked
//! model cut while `sort` and `render` read it, and PLY headers with extra blanks. Every file
//! is one the test makes itself.

mod common;

use std::path::{Path, PathBuf};

use common::{cmd, ok, output, refused_last_line, tessera};
use testkit::{arg as s, mesh_arg as mesh, patch_header, stderr};

fn write(path: &Path, bytes: impl AsRef<[u8]>) -> PathBuf {
    std::fs::write(path, bytes).unwrap();
    path.to_path_buf()
}

/// The issue's exploit: a glTF whose buffer is `../secret.bin` (or an absolute path) read
/// through a byte accessor would hand the file back through `encode --keep-order` and
/// `decode`. Refused by buffer and URI; `--allow-outside-uris` reads it on purpose.
#[test]
fn gltf_buffers_outside_the_model_folder_are_refused() {
    let root = tempfile::tempdir().unwrap();
    let secret = root.path().join("secret.bin");
    let positions: Vec<u8> = [0f32, 0., 0., 1., 0., 0., 0., 1., 0.].iter().flat_map(|v| v.to_le_bytes()).collect();
    write(&secret, &positions);
    let models = root.path().join("models");
    std::fs::create_dir(&models).unwrap();
    let doc = |uri: &str| {
        format!(
            r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
"buffers":[{{"uri":"{uri}","byteLength":36}}],"bufferViews":[{{"buffer":0,"byteLength":36}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}]}}"#
        )
    };
    let out = models.join("out.bft");
    for (uri, why) in [
        ("../secret.bin", "leads out of the model's folder"),
        (s(&secret), "absolute path"),
        ("https://example.com/secret.bin", "remote URIs are not supported"),
    ] {
        let model = write(&models.join("m.gltf"), doc(uri));
        let o = tessera(&["encode", s(&model), "-o", s(&out)]);
        refused_last_line(&o, why);
        assert!(stderr(&o).contains(&format!("buffer 0: URI '{uri}'")), "{}", stderr(&o));
        assert!(!out.exists());
    }
    let model = write(&models.join("m.gltf"), doc("../secret.bin"));
    ok(&tessera(&["encode", s(&model), "-o", s(&out), "--allow-outside-uris"]));
}

/// A chunked `--keep-order` file whose header claims 4,294,967,295 or 300M input vertices:
/// `stats` and `decode` refuse it by its field before allocating (it aborted on a 51 GB
/// allocation, and wrote a 4.5 GB PLY from a 65 KB file), and write nothing.
#[test]
fn forged_chunked_counts_are_refused_by_stats_and_decode() {
    let dir = tempfile::tempdir().unwrap();
    let bft = dir.path().join("m.bft");
    ok(&tessera(&["encode", &mesh("classic/cow.obj"), "-o", s(&bft), "--keep-order", "--chunk-triangles", "256"]));
    let bytes = std::fs::read(&bft).unwrap();
    assert!(codec::bft::chunked::is_chunked(&bytes));
    let ply = dir.path().join("out.ply");
    for count in [u32::MAX, 300_000_000] {
        let mut b = bytes.clone();
        patch_header(&mut b, 0, count.to_le_bytes());
        let bad = write(&dir.path().join("bad.bft"), &b);
        let needle = format!("header field input_vertices: {count} input vertices");
        refused_last_line(&tessera(&["stats", s(&bad)]), &needle);
        let o = tessera(&["decode", s(&bad), "-o", s(&ply)]);
        refused_last_line(&o, &needle);
        assert!(stderr(&o).contains("--max-decompressed") && stderr(&o).contains("bad.bft"), "{}", stderr(&o));
        assert!(!ply.exists(), "nothing written");
    }
    // The file as written reads.
    ok(&tessera(&["stats", s(&bft)]));
}

/// A chunked model larger than `--max-decompressed` decoded whole still sorts and reports its
/// stats, chunk by chunk (the 223M-triangle model's 112M input vertices are 1.3 GiB whole,
/// above the default 1 GiB, and `sort`, `render` and `stats` refused it); only `decode`,
/// which builds the whole model, is refused, by the field, writing nothing.
#[test]
fn a_chunked_model_above_the_cap_whole_is_read_chunk_by_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let (bft, single) = (dir.path().join("cow.bft"), dir.path().join("single.bft"));
    ok(&tessera(&["encode", &mesh("classic/cow.obj"), "-o", s(&bft), "--chunk-triangles", "256"]));
    ok(&tessera(&["encode", &mesh("classic/cow.obj"), "-o", s(&single)]));
    let json = |o: &std::process::Output| -> serde_json::Value {
        ok(o);
        serde_json::from_slice(&o.stdout).unwrap()
    };
    // The cow's 2,903 input vertices take 34 KiB whole, its 3,702 slots 22 KiB in `stats`,
    // a chunk's slots (under 200) 6 KiB.
    let cap = ["--max-decompressed", "30K"];
    let stats = json(&tessera(&[&cap[..], &["stats", s(&bft), "--json"]].concat()));
    let whole = json(&tessera(&["stats", s(&single), "--json"]));
    assert!(stats["chunks"].as_u64().unwrap() > 1, "{stats}");
    assert_eq!(stats["components"], whole["components"], "the model's components, not the chunks' sum");
    let sorted = json(&tessera(&[&cap[..], &["sort", s(&bft), "--json"]].concat()));
    assert_eq!(sorted["totals"]["triangles"], stats["triangles"]);
    let ply = dir.path().join("out.ply");
    let o = tessera(&[&cap[..], &["decode", s(&bft), "-o", s(&ply)]].concat());
    refused_last_line(&o, "header field input_vertices: 2903 input vertices");
    assert!(!ply.exists(), "nothing written");
}

/// A `.bft` header whose quantization grid does not fit `f32` (step 1e38 at 16 bits) is a
/// corrupt file named with the field, for `stats` and `decode`, single-stream and chunked.
#[test]
fn headers_that_do_not_fit_f32_are_corrupt() {
    let dir = tempfile::tempdir().unwrap();
    for (name, chunk, step) in [("single.bft", "0", 56), ("chunked.bft", "256", 48)] {
        let bft = dir.path().join(name);
        ok(&tessera(&["encode", &mesh("classic/cow.obj"), "-o", s(&bft), "--chunk-triangles", chunk]));
        let mut b = std::fs::read(&bft).unwrap();
        patch_header(&mut b, step, 1e38f32.to_le_bytes());
        write(&bft, &b);
        refused_last_line(&tessera(&["stats", s(&bft)]), "header field step");
        let o = tessera(&["decode", s(&bft), "-o", s(&dir.path().join("o.ply"))]);
        refused_last_line(&o, "does not fit f32");
        assert!(stderr(&o).contains(name), "names the file: {}", stderr(&o));
    }
}

/// A chunked model cut to its header and directory after `sort` and `render` opened it
/// (`TESSERA_FAULT=truncate-after-open`): a one-line error naming the file and the chunk,
/// never a SIGBUS (the file was memory-mapped).
#[test]
fn a_chunked_model_cut_while_in_use_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("source.bft");
    ok(&tessera(&["encode", &mesh("classic/cow.obj"), "-o", s(&source), "--chunk-triangles", "256"]));
    let runs: [&[&str]; 3] = [
        &["sort", "--size", "320x240", "--tiles", "1x1"],
        &["sort", "--size", "320x240", "--tiles", "4x4"],
        &["render", "--size", "64x48", "--tiles", "2x2"],
    ];
    for args in runs {
        let bft = dir.path().join("m.bft");
        std::fs::copy(&source, &bft).unwrap();
        let png = dir.path().join("f.png");
        let mut c = cmd();
        c.env("TESSERA_FAULT", "truncate-after-open").args(&args[..1]).arg(&bft).args(&args[1..]);
        if args[0] == "render" {
            c.args(["--out", s(&png)]);
        }
        let o = output(&mut c);
        refused_last_line(&o, "the file was truncated or replaced while in use (expected ");
        let err = stderr(&o);
        assert!(err.contains(&format!("{}: chunk ", bft.display())), "{args:?}: {err}");
        assert!(!png.exists(), "no image");
        assert!(std::fs::metadata(&bft).unwrap().len() < std::fs::metadata(&source).unwrap().len(), "cut");
    }
}

/// A PLY header with a space before `element` (which Draco reads) and tabs between words
/// encodes as the same file without them does.
#[test]
fn ply_headers_with_extra_blanks_load() {
    let dir = tempfile::tempdir().unwrap();
    let body = "0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 2 1 3\n";
    let plain = format!(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
         element face 2\nproperty list uchar int vertex_indices\nend_header\n{body}"
    );
    let spaced = format!(
        "ply\nformat ascii 1.0\n element vertex 4\nproperty\tfloat  x\nproperty float y\nproperty float z\n\
         \telement face 2\n  property list uchar int vertex_indices\nend_header\n{body}"
    );
    let mut outs = Vec::new();
    for (name, text) in [("plain.ply", plain), ("spaced.ply", spaced)] {
        let ply = write(&dir.path().join(name), text);
        let bft = dir.path().join(format!("{name}.bft"));
        ok(&tessera(&["encode", s(&ply), "-o", s(&bft)]));
        outs.push(std::fs::read(&bft).unwrap());
    }
    assert_eq!(outs[0], outs[1]);
}
