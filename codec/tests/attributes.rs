//! Colours and normals through `.bft`: exact round trips at their quantization (single
//! streams and chunked files, manifold or not), version 2 files unchanged without them, and
//! corrupt attribute sections refused.

use codec::bft::attributes::oct_encode;
use codec::bft::chunked::{encode_mesh_chunked, ChunkOptions};
use codec::bft::{self, EncodeOptions};
use codec::Mesh;
use testkit::{assert_round_trip, paint};

fn shared(rel: &str) -> Mesh {
    codec::load_path(&testkit::shared_meshes().join(rel)).unwrap()
}

const MESHES: [&str; 6] = [
    "stanford/bunny_oded_6k.obj",
    "classic/teapot.obj",            // holes, non-manifold vertices (duplicate slots)
    "classic/beetle.obj",            // non-manifold edges
    "degenerate/fused_vertices.obj", // loose triangles
    "degenerate/all_degen.obj",      // nothing but loose triangles
    "odedstein/plane_holes.obj.gz",
];

#[test]
fn colours_and_normals_round_trip_exactly() {
    for rel in MESHES {
        for alpha in [false, true] {
            let mesh = paint(shared(rel), alpha, 7);
            let enc = assert_round_trip(&mesh, 14);
            assert_eq!(u16::from_le_bytes([enc.bytes[8], enc.bytes[9]]), 4, "{rel}: a version 4 file");
            assert_eq!(enc.header.attributes.alpha, alpha, "{rel}");
        }
    }
}

#[test]
fn each_attribute_alone_and_every_normal_precision() {
    let painted = paint(shared("classic/teapot.obj"), false, 3);
    let colours = Mesh { normals: Vec::new(), ..painted.clone() };
    let normals = Mesh { colors: Vec::new(), ..painted.clone() };
    assert_round_trip(&colours, 16);
    assert_round_trip(&normals, 16);
    for bits in [4u8, 8, 12, 16] {
        let enc = bft::encode(&normals, EncodeOptions { normal_bits: bits, ..Default::default() }).unwrap();
        let dec = bft::decode(&enc.bytes).unwrap();
        for (slot, n) in dec.attributes.normals.iter().enumerate() {
            assert_eq!(*n, oct_encode(normals.normals[enc.slot_vertex[slot] as usize], bits));
        }
    }
    for bits in [3u8, 17] {
        assert!(bft::encode(&normals, EncodeOptions { normal_bits: bits, ..Default::default() }).is_err());
    }
    // Asked not to, the encoder writes today's version 2 file, byte for byte.
    let plain = bft::encode(&Mesh::new(painted.positions.clone(), painted.triangles.clone()), Default::default());
    let off = bft::encode(&painted, EncodeOptions { colors: false, normals: false, ..Default::default() });
    assert_eq!(plain.unwrap().bytes, off.unwrap().bytes);
}

#[test]
fn attribute_counts_and_normals_are_checked() {
    let mut mesh = paint(shared("classic/teapot.obj"), false, 1);
    mesh.colors.pop();
    let e = bft::encode(&mesh, Default::default()).unwrap_err().to_string();
    assert!(e.contains("colours"), "{e}");
    let mut mesh = paint(shared("classic/teapot.obj"), false, 1);
    let v = mesh.triangles[5][1] as usize;
    mesh.normals[v][2] = f32::NAN;
    let e = bft::encode(&mesh, Default::default()).unwrap_err().to_string();
    assert!(e.contains(&format!("vertex {v} has a non-finite normal")), "{e}");
}

/// Vertex `(position, colour, normal code)` triples of a welded mesh, sorted.
fn vertex_set(m: &Mesh, bits: u8) -> Vec<([u32; 3], [u8; 4], [u16; 2])> {
    let mut v: Vec<_> = (0..m.positions.len())
        .map(|i| (m.positions[i].map(f32::to_bits), m.colors[i], oct_encode(m.normals[i], bits)))
        .collect();
    v.sort_unstable();
    v
}

#[test]
fn chunked_files_carry_the_attributes_of_every_chunk() {
    for rel in ["stanford/bunny_oded_6k.obj", "classic/beetle.obj"] {
        let mesh = paint(shared(rel), true, 11);
        let single = bft::decode(&bft::encode(&mesh, Default::default()).unwrap().bytes).unwrap();
        let options = ChunkOptions { chunk_triangles: 500, ..Default::default() };
        let (bytes, enc) = encode_mesh_chunked(&mesh, &options).unwrap();
        assert!(enc.header.chunks > 3, "{rel}");
        let chunked = bft::decode(&bytes).unwrap();
        assert!(chunked.header.attributes.colors && chunked.header.attributes.alpha);
        let bits = chunked.attributes.normal_bits;
        // Decoded normals re-quantize to their own codes: compare codes.
        assert_eq!(vertex_set(&chunked.to_mesh(), bits), vertex_set(&single.to_mesh(), bits), "{rel}");
        let stats = bft::Stats::of(&bytes).unwrap();
        assert!(stats.color_bytes > 0 && stats.normal_bytes > 0);
    }
}

#[test]
fn corrupt_attribute_sections_are_errors_not_panics() {
    let mesh = paint(shared("classic/teapot.obj"), true, 5);
    let enc = bft::encode(&mesh, Default::default()).unwrap();
    for copy in testkit::bit_flipped_copies(&enc.bytes, 300) {
        let _ = bft::decode(&copy);
    }
    // Flipped bits inside the colour and normal streams, checksums refreshed: decoded values
    // change or the decoder refuses, and it never panics.
    let start = testkit::sections_start(&enc.bytes);
    let mut rng = testkit::XorShift(9);
    for _ in 0..300 {
        let mut b = enc.bytes.clone();
        let i = start + (rng.next_u64() as usize % (b.len() - start));
        b[i] ^= 1 << (rng.next_u64() % 8);
        testkit::refresh_checksums(&mut b, start);
        let _ = bft::decode(&b);
    }
    // Colour and normal streams cut short (checksums valid) are refused, never misread.
    for tag in [*b"COLR", *b"NORM"] {
        let cut = shorten(&enc.bytes, tag);
        let e = bft::decode(&cut).unwrap_err().to_string();
        assert!(e.contains("truncated") || e.contains("corrupt"), "{e}");
    }
}

/// `bytes` with the section `tag` cut to half its payload, checksums refreshed.
fn shorten(bytes: &[u8], tag: [u8; 4]) -> Vec<u8> {
    let mut out = bytes[..testkit::sections_start(bytes)].to_vec();
    let mut pos = out.len();
    while pos < bytes.len() {
        let n = u32::from_le_bytes(bytes[pos + 4..pos + 8].try_into().unwrap()) as usize;
        let payload = &bytes[pos + 8..pos + 8 + n];
        let keep = if bytes[pos..pos + 4] == tag { &payload[..n / 2] } else { payload };
        out.extend_from_slice(&bytes[pos..pos + 4]);
        out.extend_from_slice(&(keep.len() as u32).to_le_bytes());
        out.extend_from_slice(keep);
        out.extend_from_slice(&crc32fast::hash(keep).to_le_bytes());
        pos += 12 + n;
    }
    out
}

/// A header that claims more input vertices than the cap on decompressed input allows is
/// refused with a one-line error before anything that size is allocated (`to_mesh` would
/// make room for every input vertex).
#[test]
fn a_forged_count_of_input_vertices_is_refused_not_allocated() {
    let mesh = shared("classic/beetle.obj");
    let opts = EncodeOptions { keep_order: true, ..Default::default() };
    let mut bytes = bft::encode(&mesh, opts).unwrap().bytes;
    let header_len = u16::from_le_bytes([bytes[10], bytes[11]]) as usize;
    bytes[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
    let crc = crc32fast::hash(&bytes[12..12 + header_len]);
    bytes[12 + header_len..16 + header_len].copy_from_slice(&crc.to_le_bytes());
    let e = bft::decode(&bytes).unwrap_err().to_string();
    assert!(e.contains("4294967295 input vertices") && e.contains("--max-decompressed"), "{e}");
    assert!(!e.contains('\n'), "{e}");
}

/// `keep_order`: the decoded mesh has every input vertex at its input index (unused ones at
/// the origin) and the input's triangles index for index, single-stream and chunked.
#[test]
fn kept_order_gives_the_input_indices_back() {
    for rel in ["stanford/bunny_zipper_c3d.obj.gz", "classic/beetle.obj", "degenerate/fused_vertices.obj"] {
        let mesh = paint(shared(rel), false, 2);
        let opts = EncodeOptions { keep_order: true, ..Default::default() };
        let single = bft::encode(&mesh, opts).unwrap().bytes;
        let chunk = ChunkOptions { chunk_triangles: 2000, stream: opts, ..Default::default() };
        let (chunked, _) = encode_mesh_chunked(&mesh, &chunk).unwrap();
        for bytes in [single, chunked] {
            let back = bft::decode(&bytes).unwrap().to_mesh();
            assert_eq!(back.positions.len(), mesh.positions.len(), "{rel}");
            let mut a = back.triangles.iter().map(|&t| testkit::canonical(t)).collect::<Vec<_>>();
            let mut b = mesh.triangles.iter().map(|&t| testkit::canonical(t)).collect::<Vec<_>>();
            a.sort_unstable();
            b.sort_unstable();
            assert!(a == b, "{rel}: the triangles differ by index");
            let used = mesh.used_vertices();
            let q = codec::Quantization::fit(&mesh.positions, Some(&used), 16).unwrap();
            for v in (0..mesh.positions.len()).filter(|&v| used[v]) {
                assert_eq!(back.positions[v], q.dequantize(q.quantize(mesh.positions[v])), "{rel}: vertex {v}");
                assert_eq!(back.colors[v], mesh.colors[v], "{rel}: vertex {v}");
            }
            let stats = bft::Stats::of(&bytes).unwrap();
            assert!(stats.order_bytes > 0 && stats.header.attributes.order);
        }
    }
}
