//! The headless tile renderer on real meshes: coverage, tiles equal to crops of the full
//! frame, empty and off-screen meshes. Needs a wgpu adapter; without a GPU that is Mesa's
//! lavapipe (scripts/setup.sh installs it).
//!
//! `cargo test -p tessera-worker --release --test render -- --ignored --nocapture` times
//! the dragon at 1920x1080, whole and in 8x8 tiles.

use std::time::Instant;

use codec::bft;
use codec::view::{Camera, TileGrid};
use glam::{Mat4, Vec3};
use worker::gpu::Gpu;
use worker::render::{Draw, RenderError, RenderTimes, Renderer};
use worker::RenderMesh;

/// Loads a shared mesh the way a worker gets it: through a BFT encode and decode.
fn load(rel: &str) -> RenderMesh {
    let mesh = testkit::load_mesh(rel);
    let enc = bft::encode(&mesh, bft::EncodeOptions::default()).unwrap();
    RenderMesh::from_decoded(bft::decode(&enc.bytes).unwrap())
}

/// The default camera of the codec's conventions, framing the mesh's bounding box.
fn framing(mesh: &RenderMesh, (w, h): (u32, u32)) -> Mat4 {
    let (lo, hi) = mesh
        .positions
        .iter()
        .fold((Vec3::MAX, Vec3::MIN), |(lo, hi), &p| (lo.min(Vec3::from(p)), hi.max(Vec3::from(p))));
    let aspect = w as f32 / h as f32;
    Camera::framing(lo.to_array(), hi.to_array(), aspect).view_proj(aspect)
}

fn renderer() -> Renderer {
    let gpu = Gpu::new().unwrap_or_else(|e| panic!("{e}"));
    eprintln!("adapter: {}", gpu.adapter_name());
    Renderer::new(&gpu).unwrap_or_else(|e| panic!("{e}"))
}

fn alphas(pixels: &[u8]) -> impl Iterator<Item = u8> + '_ {
    pixels.chunks_exact(4).map(|p| p[3])
}

/// Renders every tile of `grid` and pastes it into a frame-sized image.
fn stitched(r: &mut Renderer, mesh: &RenderMesh, view_proj: Mat4, grid: &TileGrid) -> Vec<u8> {
    let (w, h) = (grid.width, grid.height);
    let mut image = vec![0u8; (w * h * 4) as usize];
    for t in 0..grid.tiles() {
        let rect @ [x0, y0, x1, y1] = grid.tile_rect(t);
        let (tile, _) = r.render(mesh, view_proj, (w, h), rect).unwrap();
        assert_eq!(tile.len(), ((x1 - x0) * (y1 - y0) * 4) as usize);
        let row = ((x1 - x0) * 4) as usize;
        for (y, src) in (y0..y1).zip(tile.chunks_exact(row)) {
            let at = ((y * w + x0) * 4) as usize;
            image[at..at + row].copy_from_slice(src);
        }
    }
    image
}

/// Differing pixels and the largest channel difference between two images.
fn mismatch(a: &[u8], b: &[u8]) -> (usize, u8) {
    let pixels = a.chunks_exact(4).zip(b.chunks_exact(4)).filter(|(p, q)| p != q).count();
    let channel = a.iter().zip(b).map(|(&p, &q)| p.abs_diff(q)).max().unwrap_or(0);
    (pixels, channel)
}

#[test]
fn full_frame_covers_the_middle_and_leaves_the_corners_clear() {
    let mesh = load("odedstein/spot_low_resolution.obj");
    let (w, h) = (160, 120);
    let mut r = renderer();
    let (pixels, _) = r.render(&mesh, framing(&mesh, (w, h)), (w, h), [0, 0, w, h]).unwrap();
    assert_eq!(pixels.len(), (w * h * 4) as usize);
    assert!(alphas(&pixels).all(|a| a == 0 || a == 255), "alpha must be 0 or 255");
    let covered = alphas(&pixels).filter(|&a| a == 255).count();
    assert!(covered > (w * h / 20) as usize, "only {covered} pixels covered");
    for (x, y) in [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)] {
        assert_eq!(&pixels[((y * w + x) * 4) as usize..][..4], &[0, 0, 0, 0], "corner ({x}, {y})");
    }
    // Lit: the headlight makes surfaces facing the camera brighter than the ambient floor.
    let brightest = pixels.chunks_exact(4).map(|p| p[0]).max().unwrap();
    assert!(brightest > 150, "brightest red {brightest}");
}

#[test]
fn tiles_are_exact_crops_of_the_full_frame() {
    let mesh = load("odedstein/spot_low_resolution.obj");
    let (w, h) = (203, 117);
    let view_proj = framing(&mesh, (w, h));
    let mut r = renderer();
    let (full, _) = r.render(&mesh, view_proj, (w, h), [0, 0, w, h]).unwrap();
    for (cols, rows) in [(3, 2), (7, 5)] {
        let grid = TileGrid::new(w, h, cols, rows).unwrap();
        let image = stitched(&mut r, &mesh, view_proj, &grid);
        let (pixels, channel) = mismatch(&full, &image);
        assert!(pixels == 0, "{cols}x{rows} tiles: {pixels} pixels differ, by up to {channel}");
    }
}

#[test]
fn off_screen_and_empty_meshes_render_transparent() {
    let spot = load("odedstein/spot_low_resolution.obj");
    let (w, h) = (64, 48);
    let view_proj = framing(&spot, (w, h));
    let mut off_screen = spot.clone();
    for p in &mut off_screen.positions {
        p[0] += 1000.0;
    }
    let mut r = renderer();
    // Drawn first so that anything the later tiles fail to clear would show.
    let (pixels, _) = r.render(&spot, view_proj, (w, h), [0, 0, w, h]).unwrap();
    assert!(alphas(&pixels).any(|a| a == 255));
    for (name, mesh) in [("off-screen", &off_screen), ("empty", &RenderMesh::default())] {
        for rect in [[0, 0, w, h], [10, 5, 30, 40]] {
            let (pixels, _) = r.render(mesh, view_proj, (w, h), rect).unwrap();
            assert_eq!(pixels.len(), ((rect[2] - rect[0]) * (rect[3] - rect[1]) * 4) as usize);
            assert!(pixels.iter().all(|&b| b == 0), "{name} mesh, rect {rect:?}");
        }
    }
}

#[test]
fn bad_rects_and_meshes_are_errors() {
    let mut r = renderer();
    let mesh = RenderMesh::default();
    for rect in [[0, 0, 0, 10], [5, 0, 4, 10], [0, 0, 11, 10], [0, 3, 10, 11]] {
        let e = r.render(&mesh, Mat4::IDENTITY, (10, 10), rect).unwrap_err();
        assert!(matches!(e, RenderError::BadRect { .. }), "{rect:?}: {e}");
    }
    let bad = RenderMesh { positions: vec![[0.0; 3]; 3], normals: vec![], colors: vec![], indices: vec![0, 1, 2] };
    let e = r.render(&bad, Mat4::IDENTITY, (10, 10), [0, 0, 10, 10]).unwrap_err();
    assert!(matches!(e, RenderError::NormalCount { .. }), "{e}");
}

fn print_times(what: &str, times: &[RenderTimes], wall_ms: f64) {
    let sum = |f: fn(&RenderTimes) -> f64| times.iter().map(f).sum::<f64>();
    println!(
        "{what}: upload {:.1} ms, render {:.1} ms, readback {:.1} ms (sum over {} calls; wall {:.1} ms)",
        sum(|t| t.upload_ms),
        sum(|t| t.render_ms),
        sum(|t| t.readback_ms),
        times.len(),
        wall_ms
    );
}

#[test]
#[ignore = "timing: run with --release -- --ignored --nocapture"]
fn dragon_1080p_timing() {
    let start = Instant::now();
    let mesh = load("stanford/dragon_vrip.ply.gz");
    println!(
        "dragon: {} triangles, {} vertices, loaded and BFT round-tripped in {:.0} ms",
        mesh.triangle_count(),
        mesh.positions.len(),
        start.elapsed().as_secs_f64() * 1e3
    );
    let (w, h) = (1920, 1080);
    let view_proj = framing(&mesh, (w, h));
    let mut r = renderer();
    // The first call allocates the buffers and target and compiles the pipeline's shaders.
    let (warm_up, _) = r.render(&mesh, view_proj, (w, h), [0, 0, w, h]).unwrap();
    let covered = alphas(&warm_up).filter(|&a| a == 255).count();
    println!("full frame covers {covered} pixels");
    for run in 0..3 {
        let start = Instant::now();
        let (_, times) = r.render(&mesh, view_proj, (w, h), [0, 0, w, h]).unwrap();
        print_times(&format!("full frame, run {run}"), &[times], start.elapsed().as_secs_f64() * 1e3);
    }
    let grid = TileGrid::new(w, h, 8, 8).unwrap();
    for run in 0..2 {
        let start = Instant::now();
        let times: Vec<RenderTimes> =
            (0..grid.tiles()).map(|t| r.render(&mesh, view_proj, (w, h), grid.tile_rect(t)).unwrap().1).collect();
        print_times(&format!("8x8 tiles (full mesh each), run {run}"), &times, start.elapsed().as_secs_f64() * 1e3);
    }
    // The tile size repeats, so the steady state is one tile re-rendered: what a worker does.
    let tile = grid.tile_rect(27);
    for run in 0..3 {
        let start = Instant::now();
        let (_, times) = r.render(&mesh, view_proj, (w, h), tile).unwrap();
        print_times(&format!("one 240x135 tile {tile:?}, run {run}"), &[times], start.elapsed().as_secs_f64() * 1e3);
    }
}

/// The triangles `range` of `mesh` as a mesh of their own (their vertices renumbered).
fn part(mesh: &RenderMesh, range: std::ops::Range<usize>) -> RenderMesh {
    let mut out = RenderMesh::default();
    let mut new_of = std::collections::HashMap::new();
    for &v in &mesh.indices[range.start * 3..range.end * 3] {
        let n = *new_of.entry(v).or_insert_with(|| {
            out.positions.push(mesh.positions[v as usize]);
            out.normals.push(mesh.normals[v as usize]);
            if !mesh.colors.is_empty() {
                out.colors.push(mesh.colors[v as usize]);
            }
            out.positions.len() as u32 - 1
        });
        out.indices.push(n);
    }
    out
}

/// A worker keeps the meshes of the streams it decoded on the device and uploads a tile's
/// new ones joined: drawn in stream order, kept and new alike, the pixels are those of all the
/// streams joined into one mesh, in any later frame too, with coloured and grey parts, and
/// where parts cover the same surface (the first drawn keeps the pixel, as in the joined
/// mesh).
#[test]
fn kept_and_new_parts_draw_as_the_joined_mesh() {
    let spot = load("odedstein/spot_low_resolution.obj");
    let n = spot.triangle_count();
    let mut painted = part(&spot, n / 3..n);
    painted.colors = (0..painted.positions.len()).map(|i| [(i * 37 % 256) as u8, 90, 200, 255]).collect();
    let (first, overlap) = (part(&spot, 0..n / 3), part(&spot, n / 2..n));
    let whole = RenderMesh::concat(&[&first, &painted, &overlap]);
    let (w, h) = (160, 120);
    let mut r = renderer();
    let (kept, _) = r.upload(&painted).unwrap();
    let kept = kept.expect("a mesh with triangles has buffers");
    assert!(r.upload(&RenderMesh::default()).unwrap().0.is_none(), "a mesh without triangles has none");
    let joined = RenderMesh::concat(&[&first, &overlap]);
    let (a, b) = (first.indices.len() as u32, joined.indices.len() as u32);
    let draws = [Draw::Joined(0..a), Draw::Resident(&kept), Draw::Joined(a..b)];
    let grid = TileGrid::new(w, h, 3, 2).unwrap();
    for turn in [0.0f32, 0.7] {
        let view_proj = framing(&spot, (w, h)) * Mat4::from_rotation_y(turn);
        for t in [None, Some(4)] {
            let rect = t.map_or([0, 0, w, h], |t| grid.tile_rect(t));
            let (want, _) = r.render(&whole, view_proj, (w, h), rect).unwrap();
            let (got, _) = r.render_parts(&joined, &draws, view_proj, (w, h), rect).unwrap();
            assert!(alphas(&got).any(|a| a == 255), "turn {turn}, rect {rect:?}: nothing drawn");
            let (pixels, channel) = mismatch(&want, &got);
            assert!(pixels == 0, "turn {turn}, rect {rect:?}: {pixels} pixels differ, by up to {channel}");
        }
    }
    let e = r.render_parts(&joined, &[Draw::Joined(a..b + 3)], Mat4::IDENTITY, (w, h), [0, 0, w, h]).unwrap_err();
    assert!(matches!(e, RenderError::BadDraw { .. }), "{e}");
}
