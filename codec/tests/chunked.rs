//! Chunked `.bft` files: the whole file decodes to the input exactly, whatever the chunk
//! size; every frame's tiles, from verbatim chunks and sorted pieces together, decode with
//! the ordinary decoder to exactly the triangles whose box `[t]` holds the tile; a damaged
//! directory or chunk is an error naming the chunk.

use codec::bft::chunked::sort::{ChunkedModel, Class, PieceKind};
use codec::bft::chunked::{encode_mesh_chunked, ChunkOptions, ChunkedFile};
use codec::bft::{self, Coding};
use codec::view::{triangle_tile_boxes, Camera, TileGrid};
use codec::{Mesh, Quantization};
use glam::Vec3;
use proptest::prelude::*;
use testkit::{canonical, sorted_canonical};

/// A chunked file (of one chunk too), with the input vertex of every slot.
fn chunked(mesh: &Mesh, chunk: u32) -> (Vec<u8>, Vec<u32>) {
    chunked_coded(mesh, chunk, Coding::Range)
}

/// [`chunked`] with the chunks' streams entropy-coded as `coding` says.
fn chunked_coded(mesh: &Mesh, chunk: u32, coding: Coding) -> (Vec<u8>, Vec<u32>) {
    let opts = ChunkOptions {
        chunk_triangles: chunk,
        keep_slot_vertex: true,
        one_chunk_as_stream: false,
        stream: bft::EncodeOptions { coding, ..Default::default() },
        ..Default::default()
    };
    let (bytes, enc) = encode_mesh_chunked(mesh, &opts).expect("encodes");
    assert_eq!(enc.bytes as usize, bytes.len());
    (bytes, enc.slot_vertex)
}

/// Decoding the whole file keeps the single-stream guarantee: the input's triangle multiset
/// on input vertex indices, orientation kept, every slot at its vertex's quantized position,
/// links and duplicates naming the same vertex, and the welded mesh one vertex per used one.
fn assert_chunked_round_trip(mesh: &Mesh, chunk: u32, coding: Coding) -> ChunkedFile<Vec<u8>> {
    let (bytes, slot_vertex) = chunked_coded(mesh, chunk, coding);
    let file = ChunkedFile::open(bytes.clone()).expect("opens");
    assert!(file.entries.iter().all(|e| e.triangles <= chunk));
    for c in 0..file.entries.len() {
        assert_eq!(bft::Stats::of(&file.chunk_bft(c).unwrap()).unwrap().header.coding, coding, "chunk {c}");
    }
    let dec = bft::decode(&bytes).expect("decodes");
    assert_eq!(dec.triangles.len(), mesh.triangles.len());
    assert_eq!(slot_vertex.len(), dec.positions.len());
    let back = dec.triangles.iter().map(|t| t.map(|s| slot_vertex[s as usize]));
    assert!(sorted_canonical(back) == sorted_canonical(mesh.triangles.iter().copied()), "triangles differ");
    let used = mesh.used_vertices();
    let q = Quantization::fit(&mesh.positions, Some(&used), 16).unwrap();
    assert_eq!(dec.quantization(), q);
    for (slot, p) in dec.positions.iter().enumerate() {
        assert_eq!(*p, q.quantize(mesh.positions[slot_vertex[slot] as usize]), "slot {slot}");
    }
    for &(slot, source) in &dec.duplicates {
        assert!(source < slot);
        assert_eq!(slot_vertex[slot as usize], slot_vertex[source as usize], "slot {slot} -> {source}");
    }
    let welded = dec.to_mesh();
    assert_eq!(welded.positions.len(), used.iter().filter(|&&u| u).count(), "one vertex per used input vertex");
    assert_eq!(file.header.unique_vertices as usize, welded.positions.len());
    file
}

const MESHES: [&str; 7] = [
    "classic/teapot.obj",               // holes, non-manifold vertices, 4 components
    "classic/beetle.obj",               // non-manifold edges, 23 holes
    "stanford/dragon_vrip_res4.ply.gz", // non-manifold, duplicate faces
    "odedstein/plane_holes.obj.gz",     // 27 holes
    "classic/ogre.obj.gz",              // 44 components
    "degenerate/fused_vertices.obj",
    "degenerate/non_manifold_face_graph.obj",
];

#[test]
fn shared_meshes_round_trip_at_every_chunk_size() {
    for rel in MESHES {
        let mesh = testkit::load_mesh(rel);
        let n = mesh.triangles.len() as u32;
        for (chunk, coding) in
            [3, 61, 1000, n.max(1)].into_iter().flat_map(|c| [(c, Coding::Range), (c, Coding::Prefix)])
        {
            let file = assert_chunked_round_trip(&mesh, chunk, coding);
            assert_eq!(
                file.header.chunks as usize,
                (n as usize).div_ceil(chunk as usize).max(1).min(file.entries.len())
            );
        }
    }
}

/// A model of one chunk is today's model: the chunked encoder writes it as the single-stream
/// file `bft::encode` writes, byte for byte (unused vertices included, as the bunny has).
#[test]
fn a_one_chunk_model_is_the_single_stream_file() {
    for rel in ["classic/teapot.obj", "stanford/bunny_zipper_c3d.obj.gz", "degenerate/fused_vertices.obj"] {
        let mesh = testkit::load_mesh(rel);
        let single = bft::encode(&mesh, bft::EncodeOptions::default()).unwrap();
        let opts = ChunkOptions { chunk_triangles: mesh.triangles.len() as u32, ..Default::default() };
        let (bytes, enc) = encode_mesh_chunked(&mesh, &opts).unwrap();
        assert!(bytes == single.bytes, "{rel}");
        assert_eq!(enc.header.chunks, 1);
        let (bytes, _) = chunked(&mesh, u32::MAX);
        let file = ChunkedFile::open(bytes).unwrap();
        assert_eq!(file.entries.len(), 1);
        assert!(file.border(0).unwrap().slots.is_empty(), "one chunk has no border");
        assert!(file.chunk_bft(0).unwrap()[12..] == single.bytes[12..] || mesh.used_vertices().contains(&false));
    }
}

/// `tessera encode`'s default: a model at most `one_stream_up_to` triangles is the single-
/// stream file whatever the chunk size; one above it is chunked.
#[test]
fn a_model_small_enough_for_one_stream_is_one_stream() {
    let mesh = testkit::load_mesh("stanford/bunny_zipper_c3d.obj.gz");
    let single = bft::encode(&mesh, bft::EncodeOptions::default()).unwrap();
    let t = mesh.triangles.len() as u64;
    let opts = |up_to: u64| ChunkOptions { chunk_triangles: 4096, one_stream_up_to: up_to, ..Default::default() };
    let (bytes, enc) = encode_mesh_chunked(&mesh, &opts(t)).unwrap();
    assert!(bytes == single.bytes, "at the threshold: the single-stream file");
    assert_eq!(enc.header.chunks, 1);
    let (bytes, enc) = encode_mesh_chunked(&mesh, &opts(t - 1)).unwrap();
    assert!(enc.header.chunks > 1 && bytes != single.bytes, "above it: chunks");
    assert_eq!(bytes, chunked(&mesh, 4096).0, "the chunked file of 4096-triangle chunks");
    assert_eq!(codec::bft::chunked::ONE_STREAM_MAX_TRIANGLES, 4 << 20);
}

/// The pieces of a chunked frame decode with the ordinary decoder to exactly the triangles
/// whose `[t]` holds each tile; returns (verbatim, straddling, culled) chunk counts.
fn check_frame(model: &ChunkedModel<Vec<u8>>, whole: &bft::Decoded, cam: &Camera, grid: &TileGrid) -> [u32; 3] {
    let vp = cam.view_proj(grid.aspect());
    let q = whole.quantization();
    let positions: Vec<[f32; 3]> = whole.positions.iter().map(|&p| q.dequantize(p)).collect();
    let boxes = triangle_tile_boxes(&positions, &whole.triangles, vp, grid);
    let mut expected = testkit::triangles_by_tile(&whole.triangles, &boxes, grid);
    let classes = model.classify_all(vp, grid);
    for coding in [Coding::Prefix, Coding::Range] {
        let (tiles, counts) = model.sort(vp, grid, coding).expect("sorts");
        let mut got = vec![Vec::new(); grid.tiles()];
        for tile in &tiles {
            for p in &tile.pieces {
                let e = model.file.entries[p.chunk as usize];
                let (tris, base): (Vec<[u32; 3]>, u32) = match &p.kind {
                    PieceKind::Verbatim => {
                        assert_eq!(classes[p.chunk as usize], Class::Verbatim(tile.index as u32));
                        (bft::decode(&model.file.chunk_bft(p.chunk as usize).unwrap()).unwrap().triangles, e.first_slot)
                    }
                    PieceKind::Sorted { bytes, slots, .. } => {
                        let d = bft::decode(bytes).expect("a piece decodes");
                        (d.triangles.iter().map(|t| t.map(|s| slots[s as usize])).collect(), e.first_slot)
                    }
                };
                assert_eq!(tris.len(), p.triangles as usize);
                got[tile.index].extend(tris.iter().map(|t| canonical(t.map(|s| s + base))));
            }
        }
        for (b, (g, w)) in got.iter_mut().zip(expected.iter_mut()).enumerate() {
            g.sort_unstable();
            w.sort_unstable();
            assert!(g == w, "tile {b}: {} triangles from the pieces, {} expected", g.len(), w.len());
        }
        let sum = counts.verbatim + counts.straddling + counts.culled;
        assert_eq!(sum as usize, model.chunks());
    }
    let count = |f: &dyn Fn(&Class) -> bool| classes.iter().filter(|c| f(c)).count() as u32;
    [count(&|c| matches!(c, Class::Verbatim(_))), count(&|c| *c == Class::Straddling), count(&|c| *c == Class::Culled)]
}

/// Cameras around the model (see [`testkit::cameras_around`]): most chunks are culled in the
/// close-up from inside the box.
fn cameras(h: &codec::bft::chunked::ChunkedHeader, aspect: f32) -> Vec<Camera> {
    testkit::cameras_around(h.bbox_min, h.bbox_max, aspect)
}

#[test]
fn shared_meshes_sort_exactly_from_chunks() {
    let mut totals = [0u32; 3];
    for rel in MESHES.iter().chain(&["stanford/bunny_zipper_c3d.obj.gz"]) {
        let mesh = testkit::load_mesh(rel);
        // Prefix-coded chunks too: verbatim ones are forwarded as the file has them.
        let sizes = [
            (5, Coding::Range),
            (300, Coding::Range),
            (300, Coding::Prefix),
            (4096, Coding::Range),
            (u32::MAX, Coding::Range),
        ];
        for (chunk, coding) in sizes {
            let (bytes, _) = chunked_coded(&mesh, chunk, coding);
            let whole = bft::decode(&bytes).unwrap();
            // A small cache bound, so that chunks are evicted and built again.
            let model = ChunkedModel::new(ChunkedFile::open(bytes).unwrap(), 1 << 20);
            for (w, h, c, r) in [(1920, 1080, 8, 8), (1000, 601, 7, 3), (640, 480, 1, 1), (333, 257, 64, 64)] {
                let grid = TileGrid::new(w, h, c, r).unwrap();
                for cam in cameras(&model.file.header, grid.aspect()) {
                    let k = check_frame(&model, &whole, &cam, &grid);
                    (0..3).for_each(|i| totals[i] += k[i]);
                }
            }
        }
    }
    // Every class occurs: the test covers forwarding, sorting and culling.
    assert!(totals.iter().all(|&n| n > 100), "verbatim, straddling, culled: {totals:?}");
}

/// A frame's tiles as comparable values: per tile its pieces' chunk, triangles and, for a
/// sorted piece, its bytes, slots and border normals (as bits).
type PieceValue = (u32, u32, Option<(Vec<u8>, Vec<u32>, Vec<(u32, [u32; 3])>)>);

fn frame_values(tiles: &[codec::bft::chunked::sort::ChunkedTile]) -> Vec<(usize, Vec<PieceValue>)> {
    let piece = |p: &codec::bft::chunked::sort::Piece| -> PieceValue {
        let sorted = match &p.kind {
            PieceKind::Verbatim => None,
            PieceKind::Sorted { bytes, slots, normals } => {
                Some((bytes.clone(), slots.clone(), normals.iter().map(|&(s, n)| (s, n.map(f32::to_bits))).collect()))
            }
        };
        (p.chunk, p.triangles, sorted)
    };
    tiles.iter().map(|t| (t.index, t.pieces.iter().map(piece).collect())).collect()
}

/// A model that sorted the frame before takes from it the pieces of the tiles whose
/// triangles did not change: its frames are exactly those of a model that sorts each frame
/// afresh, along slow and fast orbits, when the grid or the coding changes, and when chunks
/// stop straddling and come back.
#[test]
fn pieces_kept_from_the_frame_before_are_those_a_fresh_sort_makes() {
    for (rel, chunk) in [("stanford/bunny_zipper_c3d.obj.gz", 1024), ("classic/beetle.obj", 300)] {
        let mesh = testkit::load_mesh(rel);
        let (reused, sorted) = orbit_with_kept_pieces(&mesh, chunk, 1 << 24);
        // The slow orbits reuse a good share; not everything (the test sees both paths).
        assert!(reused > sorted / 20 && reused < sorted, "{rel}: {reused} of {sorted} visible triangles reused");
        // Sorts are kept only in the room the tables leave under the cache's bound.
        assert_eq!(orbit_with_kept_pieces(&mesh, chunk, 0).0, 0, "{rel}: kept beyond the cache's bound");
        // A bound the tables alone overflow: what is kept still fits it (asserted within).
        orbit_with_kept_pieces(&mesh, chunk, 1 << 16);
    }
}

/// A still view's second frame takes every straddling chunk's pieces from the first: sorts
/// are kept from a model's first frame on, before the cache knows its tables' bytes.
#[test]
fn a_still_view_reuses_its_first_frame() {
    let (bytes, _) = chunked(&testkit::load_mesh("stanford/bunny_zipper_c3d.obj.gz"), 1024);
    let model = ChunkedModel::new(ChunkedFile::open(bytes.clone()).unwrap(), 1 << 24);
    let grid = TileGrid::new(1920, 1080, 8, 8).unwrap();
    let h = model.file.header;
    let vp = Camera::framing(h.bbox_min, h.bbox_max, grid.aspect()).view_proj(grid.aspect());
    let (first, counts) = model.sort(vp, &grid, Coding::Prefix).unwrap();
    assert_eq!(counts.reused_triangles, 0);
    let (second, counts) = model.sort(vp, &grid, Coding::Prefix).unwrap();
    assert!(frame_values(&first) == frame_values(&second), "the second frame differs");
    let sorted: u64 = second
        .iter()
        .flat_map(|t| &t.pieces)
        .filter(|p| matches!(p.kind, PieceKind::Sorted { .. }))
        .map(|p| p.triangles as u64)
        .sum();
    assert!(counts.straddling > 0 && sorted > 0);
    assert_eq!(counts.reused_triangles, sorted, "every straddling piece is the first frame's");
    // A model told not to keep sorts sorts every frame afresh, to the same tiles.
    let mut model = ChunkedModel::new(ChunkedFile::open(bytes).unwrap(), 1 << 24);
    model.keep_sorts = false;
    for _ in 0..2 {
        let (tiles, counts) = model.sort(vp, &grid, Coding::Prefix).unwrap();
        assert!(frame_values(&tiles) == frame_values(&first));
        assert_eq!(counts.reused_triangles, 0);
    }
}

/// Sorts an orbit with one model and with a fresh one per frame; returns the triangles the
/// first reused and its visible triangles.
fn orbit_with_kept_pieces(mesh: &Mesh, chunk: u32, cache: usize) -> (u64, u64) {
    let (bytes, _) = chunked(mesh, chunk);
    let kept = ChunkedModel::new(ChunkedFile::open(bytes.clone()).unwrap(), cache);
    let h = kept.file.header;
    let grids = [TileGrid::new(1920, 1080, 8, 8).unwrap(), TileGrid::new(1000, 601, 7, 3).unwrap()];
    let start = Camera::framing(h.bbox_min, h.bbox_max, grids[0].aspect());
    let (mut reused, mut sorted) = (0u64, 0u64);
    let mut frame = 0;
    // Closer in the third and fourth runs, so that chunks leave the screen and come back.
    for (grid, coding, degrees, zoom) in [
        (grids[0], Coding::Prefix, 0.05f32, 1.0),
        (grids[0], Coding::Prefix, 1.0, 1.0),
        (grids[1], Coding::Prefix, 0.5, 0.45),
        (grids[1], Coding::Range, 0.5, 0.45),
        (grids[0], Coding::Prefix, 40.0, 1.0),
    ] {
        for _ in 0..4 {
            frame += 1;
            let rot = glam::Quat::from_axis_angle(Vec3::Y, (degrees * frame as f32).to_radians());
            let cam = Camera { eye: start.target + rot * (start.eye - start.target) * zoom, ..start };
            let vp = cam.view_proj(grid.aspect());
            let (tiles, counts) = kept.sort(vp, &grid, coding).unwrap();
            let fresh = ChunkedModel::new(ChunkedFile::open(bytes.clone()).unwrap(), 1 << 24);
            let (want, want_counts) = fresh.sort(vp, &grid, coding).unwrap();
            assert!(frame_values(&tiles) == frame_values(&want), "frame {frame}: the kept model's tiles differ");
            assert_eq!(want_counts.reused_triangles, 0);
            assert_eq!(counts.straddling, want_counts.straddling);
            reused += counts.reused_triangles;
            sorted += counts.visible_triangles;
        }
    }
    assert!(kept.cached_bytes() <= cache);
    (reused, sorted)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Random holed grids (several copies: many components) cut into chunks of random size,
    /// under random cameras (inside the model, looking past it) on random tile grids.
    #[test]
    fn random_meshes_chunks_and_cameras_sort_exactly(
        w in 2usize..30, h in 2usize..30, copies in 1usize..4,
        holes in prop::collection::vec(prop::bool::weighted(0.1), 1..30),
        seed: u64, chunk in 1u32..400,
        eye in (-2.0f32..2.0, -2.0f32..2.0, -0.5f32..3.0),
        target in (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0),
        fovy in 20.0f32..120.0, near in 0.01f32..0.5,
        size in (1u32..700, 1u32..500), tiles in (1u32..65, 1u32..65),
    ) {
        let mesh = testkit::holed_grids(w, h, copies, &holes, seed);
        prop_assume!(!mesh.triangles.is_empty());
        let file = assert_chunked_round_trip(&mesh, chunk, Coding::Range);
        let whole = bft::decode(file.bytes()).unwrap();
        let model = ChunkedModel::new(file, 1 << 16);
        let cam = Camera { eye: eye.into(), target: target.into(), up: Vec3::Y, fovy, near, far: near + 10.0, shift: [0.0; 2] };
        prop_assume!(cam.validate().is_ok());
        let grid = TileGrid::new(size.0, size.1, tiles.0.min(size.0), tiles.1.min(size.1)).unwrap();
        check_frame(&model, &whole, &cam, &grid);
    }
}

/// A chunk's border normals are the whole model's: a worker shading a verbatim chunk or a
/// sorted piece, with the normals that come with it, gets every slot's model normal, which
/// for a vertex inside one chunk is the one the chunk's own triangles give.
#[test]
fn border_normals_complete_each_chunk() {
    use codec::bft::chunked::{oct_decode, oct_encode};
    use codec::bft::normals::{unit, vertex_normals};
    let mesh = testkit::load_mesh("classic/teapot.obj");
    let (bytes, slot_vertex) = chunked(&mesh, 200);
    let file = ChunkedFile::open(bytes).unwrap();
    // The model normal of each input vertex: chunk sums added in file order.
    let mut sums = vec![Vec3::ZERO; mesh.positions.len()];
    let mut normal_of = vec![None; mesh.positions.len()];
    for i in 0..file.entries.len() {
        let d = file.decode_chunk(i).unwrap();
        let q = d.quantization();
        let p: Vec<[f32; 3]> = d.positions.iter().map(|&x| q.dequantize(x)).collect();
        let (source, acc) = codec::bft::normals::face_normal_sums(&p, &d.triangles, &d.duplicates);
        for s in 0..p.len() {
            if source[s] as usize == s {
                sums[slot_vertex[file.entries[i].first_slot as usize + s] as usize] += acc[s];
            }
        }
    }
    for (v, s) in sums.iter().enumerate() {
        // Border normals are stored octahedral: the model normal is what they decode to.
        let n = unit(*s);
        let stored = oct_decode(oct_encode(n));
        assert!(glam::Vec3::from(n).distance(glam::Vec3::from(stored)) < 1e-4, "{n:?} stored as {stored:?}");
        normal_of[v] = Some((n, stored));
    }
    let (mut bordered, mut linked) = (0, 0);
    for i in 0..file.entries.len() {
        linked += file.border(i).unwrap().links.iter().flatten().count() as u64;
        let d = file.decode_chunk(i).unwrap();
        let q = d.quantization();
        let p: Vec<[f32; 3]> = d.positions.iter().map(|&x| q.dequantize(x)).collect();
        let mut normals = vertex_normals(&p, &d.triangles, &d.duplicates);
        let border = file.border(i).unwrap();
        bordered += border.slots.len();
        let mut is_border = vec![false; normals.len()];
        for (s, n) in border.slot_normals() {
            normals[s as usize] = n;
            is_border[s as usize] = true;
        }
        for (s, n) in normals.iter().enumerate() {
            let v = slot_vertex[file.entries[i].first_slot as usize + s] as usize;
            let (exact, stored) = normal_of[v].unwrap();
            let want = if is_border[s] { stored } else { exact };
            assert_eq!(n.map(f32::to_bits), want.map(f32::to_bits), "chunk {i} slot {s}");
        }
    }
    assert!(bordered > 0);
    // `tessera stats` counts the same entries and links.
    let stats = file.stats().unwrap();
    assert_eq!((stats.border_entries, stats.border_links), (bordered as u64, linked));
    assert!(linked > 0 && linked < bordered as u64, "{linked} of {bordered} entries linked");
}

fn refresh_dir_crc(b: &mut [u8]) {
    let hlen = u16::from_le_bytes([b[10], b[11]]) as usize;
    let chunks = u32::from_le_bytes(b[12 + 12..12 + 16].try_into().unwrap()) as usize;
    let start = 16 + hlen;
    let end = start + chunks * codec::bft::chunked::ENTRY_LEN;
    if end + 4 > b.len() {
        return;
    }
    let crc = crc32fast::hash(&b[start..end]);
    b[end..end + 4].copy_from_slice(&crc.to_le_bytes());
}

/// A damaged directory is refused when the file is opened, naming the chunk; a damaged chunk
/// when it is read.
#[test]
fn bad_directories_and_chunks_are_named() {
    let mesh = testkit::load_mesh("classic/teapot.obj");
    let (bytes, _) = chunked(&mesh, 500);
    let file = ChunkedFile::open(bytes.clone()).unwrap();
    assert!(file.entries.len() >= 4);
    let hlen = u16::from_le_bytes([bytes[10], bytes[11]]) as usize;
    let dir = 16 + hlen;
    let entry = |i: usize| dir + i * codec::bft::chunked::ENTRY_LEN;
    let open_err = |b: &[u8]| ChunkedFile::open(b.to_vec()).err().expect("refused").to_string();
    // The second chunk's offset moved past the file's end; into the first; its byte
    // length grown (overlap); its triangle count changed.
    let cases: [(usize, u64, &str); 4] = [
        (entry(1), bytes.len() as u64 + 10, "chunk 1: its bytes start at"),
        (entry(1), file.entries[0].offset + 1, "chunk 1: its bytes start at"),
        (entry(1) + 8, file.entries[1].bft_len as u64 + 7, "chunk 2: its bytes start at"),
        (entry(1) + 16, file.entries[1].triangles as u64 + 1, "chunk 2: its first triangle"),
    ];
    for (at, value, want) in cases {
        let mut b = bytes.clone();
        if at == entry(1) {
            b[at..at + 8].copy_from_slice(&value.to_le_bytes());
        } else {
            b[at..at + 4].copy_from_slice(&(value as u32).to_le_bytes());
        }
        refresh_dir_crc(&mut b);
        let e = open_err(&b);
        assert!(e.contains(want), "{e}");
        assert!(!e.contains('\n'));
    }
    // Without a refreshed checksum the directory is corrupt as such.
    let mut b = bytes.clone();
    b[entry(2)] ^= 1;
    assert_eq!(open_err(&b), "checksum mismatch in chunk directory: the file is corrupt");
    // Truncated anywhere: refused at open.
    for cut in [5, 20, entry(1), bytes.len() - 1] {
        assert!(ChunkedFile::open(bytes[..cut].to_vec()).is_err(), "cut at {cut}");
    }
    // A flipped byte inside chunk 3's stream: the file opens; reading the chunk names it.
    let mut b = bytes.clone();
    let e3 = file.entries[3];
    b[e3.offset as usize + e3.bft_len as usize / 2] ^= 0x40;
    let f = ChunkedFile::open(b.clone()).expect("the directory is intact");
    let e = f.decode_chunk(3).unwrap_err().to_string();
    assert!(e.contains("chunk 3"), "{e}");
    assert!(bft::decode(&b).unwrap_err().to_string().contains("chunk 3"));
    let model = ChunkedModel::new(f, 1 << 20);
    assert!(model.straddler(3).err().expect("refused").to_string().contains("chunk 3"));
    // A flipped byte in chunk 2's border table.
    let mut b = bytes.clone();
    let e2 = file.entries[2];
    b[(e2.offset + e2.bft_len as u64) as usize + 1] ^= 0x01;
    let e = ChunkedFile::open(b).unwrap().border(2).unwrap_err().to_string();
    assert!(e.contains("chunk 2") && e.contains("border table"), "{e}");
}

/// Opens, decodes, reads every border table and builds every chunk's tables, and sorts a
/// frame: what the master and the fuzz target do with a file. It must return errors, never
/// panic.
fn exercise(b: &[u8]) {
    let _ = bft::decode(b);
    let _ = bft::Stats::of(b);
    if let Ok(file) = ChunkedFile::open(b.to_vec()) {
        let model = ChunkedModel::new(file, 1 << 20);
        for i in 0..model.chunks() {
            let _ = model.file.border(i);
            let _ = model.straddler(i);
        }
        let grid = TileGrid::new(200, 100, 4, 2).unwrap();
        let h = model.file.header;
        let cam = Camera::framing(h.bbox_min, h.bbox_max, grid.aspect());
        let _ = model.sort(cam.view_proj(grid.aspect()), &grid, Coding::Prefix);
    }
}

/// The fuzz target's inputs, run a few thousand times in the tests: random directories behind
/// valid checksums, and a real chunked file with bits flipped anywhere (directory, streams,
/// border tables), with the directory's checksum refreshed half the time.
#[test]
fn random_and_damaged_chunked_files_are_errors_not_panics() {
    let mut rng = testkit::XorShift(0x5eed);
    for _ in 0..2000 {
        let len = (rng.next_u64() % 600) as usize;
        exercise(&codec::bft::chunked::wrap_for_fuzzing(&rng.bytes(len)));
    }
    let mesh = testkit::load_mesh("classic/cow.obj");
    let (bytes, _) = chunked(&mesh, 700);
    for (k, mut copy) in testkit::bit_flipped_copies(&bytes, 400).into_iter().enumerate() {
        if k % 2 == 0 {
            refresh_dir_crc(&mut copy);
        }
        exercise(&copy);
    }
}

/// `tessera stats` counts a chunked model's components chunk by chunk, over slots joined by
/// their duplicates and border links: as many as the whole model decoded and welded has, on
/// meshes of one, several and many components (separate grids, a scan with holes).
#[test]
fn components_counted_chunk_by_chunk_are_the_welded_model_s() {
    for (name, mesh) in [
        ("teapot", testkit::load_mesh("classic/teapot.obj")),
        ("cow", testkit::load_mesh("classic/cow.obj")),
        ("grids", testkit::holed_grids(24, 24, 5, &[true, false], 3)),
    ] {
        let whole = mesh.components();
        assert!(name != "grids" || whole > 1, "{name}: {whole} components");
        let (bytes, _) = chunked(&mesh, 200);
        let file = ChunkedFile::open(bytes).unwrap();
        assert!(file.entries.len() > 2, "{name}: {} chunks", file.entries.len());
        assert_eq!(file.decode_all().unwrap().to_mesh().components(), whole, "{name}: decoded whole");
        assert_eq!(file.components().unwrap(), whole, "{name}: chunk by chunk");
    }
}
