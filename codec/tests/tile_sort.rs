//! The tile sort is exact: every tile's submesh decodes, with the ordinary decoder, to
//! exactly the triangles `t` with that tile in `[t]` (same multiset, orientation kept),
//! with the model's quantized positions.

use codec::bft::tile_sort::{self, TileModel};
use codec::bft::{self, Coding, EncodeOptions};
use codec::view::{Camera, TileGrid};
use codec::Mesh;
use glam::Vec3;
use proptest::prelude::*;
use testkit::canonical;

/// Sorts with every coding and checks every tile; returns (non-empty tiles, triangle-tile
/// pairs).
fn check_sort(model: &TileModel, cam: &Camera, grid: &TileGrid) -> (usize, usize) {
    let range = check_coding(model, cam, grid, Coding::Range);
    assert_eq!(check_coding(model, cam, grid, Coding::Prefix), range);
    assert_eq!(check_coding(model, cam, grid, Coding::PrefixByDegree), range);
    range
}

fn check_coding(model: &TileModel, cam: &Camera, grid: &TileGrid, coding: Coding) -> (usize, usize) {
    let vp = cam.view_proj(grid.aspect());
    let boxes = tile_sort::boxes(model, vp, grid);
    let tiles = tile_sort::Sorter::new(coding).sort(model, &boxes, grid).expect("sorts");
    let mut expected = testkit::triangles_by_tile(model.triangles(), &boxes.triangles, grid);
    let pairs = expected.iter().map(Vec::len).sum();
    let mut seen = vec![false; grid.tiles()];
    for tile in &tiles {
        seen[tile.index] = true;
        let dec = bft::decode(&tile.bytes).unwrap_or_else(|e| panic!("tile {} does not decode: {e}", tile.index));
        assert_eq!(dec.header.coding, coding);
        assert_eq!(dec.positions.len(), tile.slots.len());
        for (i, p) in dec.positions.iter().enumerate() {
            assert_eq!(*p, model.decoded.positions[tile.slots[i] as usize], "tile {} vertex {i}", tile.index);
        }
        // Attributes travel with the vertices a tile keeps, exactly.
        let (a, m) = (&dec.attributes, &model.decoded.attributes);
        assert_eq!((a.alpha, a.normal_bits), (m.alpha, m.normal_bits));
        assert_eq!(a.colors.len(), if m.colors.is_empty() { 0 } else { tile.slots.len() });
        assert_eq!(a.normals.len(), if m.normals.is_empty() { 0 } else { tile.slots.len() });
        for (i, c) in a.colors.iter().enumerate() {
            assert_eq!(*c, m.colors[tile.slots[i] as usize], "tile {} vertex {i}'s colour", tile.index);
        }
        for (i, n) in a.normals.iter().enumerate() {
            assert_eq!(*n, m.normals[tile.slots[i] as usize], "tile {} vertex {i}'s normal", tile.index);
        }
        let mut got: Vec<_> = dec.triangles.iter().map(|t| canonical(t.map(|s| tile.slots[s as usize]))).collect();
        got.sort_unstable();
        let want = &mut expected[tile.index];
        want.sort_unstable();
        assert!(got == *want, "tile {}: {} triangles decoded, {} expected", tile.index, got.len(), want.len());
        assert_eq!(tile.triangles as usize, want.len());
    }
    for (b, e) in expected.iter().enumerate() {
        assert!(seen[b] || e.is_empty(), "tile {b} should hold {} triangles but is missing", e.len());
    }
    (tiles.len(), pairs)
}

fn model_of(mesh: &Mesh) -> TileModel {
    let enc = bft::encode(mesh, EncodeOptions { quant_bits: 16, ..Default::default() }).unwrap();
    TileModel::from_bytes(&enc.bytes).unwrap()
}

fn shared(rel: &str) -> TileModel {
    model_of(&codec::load_path(&testkit::shared_meshes().join(rel)).unwrap())
}

/// Cameras around a model (see [`testkit::cameras_around`]).
fn cameras(model: &TileModel, aspect: f32) -> Vec<Camera> {
    let h = model.decoded.header;
    testkit::cameras_around(h.bbox_min, h.bbox_max, aspect)
}

#[test]
fn shared_meshes_sort_exactly() {
    for rel in [
        "classic/teapot.obj",               // holes, non-manifold vertices, 4 components
        "classic/beetle.obj",               // non-manifold edges, 23 holes
        "stanford/dragon_vrip_res4.ply.gz", // non-manifold, duplicate faces
        "odedstein/plane_holes.obj.gz",     // 27 holes
        "classic/ogre.obj.gz",              // 44 components
        "degenerate/fused_vertices.obj",
        "stanford/bunny_zipper_c3d.obj.gz",
    ] {
        let model = shared(rel);
        for (w, h, c, r) in [(1920, 1080, 8, 8), (1000, 601, 7, 3), (640, 480, 1, 1), (333, 257, 64, 64)] {
            let grid = TileGrid::new(w, h, c, r).unwrap();
            for cam in cameras(&model, grid.aspect()) {
                let (tiles, pairs) = check_sort(&model, &cam, &grid);
                assert!(tiles > 0 && pairs > 0, "{rel}: nothing on screen");
            }
        }
    }
}

#[test]
fn colours_and_normals_travel_with_their_vertices() {
    for rel in ["classic/teapot.obj", "classic/beetle.obj", "degenerate/fused_vertices.obj"] {
        let mesh = codec::load_path(&testkit::shared_meshes().join(rel)).unwrap();
        for alpha in [false, true] {
            let model = model_of(&testkit::paint(mesh.clone(), alpha, 5));
            assert!(!model.decoded.attributes.colors.is_empty() && !model.decoded.attributes.normals.is_empty());
            for (w, h, c, r) in [(1000, 601, 7, 3), (333, 257, 16, 16)] {
                let grid = TileGrid::new(w, h, c, r).unwrap();
                for cam in cameras(&model, grid.aspect()) {
                    let (tiles, _) = check_sort(&model, &cam, &grid);
                    assert!(tiles > 1, "{rel}");
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Random holed grids (several copies at random offsets: many components) under random
    /// cameras, including ones inside the model and ones looking past it, on random grids.
    #[test]
    fn random_meshes_and_cameras_sort_exactly(
        w in 2usize..24, h in 2usize..24, copies in 1usize..4,
        holes in prop::collection::vec(prop::bool::weighted(0.1), 1..30),
        seed: u64,
        eye in (-2.0f32..2.0, -2.0f32..2.0, -0.5f32..3.0),
        target in (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0),
        fovy in 20.0f32..120.0, near in 0.01f32..0.5,
        size in (1u32..700, 1u32..500), tiles in (1u32..65, 1u32..65),
    ) {
        let model = model_of(&testkit::holed_grids(w, h, copies, &holes, seed));
        let cam = Camera { eye: eye.into(), target: target.into(), up: Vec3::Y, fovy, near, far: near + 10.0, shift: [0.0; 2] };
        prop_assume!(cam.validate().is_ok());
        let (tw, th) = (tiles.0.min(size.0), tiles.1.min(size.1));
        let grid = TileGrid::new(size.0, size.1, tw, th).unwrap();
        check_sort(&model, &cam, &grid);
    }
}
