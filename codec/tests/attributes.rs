//! Colours and normals through `.bft`: exact round trips at their quantization (single
//! streams and chunked files, manifold or not), version 2 files unchanged without them, and
//! corrupt attribute sections refused.

use codec::bft::attributes::oct_encode;
use codec::bft::chunked::{encode_mesh_chunked, ChunkOptions};
use codec::bft::{self, Coding, EncodeOptions};
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
    decode_with_flipped_section_bits(&enc.bytes, 9);
    // Colour and normal streams cut short (checksums valid) are refused, never misread.
    for tag in [*b"COLR", *b"NORM"] {
        let cut = shorten(&enc.bytes, tag);
        let e = bft::decode(&cut).unwrap_err().to_string();
        assert!(e.contains("truncated") || e.contains("corrupt"), "{e}");
    }
}

/// A prefix-coded stream's normals are prefix-coded too (version 6; the tile sort re-codes
/// them every frame): exact at every precision, manifold or not, corrupt or cut sections
/// refused, a version 6 header that is not prefix-coded refused, and a prefix-coded version 4
/// file, whose normals are range-coded (written by the build before version 6), still read.
#[test]
fn prefix_coded_streams_prefix_code_their_normals() {
    for rel in MESHES {
        let mesh = paint(shared(rel), false, 4);
        for coding in [Coding::Prefix, Coding::PrefixByDegree] {
            for bits in [4u8, 10, 16] {
                let opts = EncodeOptions { coding, normal_bits: bits, ..Default::default() };
                let enc = bft::encode(&mesh, opts).unwrap();
                assert_eq!(u16::from_le_bytes([enc.bytes[8], enc.bytes[9]]), 6, "{rel}: a version 6 file");
                let dec = bft::decode(&enc.bytes).unwrap();
                assert_eq!(dec.attributes.normals.len(), enc.slot_vertex.len(), "{rel}");
                for (slot, n) in dec.attributes.normals.iter().enumerate() {
                    assert_eq!(*n, oct_encode(mesh.normals[enc.slot_vertex[slot] as usize], bits), "{rel} slot {slot}");
                }
            }
        }
    }
    let mesh = paint(shared("classic/teapot.obj"), false, 6);
    let enc = bft::encode(&mesh, EncodeOptions { coding: Coding::Prefix, ..Default::default() }).unwrap();
    decode_with_flipped_section_bits(&enc.bytes, 13);
    let e = bft::decode(&shorten(&enc.bytes, *b"NORM")).unwrap_err().to_string();
    assert!(e.contains("truncated") || e.contains("corrupt"), "{e}");
    // Header bytes 40-43: byte 41 the coding (0: range), 42-43 the attributes.
    let mut range = enc.bytes.clone();
    let word: [u8; 4] = range[12 + 40..12 + 44].try_into().unwrap();
    testkit::patch_header(&mut range, 40, [word[0], 0, word[2], word[3]]);
    let e = bft::decode(&range).unwrap_err().to_string();
    assert!(e.contains("version 6 file is not a prefix-coded stream with normals"), "{e}");

    let fixture = |name: &str| {
        let bytes = std::fs::read(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/formats").join(name));
        bytes.unwrap()
    };
    // The same model (a cow with per-vertex normals) written by that build range- and
    // prefix-coded: the same vertices and normals.
    let (old, range) = (fixture("spot-prefix-v4.bft"), fixture("spot-range-v4.bft"));
    assert_eq!(u16::from_le_bytes([old[8], old[9]]), 4);
    let (old, range) = (bft::decode(&old).unwrap(), bft::decode(&range).unwrap());
    assert_eq!(old.header.coding, Coding::Prefix);
    assert!(!range.attributes.normals.is_empty());
    assert_eq!((&old.positions, &old.triangles), (&range.positions, &range.triangles));
    assert_eq!(old.attributes, range.attributes);
}

/// Decodes 300 copies of `bytes`, each with a bit flipped in its sections and their checksums
/// refreshed, so that the flips reach the stream decoders; none may panic.
fn decode_with_flipped_section_bits(bytes: &[u8], seed: u64) {
    let start = testkit::sections_start(bytes);
    let mut rng = testkit::XorShift(seed);
    for _ in 0..300 {
        let mut b = bytes.to_vec();
        let i = start + (rng.next_u64() as usize % (b.len() - start));
        b[i] ^= 1 << (rng.next_u64() % 8);
        testkit::refresh_checksums(&mut b, start);
        let _ = bft::decode(&b);
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
