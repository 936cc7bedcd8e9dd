//! Issue 47's hostile inputs to the codec's formats and loaders, each a regression test on
//! files the test makes itself: glTF file access confined to the model's folder, every
//! allocation a file drives checked against the cap on decompressed input before it is
//! made, headers that do not fit `f32` refused as corrupt, chunked files read with
//! positioned reads that fail cleanly when the file is cut while in use, PLY headers with
//! extra blanks read as Draco reads them, and one-line messages in the user's terms.
//!
//! The cap and the URI setting are process-wide: every test here holds [`LOCK`], so that one
//! test's lowered cap never meets another's load.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};
use std::time::Instant;

use codec::bft::chunked::{encode_mesh_chunked, ChunkOptions, ChunkedFile, FileSource};
use codec::bft::{self, EncodeOptions};
use codec::input::{max_decompressed_bytes, set_allow_outside_uris, set_max_decompressed_bytes};
use codec::load::{load_bytes, load_path_counted, load_path_streamed_counted, Format};
use codec::Mesh;
use testkit::patch_header;

static LOCK: Mutex<()> = Mutex::new(());

/// Holds the lock with the default settings, and restores them when dropped.
struct Settings(#[allow(dead_code)] MutexGuard<'static, ()>);

fn settings() -> Settings {
    let guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    set_max_decompressed_bytes(codec::input::DEFAULT_MAX_DECOMPRESSED_BYTES);
    set_allow_outside_uris(false);
    Settings(guard)
}

impl Drop for Settings {
    fn drop(&mut self) {
        set_max_decompressed_bytes(codec::input::DEFAULT_MAX_DECOMPRESSED_BYTES);
        set_allow_outside_uris(false);
    }
}

fn one_line(e: &str) {
    assert!(!e.contains('\n'), "one line: {e}");
    for debug in ["Valid(", "DracoError", "kind:", "Some(", "{ ", "[0.0"] {
        assert!(!e.contains(debug), "no Debug output ({debug}): {e}");
    }
}

/// Three vertices' positions as 36 bytes of `f32`.
fn triangle_bytes() -> Vec<u8> {
    [0f32, 0., 0., 1., 0., 0., 0., 1., 0.].iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// A glTF document with one buffer at `uri` of `len` bytes read as one triangle's positions.
fn gltf_with_buffer(uri: &str, len: usize) -> String {
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
"buffers":[{{"uri":"{uri}","byteLength":{len}}}],
"bufferViews":[{{"buffer":0,"byteLength":36}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}]}}"#
    )
}

fn write(path: &Path, bytes: impl AsRef<[u8]>) -> PathBuf {
    std::fs::write(path, bytes).unwrap();
    path.to_path_buf()
}

fn load_gltf(path: &Path) -> Result<Mesh, String> {
    let bytes = std::fs::read(path).unwrap();
    load_bytes(path, &bytes, Format::Gltf).map_err(|e| e.to_string())
}

/// Buffer URIs resolve only inside the model's folder: `..` out of it, an absolute path and
/// a symlink out of it are refused with the buffer and the URI named, remote URIs are not
/// supported, and `--allow-outside-uris` (the codec setting) widens it on purpose.
#[test]
fn gltf_uris_stay_in_the_model_folder() {
    let _s = settings();
    let root = tempfile::tempdir().unwrap();
    let secret = write(&root.path().join("secret.bin"), triangle_bytes());
    let models = root.path().join("models");
    std::fs::create_dir_all(models.join("sub")).unwrap();
    write(&models.join("inside.bin"), triangle_bytes());
    std::os::unix::fs::symlink(&secret, models.join("link.bin")).unwrap();
    std::os::unix::fs::symlink(models.join("inside.bin"), models.join("sub/ok-link.bin")).unwrap();

    let model = |name: &str, uri: &str| write(&models.join(name), gltf_with_buffer(uri, 36));
    // Inside the folder: plain, through a subfolder and back, through a symlink that stays.
    for (name, uri) in [("a.gltf", "inside.bin"), ("b.gltf", "sub/../inside.bin"), ("c.gltf", "sub/ok-link.bin")] {
        let m = load_gltf(&model(name, uri)).unwrap_or_else(|e| panic!("{uri}: {e}"));
        assert_eq!(m.triangles.len(), 1, "{uri}");
    }
    let abs = secret.to_str().unwrap().to_string();
    let refused = [
        ("up.gltf", "../secret.bin", "leads out of the model's folder"),
        ("up2.gltf", "sub/../../secret.bin", "leads out of the model's folder"),
        ("esc.gltf", "%2E%2E/secret.bin", "leads out of the model's folder"),
        ("abs.gltf", abs.as_str(), "absolute path"),
        ("link.gltf", "link.bin", "symlink leads out of the model's folder"),
        ("http.gltf", "http://example.com/x.bin", "remote URIs are not supported"),
        ("https.gltf", "HTTPS://example.com/x.bin", "remote URIs are not supported"),
        ("file.gltf", "file:///etc/passwd", "remote URIs are not supported"),
    ];
    for (name, uri, why) in refused {
        let e = load_gltf(&model(name, uri)).expect_err(uri);
        assert!(e.contains("buffer 0") && e.contains(&format!("'{uri}'")) && e.contains(why), "{uri}: {e}");
        one_line(&e);
    }
    // The flag widens it for the paths, not for remote URIs.
    set_allow_outside_uris(true);
    for name in ["up.gltf", "abs.gltf", "link.gltf", "esc.gltf"] {
        assert!(load_gltf(&models.join(name)).is_ok(), "{name} with --allow-outside-uris");
    }
    assert!(load_gltf(&models.join("http.gltf")).unwrap_err().contains("remote URIs are not supported"));
}

/// An accessor without a buffer view costs nothing in the file whatever its count: the
/// 492-byte file of the issue (count 100M) is refused by name before its values are
/// allocated, as are an index accessor as large, a sparse count above the accessor's, and a
/// mesh instanced by more nodes than the cap holds (the running total across primitives).
#[test]
fn gltf_counts_are_bounded_before_allocation() {
    let _s = settings();
    let dir = tempfile::tempdir().unwrap();
    let doc = |accessors: &str, nodes: usize, indices: bool| {
        let node_list: Vec<String> = (0..nodes).map(|i| i.to_string()).collect();
        let node_objs: Vec<String> = (0..nodes).map(|_| r#"{"mesh":0}"#.to_string()).collect();
        format!(
            r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[{}]}}],"nodes":[{}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}{}}}]}}],"accessors":[{accessors}]}}"#,
            node_list.join(","),
            node_objs.join(","),
            if indices { r#","indices":1"# } else { "" }
        )
    };
    let position =
        |count: u64| format!(r#"{{"componentType":5126,"count":{count},"type":"VEC3","min":[0,0,0],"max":[0,0,0]}}"#);
    let issue = write(&dir.path().join("huge.gltf"), doc(&position(100_000_000), 1, false));
    assert!(std::fs::metadata(&issue).unwrap().len() < 600, "a file of a few hundred bytes");
    let start = Instant::now();
    let e = load_gltf(&issue).unwrap_err();
    assert!(start.elapsed().as_secs_f64() < 5.0, "refused at once, not after the allocation");
    assert!(e.contains("the primitives read so far: 100000000 vertices") && e.contains("--max-decompressed"), "{e}");
    one_line(&e);

    let index = |count: u64| format!(r#"{{"componentType":5125,"count":{count},"type":"SCALAR"}}"#);
    let e = load_gltf(&write(
        &dir.path().join("idx.gltf"),
        doc(&format!("{},{}", position(3), index(300_000_000)), 1, true),
    ))
    .unwrap_err();
    assert!(e.contains("accessor 1 (count 300000000)") && e.contains("--max-decompressed"), "{e}");

    // Sparse: more substitutions than elements.
    let sparse = r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],
"buffers":[{"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA","byteLength":48}],
"bufferViews":[{"buffer":0,"byteLength":48}],
"accessors":[{"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[0,0,0],
"sparse":{"count":4,"indices":{"bufferView":0,"componentType":5121},"values":{"bufferView":0}}}]}"#;
    let e = load_gltf(&write(&dir.path().join("sparse.gltf"), sparse)).unwrap_err();
    assert!(e.contains("sparse count 4 exceeds its count 3"), "{e}");

    // Instancing: one mesh of 1000 vertices (28 bytes each in the model) under many nodes.
    set_max_decompressed_bytes(100_000);
    let one = write(&dir.path().join("one.gltf"), doc(&position(999), 1, false));
    assert!(load_gltf(&one).is_ok(), "one instance fits");
    let many = write(&dir.path().join("many.gltf"), doc(&position(999), 4, false));
    let e = load_gltf(&many).unwrap_err();
    assert!(e.contains("the primitives read so far") && e.contains("3996 vertices"), "{e}");
    assert!(e.contains("--max-decompressed"), "{e}");
    one_line(&e);
}

/// Errors name attributes as glTF does (POSITION, NORMAL, COLOR_0) and say what a Draco
/// stream's problem is in words, never as Rust's Debug output.
#[test]
fn gltf_messages_are_in_the_users_terms() {
    let _s = settings();
    let dir = tempfile::tempdir().unwrap();
    let bad_index = r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
"meshes":[{"primitives":[{"attributes":{"POSITION":5}}]}],"accessors":[]}"#;
    let e = load_gltf(&write(&dir.path().join("i.gltf"), bad_index)).unwrap_err();
    assert!(e.contains("attribute POSITION names accessor 5"), "{e}");
    one_line(&e);

    let zeros =
        |count: u32| format!(r#"{{"componentType":5126,"count":{count},"type":"VEC3","min":[0,0,0],"max":[0,0,0]}}"#);
    let normals = format!(
        r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0,"NORMAL":1,"COLOR_0":2}}}}]}}],"accessors":[{},{},{}]}}"#,
        zeros(3),
        zeros(2),
        zeros(3)
    );
    let e = load_gltf(&write(&dir.path().join("n.gltf"), normals)).unwrap_err();
    assert!(e.contains("NORMAL accessor 1 has 2 values for 3 vertices"), "{e}");
    one_line(&e);

    // A Draco extension over bytes that are no Draco stream.
    let draco = r#"{"asset":{"version":"2.0"},"extensionsUsed":["KHR_draco_mesh_compression"],
"extensionsRequired":["KHR_draco_mesh_compression"],"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0},
"extensions":{"KHR_draco_mesh_compression":{"bufferView":0,"attributes":{"POSITION":0}}}}]}],
"buffers":[{"uri":"data:application/octet-stream;base64,RFJBQ08CAgEBAAAAAAAAAA==","byteLength":16}],
"bufferViews":[{"buffer":0,"byteLength":16}],
"accessors":[{"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[0,0,0]}]}"#;
    let e = load_gltf(&write(&dir.path().join("d.gltf"), draco)).unwrap_err();
    assert!(e.contains("KHR_draco_mesh_compression") && e.contains("Draco stream"), "{e}");
    one_line(&e);
}

/// A PLY header with spaces or tabs before a keyword and several between words (which
/// Draco reads) loads, in core and streamed, to the mesh of the same file without them.
#[test]
fn ply_headers_with_extra_blanks_load_in_core_and_streamed() {
    let _s = settings();
    let dir = tempfile::tempdir().unwrap();
    let body = "0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 2 1 3\n";
    let plain = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
                 element face 2\nproperty list uchar int vertex_indices\nend_header\n";
    let spaced =
        "ply\n format ascii 1.0\n element vertex 4\nproperty  float x\n\tproperty float\ty\nproperty float z \t\n\
                  \t element  face\t2\n  property list uchar  int vertex_indices\n end_header\n";
    let a = write(&dir.path().join("plain.ply"), format!("{plain}{body}"));
    let b = write(&dir.path().join("spaced.ply"), format!("{spaced}{body}"));
    let expected = load_path_counted(&a).unwrap().mesh;
    assert_eq!(expected.triangles.len(), 2);
    assert_eq!(load_path_counted(&b).unwrap().mesh, expected, "in core");
    assert_eq!(load_path_streamed_counted(&b).unwrap().mesh, expected, "streamed");
    // Binary too: the header is the same parser's, the payload follows it.
    let mut bin = spaced.replace("ascii", "binary_little_endian").into_bytes();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.], [1., 1., 0.]] {
        bin.extend(p.iter().flat_map(|v| v.to_le_bytes()));
    }
    for t in [[0i32, 1, 2], [2, 1, 3]] {
        bin.push(3);
        bin.extend(t.iter().flat_map(|v| v.to_le_bytes()));
    }
    let c = write(&dir.path().join("binary.ply"), bin);
    assert_eq!(load_path_streamed_counted(&c).unwrap().mesh, expected, "binary, streamed");
    assert_eq!(load_path_counted(&c).unwrap().mesh, expected, "binary, in core");
}

/// A small mesh with colours and normals: `n` by `n` quads.
fn painted_grid(n: usize) -> Mesh {
    let mut mesh = testkit::holed_grids(n, n, 1, &[false], 7);
    mesh.colors = (0..mesh.positions.len()).map(|i| [i as u8, 7, 9, 255]).collect();
    mesh.normals = vec![[0.0, 0.0, 1.0]; mesh.positions.len()];
    mesh
}

/// Every count of a `.bft` header is checked against the cap before the decoder allocates
/// for it, single-stream and chunked, and refused by its field's name: slots (with their
/// colours, normals and input order), triangles, commands, and a chunked file's input
/// vertices (the issue's 4,294,967,295 and 300M, which `to_mesh` would have allocated, with
/// colours and normals beside the positions).
#[test]
fn bft_counts_beyond_the_cap_are_refused_by_field() {
    let _s = settings();
    let mesh = painted_grid(20);
    let keep = EncodeOptions { keep_order: true, ..Default::default() };
    let single = bft::encode(&mesh, keep).unwrap().bytes;
    for (offset, field) in [(4, "slots"), (8, "triangles"), (16, "commands")] {
        let mut b = single.clone();
        patch_header(&mut b, offset, u32::MAX.to_le_bytes());
        let e = bft::decode(&b).unwrap_err().to_string();
        assert!(e.contains(&format!("header field {field}: 4294967295")) && e.contains("--max-decompressed"), "{e}");
        one_line(&e);
        assert_eq!(e.matches("cap").count(), 1, "the cap said once: {e}");
    }
    // The single stream's input vertices with colours and normals: 28 bytes each.
    let n = mesh.positions.len() as u64;
    set_max_decompressed_bytes(n * 20);
    let e = bft::decode(&single).unwrap_err().to_string();
    assert!(e.contains("header field slots") || e.contains("header field input_vertices"), "{e}");
    set_max_decompressed_bytes(codec::input::DEFAULT_MAX_DECOMPRESSED_BYTES);

    let chunk = ChunkOptions { chunk_triangles: 256, stream: keep, ..Default::default() };
    let (chunked, _) = encode_mesh_chunked(&mesh, &chunk).unwrap();
    assert!(ChunkedFile::open(chunked.clone()).unwrap().entries.len() > 1);
    for count in [u32::MAX, 300_000_000] {
        let mut b = chunked.clone();
        patch_header(&mut b, 0, count.to_le_bytes());
        let start = Instant::now();
        let e = bft::decode(&b).unwrap_err().to_string();
        assert!(
            e.contains(&format!("header field input_vertices: {count} input vertices"))
                && e.contains("--max-decompressed"),
            "{e}"
        );
        one_line(&e);
        assert!(start.elapsed().as_secs_f64() < 5.0, "refused before decoding");
        // Reading it chunk by chunk allocates nothing by the count (a sort, a render), and
        // checking its chunks finds that they place fewer input vertices.
        let file = ChunkedFile::open(b.clone()).unwrap();
        let e = file.components().unwrap_err().to_string();
        assert!(e.contains(&format!("header field input_vertices: {count} input vertices, where")), "{e}");
        one_line(&e);
    }
    // Input vertices that fit 12 bytes each, but not with their colours and normals: the
    // whole model's arrays are refused after the chunks' own checks, before `to_mesh`.
    let chunk_plain = ChunkOptions { chunk_triangles: 256, stream: keep, ..Default::default() };
    let (b, _) = encode_mesh_chunked(&mesh, &chunk_plain).unwrap();
    let cap = n * 12 + 8;
    set_max_decompressed_bytes(cap);
    let e = bft::decode(&b).unwrap_err().to_string();
    assert!(e.contains("input_vertices") || e.contains("slots"), "{e}");
    assert!(e.contains("--max-decompressed"), "{e}");
    set_max_decompressed_bytes(codec::input::DEFAULT_MAX_DECOMPRESSED_BYTES);
    assert_eq!(bft::decode(&b).unwrap().to_mesh().positions.len(), mesh.positions.len());
}

/// Header values that do not fit `f32`, in `.bft` (single-stream and chunked) and `.dpm`: a
/// quantization grid whose far corner is infinite, a box that is not finite, are corrupt
/// with the field named.
#[test]
fn headers_that_do_not_fit_f32_are_corrupt() {
    let _s = settings();
    let mesh = painted_grid(20);
    let single = bft::encode(&mesh, EncodeOptions::default()).unwrap().bytes;
    let (chunked, _) =
        encode_mesh_chunked(&mesh, &ChunkOptions { chunk_triangles: 256, ..Default::default() }).unwrap();
    // (file, offset of bbox_min x, offset of step) in each header.
    for (name, bytes, min, step) in [("single", &single, 44, 56), ("chunked", &chunked, 36, 48)] {
        for (offset, value, field) in [
            (step, 1e38f32, "header field step"),
            (step, f32::MAX, "header field step"),
            (min, f32::INFINITY, "header field bbox"),
            (min, f32::NAN, "header field bbox"),
        ] {
            let mut b = bytes.clone();
            patch_header(&mut b, offset, value.to_le_bytes());
            let e = bft::decode(&b).unwrap_err().to_string();
            assert!(e.contains("corrupt .bft data") && e.contains(field), "{name} {field} = {value}: {e}");
            assert!(value.is_nan() || e.contains("does not fit f32") || e.contains("not ordered"), "{e}");
            one_line(&e);
        }
    }
    // .dpm: the step (header offset 30) and bbox_min (18).
    let pm = codec::pm::build(&testkit::holed_grids(12, 12, 1, &[false], 3)).unwrap();
    let dpm = codec::pm::format::encode(&pm, Default::default()).unwrap().bytes;
    for (offset, value, field) in [(30, 1e38f32, "header field step"), (18, f32::INFINITY, "header field bbox_min")] {
        let mut b = dpm.clone();
        patch_header(&mut b, offset, value.to_le_bytes());
        let e = codec::pm::format::decode(&b).unwrap_err().to_string();
        assert!(e.contains("corrupt .dpm data") && e.contains(field) && e.contains("does not fit f32"), "{e}");
        one_line(&e);
    }
}

/// A `.dpm` file whose whole decode would exceed the cap is refused by its header's field
/// before the decoder allocates the vertex arrays.
#[test]
fn dpm_counts_beyond_the_cap_are_refused_by_field() {
    let _s = settings();
    let pm = codec::pm::build(&testkit::holed_grids(12, 12, 1, &[false], 3)).unwrap();
    let dpm = codec::pm::format::encode(&pm, Default::default()).unwrap().bytes;
    assert!(codec::pm::format::decode(&dpm).is_ok());
    set_max_decompressed_bytes(64);
    let e = codec::pm::format::decode(&dpm).unwrap_err().to_string();
    assert!(e.contains("header field vertices") && e.contains("--max-decompressed"), "{e}");
    one_line(&e);
}

/// A chunked file read from disk (positioned reads, no mapping): cut while in use, every
/// chunk read after the cut is an error naming the file, the chunk, the bytes expected and
/// where, and no sort panics or dies; a file replaced by a rename is still read whole
/// through the descriptor; one rewritten in place is caught by the chunk's checksums.
#[test]
fn chunked_files_cut_while_in_use_fail_cleanly() {
    let _s = settings();
    let dir = tempfile::tempdir().unwrap();
    let mesh = testkit::holed_grids(40, 40, 1, &[false], 5);
    let (bytes, _) = encode_mesh_chunked(&mesh, &ChunkOptions { chunk_triangles: 256, ..Default::default() }).unwrap();
    let path = write(&dir.path().join("m.bft"), &bytes);
    let file = ChunkedFile::open(FileSource::open(&path).unwrap()).unwrap();
    assert!(file.entries.len() > 4);
    assert_eq!(file.file_len(), bytes.len() as u64);
    assert_eq!(&file.chunk_bft(3).unwrap()[..], &bytes[file.entries[3].bft_range()], "reads as the bytes do");
    let whole: Vec<_> = (0..file.entries.len()).map(|i| file.decode_chunk(i).unwrap()).collect();

    // Cut inside chunk 2.
    let e2 = file.entries[2];
    let cut = e2.offset + 10;
    std::fs::OpenOptions::new().write(true).open(&path).unwrap().set_len(cut).unwrap();
    for i in [2, 3, file.entries.len() - 1] {
        let e = file.entries[i];
        let err = file.chunk_bft(i).unwrap_err().to_string();
        let expected = format!(
            "{}: chunk {i}: the file was truncated or replaced while in use (expected {} bytes at offset {})",
            path.display(),
            e.bft_len,
            e.offset
        );
        assert_eq!(err, expected);
        assert!(file.decode_chunk(i).unwrap_err().to_string().contains("truncated or replaced while in use"));
        assert!(file.border(i).unwrap_err().to_string().contains(&format!("chunk {i}: the file was truncated")));
    }
    assert!(file.decode_chunk(0).is_ok(), "chunks before the cut still read");
    let model = codec::bft::chunked::sort::ChunkedModel::new(file, 1 << 20);
    let grid = codec::view::TileGrid::new(64, 48, 4, 4).unwrap();
    let h = model.file.header;
    let cam = codec::view::Camera::framing(h.bbox_min, h.bbox_max, grid.aspect());
    let e = model.sort(cam.view_proj(grid.aspect()), &grid, bft::Coding::Prefix).unwrap_err().to_string();
    assert!(e.contains("truncated or replaced while in use"), "{e}");
    one_line(&e);

    // Replaced by a rename: the open descriptor still reads the old file, whole.
    let path = write(&dir.path().join("r.bft"), &bytes);
    let file = ChunkedFile::open(FileSource::open(&path).unwrap()).unwrap();
    let other = write(&dir.path().join("other.bft"), b"something else entirely");
    std::fs::rename(&other, &path).unwrap();
    for (i, d) in whole.iter().enumerate() {
        assert_eq!(&file.decode_chunk(i).unwrap(), d, "chunk {i} after a rename");
    }

    // Rewritten in place, same length: the chunk's checksums catch it.
    let path = write(&dir.path().join("w.bft"), &bytes);
    let file = ChunkedFile::open(FileSource::open(&path).unwrap()).unwrap();
    let mut changed = bytes.clone();
    let e1 = file.entries[1];
    changed[e1.offset as usize + e1.bft_len as usize / 2] ^= 0x55;
    changed[(e1.offset + e1.bft_len as u64) as usize + 1] ^= 0x55;
    std::fs::write(&path, &changed).unwrap();
    let e = file.decode_chunk(1).unwrap_err().to_string();
    assert!(e.contains("chunk 1") && e.contains("checksum mismatch"), "{e}");
    assert_eq!(e.matches("corrupt").count(), 1, "said once: {e}");
    assert!(file.border(1).unwrap_err().to_string().contains("checksum mismatch in the border table"));
}

/// The cap's default is what `max_decompressed_bytes` reports when nothing set it (a guard
/// on the helpers above).
#[test]
fn the_settings_restore_the_defaults() {
    let s = settings();
    set_max_decompressed_bytes(5);
    drop(s);
    let _s = settings();
    assert_eq!(max_decompressed_bytes(), codec::input::DEFAULT_MAX_DECOMPRESSED_BYTES);
    assert!(!codec::input::allow_outside_uris());
}
