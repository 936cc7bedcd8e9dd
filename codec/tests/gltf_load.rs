//! glTF 2.0 in: the hand-made file (`tests/gltf/make_handmade.py`: node hierarchy and
//! transforms, strips, fans, sparse accessors, non-indexed primitives, a mirror, a node in no
//! scene) against its triangles worked out by hand, and files written by real peer tools
//! (`scripts/dev/gltf-fixtures.sh`: obj2gltf, glTF Transform's Draco and meshopt) against the
//! same mesh loaded from OBJ.

use std::path::{Path, PathBuf};

use codec::load::{load_bytes, load_path, load_path_counted, Format};
use codec::Mesh;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/gltf").join(name)
}

/// The triangles of `m` as corner positions.
fn soup(m: &Mesh) -> Vec<[[f32; 3]; 3]> {
    m.triangles.iter().map(|t| t.map(|i| m.positions[i as usize])).collect()
}

fn close(a: [f32; 3], b: [f32; 3], tol: f32) -> bool {
    (0..3).all(|k| (a[k] - b[k]).abs() <= tol)
}

#[test]
fn the_hand_made_file_gives_its_triangles() {
    let w = |x: f32, y: f32| [10.0 + 2.0 * x, 2.0 * y, 0.0];
    let (w0, w1, w2, w3) = (w(0.0, 0.0), w(1.0, 0.0), w(1.0, 1.0), w(0.0, 1.0));
    let expected = [
        // Node 1 (translation 10 0 0, scale 2): triangles, strip 0 1 3 2, fan 0 1 2 3.
        [w0, w1, w2],
        [w0, w2, w3],
        [w0, w1, w3],
        [w1, w2, w3],
        [w1, w2, w0],
        [w2, w3, w0],
        // Node 2 (90 degrees about z): non-indexed, then the sparse accessor (vertex 2 at 2 2 0).
        [[0.0, 0.0, 1.0], [0.0, 1.0, 1.0], [-1.0, 0.0, 1.0]],
        [[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-2.0, 2.0, 0.0]],
        // Node 4 (mirror in x): the winding flips.
        [[0.0, 0.0, 0.0], [-1.0, 1.0, 0.0], [-1.0, 0.0, 0.0]],
    ];
    for name in ["handmade.gltf", "handmade.glb"] {
        let l = load_path_counted(&fixture(name)).unwrap_or_else(|e| panic!("{e}"));
        let got = soup(&l.mesh);
        assert_eq!(got.len(), expected.len(), "{name}: {got:?}");
        for (g, e) in got.iter().zip(&expected) {
            assert!((0..3).all(|k| close(g[k], e[k], 1e-5)), "{name}: {g:?} for {e:?}");
        }
        assert_eq!(l.ignored, 1, "{name}: the LINES primitive");
        // COLOR_0 of mesh 0 (red, green, blue, white at half alpha) on its three primitives'
        // corners; white where a primitive has none. Normals: mesh 1 has none, so none.
        let c = &l.mesh.colors;
        assert_eq!(c.len(), l.mesh.positions.len(), "{name}");
        assert_eq!(c[..4], [[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255], [255, 255, 255, 128]], "{name}");
        assert_eq!(c[4..12], c[..8], "{name}: the strip's and fan's corners");
        assert!(c[12..].iter().all(|&v| v == [255; 4]), "{name}");
        assert!(l.mesh.normals.is_empty(), "{name}");
    }
}

/// NORMAL of every primitive reaches the mesh in world space (the inverse transpose of a
/// non-uniform scale), and a COLOR_0 of floats in VEC3 is 8-bit RGB with alpha 255.
#[test]
fn normals_and_float_colours_are_read_in_world_space() {
    let dir = tempfile::tempdir().unwrap();
    let mut bin = Vec::new();
    for v in [[0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        bin.extend(v.iter().flat_map(|c| c.to_le_bytes()));
    }
    let n = [0.6f32, 0.0, 0.8];
    for _ in 0..3 {
        bin.extend(n.iter().flat_map(|c| c.to_le_bytes()));
    }
    for v in [[1.0f32, 0.5, 0.0], [0.0, 1.0, 0.25], [0.2, 0.2, 0.2]] {
        bin.extend(v.iter().flat_map(|c| c.to_le_bytes()));
    }
    std::fs::write(dir.path().join("t.bin"), &bin).unwrap();
    let json = r#"{"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"scale": [2, 1, 1], "mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "COLOR_0": 2}}]}],
        "accessors": [
          {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
          {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"},
          {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC3"}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
          {"buffer": 0, "byteOffset": 36, "byteLength": 36}, {"buffer": 0, "byteOffset": 72, "byteLength": 36}],
        "buffers": [{"uri": "t.bin", "byteLength": 108}]}"#;
    let path = dir.path().join("t.gltf");
    std::fs::write(&path, json).unwrap();
    let m = codec::load_path(&path).unwrap();
    // (0.6, 0, 0.8) under scale (2, 1, 1): (0.3, 0, 0.8), normalized.
    let l = (0.3f32 * 0.3 + 0.8 * 0.8).sqrt();
    for got in &m.normals {
        assert!(close(*got, [0.3 / l, 0.0, 0.8 / l], 1e-6), "{got:?}");
    }
    assert_eq!(m.colors, vec![[255, 128, 0, 255], [0, 255, 64, 255], [51, 51, 51, 255]]);
}

/// Whether `gltf` holds the triangles of `obj`, with the same orientation, corners within
/// `tol` of the bounding box's diagonal.
fn same_triangles(gltf: &Mesh, obj: &Mesh, tol: f32, name: &str) {
    let (lo, hi) = codec::mesh::bounding_box(obj.positions.iter()).unwrap();
    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f32>().sqrt();
    // Each glTF vertex is the nearest OBJ vertex (brute force: a few thousand each).
    let map: Vec<u32> = gltf
        .positions
        .iter()
        .map(|p| {
            let d = |q: &[f32; 3]| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f32>();
            let (i, q) = obj.positions.iter().enumerate().min_by(|a, b| d(a.1).total_cmp(&d(b.1))).unwrap();
            assert!(d(q).sqrt() <= tol * diag, "{name}: {p:?} is {} from the nearest OBJ vertex", d(q).sqrt());
            i as u32
        })
        .collect();
    // Triangles up to rotation (orientation kept), as sorted lists.
    let canon = |t: [u32; 3]| {
        let k = (0..3).min_by_key(|&k| t[k]).unwrap();
        [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
    };
    let mut a: Vec<[u32; 3]> = gltf.triangles.iter().map(|t| canon(t.map(|i| map[i as usize]))).collect();
    let mut b: Vec<[u32; 3]> = obj.triangles.iter().map(|&t| canon(t)).collect();
    a.sort_unstable();
    b.sort_unstable();
    assert_eq!(a.len(), b.len(), "{name}: triangle counts");
    assert!(a == b, "{name}: the triangles differ");
}

#[test]
fn peer_tools_files_hold_the_obj_mesh() {
    let obj = load_path(&testkit::mesh_path("classic/cow.obj")).unwrap();
    for (name, tol) in [
        ("cow_embedded.gltf", 1e-6),
        ("separate/cow_separate.gltf", 1e-6),
        ("cow.glb", 1e-6),
        // glTF Transform's defaults: Draco quantizes positions to 14 bits, meshopt to 16 bits.
        ("cow_draco.glb", 1.0 / 8192.0),
        ("cow_meshopt.glb", 1.0 / 16384.0),
    ] {
        let m = load_path(&fixture(name)).unwrap_or_else(|e| panic!("{e}"));
        same_triangles(&m, &obj, tol, name);
    }
}

#[test]
fn glb_is_recognised_by_content_and_corrupt_files_get_one_line() {
    let glb = std::fs::read(fixture("cow_meshopt.glb")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let renamed = dir.path().join("model.bin");
    std::fs::write(&renamed, &glb).unwrap();
    assert_eq!(Format::of_file(&renamed).unwrap(), Format::Gltf);
    assert!(load_path(&renamed).is_ok());
    // Truncations and flipped bytes in every fixture: an error or a mesh, never a panic,
    // and every error is one line naming the file.
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let path = Path::new("m.glb");
    for name in ["cow_draco.glb", "cow_meshopt.glb", "handmade.glb", "handmade.gltf"] {
        let bytes = std::fs::read(fixture(name)).unwrap();
        for round in 0..1000 {
            let mut b = bytes.clone();
            if round % 3 == 0 {
                b.truncate(next() as usize % b.len());
            } else {
                for _ in 0..1 + next() % 4 {
                    let at = next() as usize % b.len();
                    b[at] ^= 1 << (next() % 8);
                }
            }
            if let Err(e) = load_bytes(path, &b, Format::Gltf) {
                let e = e.to_string();
                assert!(!e.contains('\n') && e.starts_with("m.glb: "), "{name}: {e}");
            }
        }
    }
}

/// A GLB whose one primitive is Draco-compressed with `NORMAL` and `COLOR_0` (written here
/// with draco-core's encoder): its normals and colours load as an uncompressed file's do.
#[test]
fn draco_compressed_normals_and_colours_load() {
    use draco_core::{DataType, EncoderBuffer, EncoderOptions, GeometryAttributeType, MeshEncoder, PointAttribute};
    let positions = [[0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    let normals = [[0f32, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, 0.6, 0.8], [0.0, 0.0, 1.0]];
    let colors = [[255u8, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255], [10, 20, 30, 40]];
    let mut mesh = draco_core::Mesh::new();
    let mut add = |ty, comps: u8, data_type, normalized, bytes: Vec<u8>| {
        let mut a = PointAttribute::new();
        a.init(ty, comps, data_type, normalized, 4);
        a.buffer_mut().write(0, &bytes);
        mesh.add_attribute(a)
    };
    let floats = |v: &[[f32; 3]]| v.iter().flatten().flat_map(|c| c.to_le_bytes()).collect::<Vec<u8>>();
    let p = add(GeometryAttributeType::Position, 3, DataType::Float32, false, floats(&positions));
    let n = add(GeometryAttributeType::Normal, 3, DataType::Float32, false, floats(&normals));
    let c = add(GeometryAttributeType::Color, 4, DataType::Uint8, true, colors.concat());
    mesh.set_num_faces(2);
    mesh.set_faces_from_flat_indices(&[0, 1, 2, 0, 2, 3]);
    let mut options = EncoderOptions::new();
    options.set_attribute_quantization(p, 14);
    options.set_attribute_quantization(n, 12);
    let mut encoder = MeshEncoder::new();
    encoder.set_mesh(mesh);
    let mut out = EncoderBuffer::new();
    encoder.encode(&options, &mut out).unwrap();
    let mut bin = out.data().to_vec();
    let draco_len = bin.len();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let ids = (p, n, c);
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
        "extensionsUsed": ["KHR_draco_mesh_compression"], "extensionsRequired": ["KHR_draco_mesh_compression"],
        "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1, "COLOR_0": 2}}, "indices": 3,
          "extensions": {{"KHR_draco_mesh_compression": {{"bufferView": 0,
            "attributes": {{"POSITION": {}, "NORMAL": {}, "COLOR_0": {}}}}}}}}}]}}],
        "accessors": [
          {{"componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
          {{"componentType": 5126, "count": 4, "type": "VEC3"}},
          {{"componentType": 5121, "normalized": true, "count": 4, "type": "VEC4"}},
          {{"componentType": 5125, "count": 6, "type": "SCALAR"}}],
        "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": {draco_len}}}],
        "buffers": [{{"byteLength": {}}}]}}"#,
        ids.0,
        ids.1,
        ids.2,
        bin.len()
    );
    let mut json = json.into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut glb = b"glTF".to_vec();
    glb.extend(2u32.to_le_bytes());
    glb.extend(((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
    glb.extend((json.len() as u32).to_le_bytes());
    glb.extend(b"JSON");
    glb.extend(&json);
    glb.extend((bin.len() as u32).to_le_bytes());
    glb.extend(b"BIN\0");
    glb.extend(&bin);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("draco.glb");
    std::fs::write(&path, &glb).unwrap();
    let m = codec::load_path(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(m.triangles.len(), 2);
    // Draco may reorder the points: match each loaded vertex to its input by position.
    for (k, q) in m.positions.iter().enumerate() {
        let i = positions.iter().position(|p| close(*p, *q, 1e-3)).expect("a position of the input");
        assert!(close(m.normals[k], normals[i], 2e-3), "{:?} for {:?}", m.normals[k], normals[i]);
        assert_eq!(m.colors[k], colors[i]);
    }
}
