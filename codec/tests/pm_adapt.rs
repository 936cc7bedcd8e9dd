//! The view-dependent adaptation (`pm::adapt`): refining fully gives back the input, every
//! adapted mesh is valid and exactly the faces of the applied splits, adapting frame to frame
//! converges to the same mesh as adapting from the base mesh, one pass performs every split
//! the criteria ask for, and the criteria are monotone over the split tree.

use std::time::Instant;

use codec::pm::format::{decode, encode, Dpm, EncodeOptions};
use codec::pm::{build, Adapter, DpmAdapter, Levels, ProgressiveMesh, SplitTree, Viewpoint, NONE};
use codec::view::Camera;
use codec::Mesh;
use glam::Vec3;
use proptest::prelude::*;
use testkit::{shared_meshes, sorted_canonical, soup};

const MAX_PASSES: usize = 10_000;

fn load(rel: &str) -> Mesh {
    codec::load_path(&shared_meshes().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

fn input_of_fvid(pm: &ProgressiveMesh) -> Vec<u32> {
    let mut inv = vec![u32::MAX; pm.positions.len()];
    for (v, &f) in pm.fvid_of_input.iter().enumerate() {
        if f != u32::MAX {
            inv[f as usize] = v as u32;
        }
    }
    inv
}

/// Checks everything an adapted state must satisfy: the active set is the base vertices plus
/// the `v_u` of a set of applied splits closed under parents, the per-vertex state matches the
/// split tree, every face's indices are in range and equal its finest FVIDs mapped to active
/// vertices (so orientation is kept), and the faces are exactly those of the base mesh and the
/// applied splits (so no collapsed face survives and no duplicate appears that the input did
/// not have).
fn check_state(pm: &ProgressiveMesh, tree: &SplitTree, a: &Adapter) {
    let active = a.active();
    assert!(active.windows(2).all(|w| w[0] < w[1]), "active vertices not sorted");
    let is_active = |f: u32| active.binary_search(&f).is_ok();
    let applied: Vec<bool> = pm.splits.iter().map(|s| is_active(s.v_u)).collect();
    for (s, split) in pm.splits.iter().enumerate() {
        if applied[s] {
            assert!(is_active(split.v), "split {s} applied but v {} inactive", split.v);
            let p = tree.parent[s];
            assert!(p == NONE || applied[(p >> 1) as usize], "split {s} applied before its parent");
        }
    }
    let expected_active = pm.base_vertices.len() + applied.iter().filter(|&&x| x).count();
    assert_eq!(active.len(), expected_active, "active set is not base + applied v_u");
    // Per-vertex state: the node and the next split follow from the applied set.
    for (i, &f) in active.iter().enumerate() {
        let node = a.nodes()[i];
        let next = a.next_splits()[i];
        let expect_next = if node == NONE {
            tree.roots[pm.base_vertices.binary_search(&f).expect("root is a base vertex")]
        } else {
            let s = (node >> 1) as usize;
            assert!(applied[s], "vertex {f} is a child of unapplied split {s}");
            let split = &pm.splits[s];
            assert_eq!(f, if node & 1 == 0 { split.v } else { split.v_u });
            tree.children[s][(node & 1) as usize]
        };
        assert_eq!(next, expect_next, "vertex {f}: wrong next split");
        assert!(next == NONE || !applied[next as usize], "vertex {f}: next split {next} already applied");
    }
    // Faces.
    let rep = |f: u32| active[active.partition_point(|&x| x <= f) - 1];
    assert_eq!(a.faces().len(), a.finest_faces().len());
    for (k, (idx, fv)) in a.faces().iter().zip(a.finest_faces()).enumerate() {
        for c in 0..3 {
            assert!((idx[c] as usize) < active.len(), "face {k}: index out of range");
            assert_eq!(active[idx[c] as usize], rep(fv[c]), "face {k}: index is not its FVID's active vertex");
        }
    }
    let expected = pm
        .base_faces
        .iter()
        .copied()
        .chain(pm.splits.iter().zip(&applied).filter(|(_, &ap)| ap).flat_map(|(s, _)| s.faces.iter().copied()));
    assert!(
        sorted_canonical(a.finest_faces().iter().copied()) == sorted_canonical(expected),
        "faces are not those of the applied splits"
    );
}

/// Refines with the adapter, checking every pass, and compares with the input.
fn check_refine_fully(mesh: &Mesh, pm: &ProgressiveMesh) {
    let tree = SplitTree::new(pm);
    let mut a = Adapter::new(pm);
    check_state(pm, &tree, &a);
    let inv = input_of_fvid(pm);
    // Pass by pass: every pass is checked.
    let mut passes = 0;
    loop {
        let before = a.next_splits().iter().filter(|&&s| s != NONE).count();
        let st = a.refine_step();
        assert_eq!(st.splits, before, "a refine step splits every vertex that can");
        check_state(pm, &tree, &a);
        if st.splits == 0 {
            break;
        }
        passes += 1;
        assert!(passes < MAX_PASSES);
    }
    let mut b = Adapter::new(pm);
    b.refine_fully();
    assert!(a.active() == b.active());
    for x in [&a, &b] {
        assert_eq!(x.active().len(), pm.positions.len());
        let back = x.face_fvids().into_iter().map(|t| t.map(|f| inv[f as usize]));
        assert!(
            sorted_canonical(back) == sorted_canonical(mesh.triangles.iter().copied()),
            "fully refined faces differ from the input"
        );
    }
}

fn bbox(pm: &ProgressiveMesh) -> ([f32; 3], [f32; 3]) {
    codec::mesh::bounding_box(&pm.positions).unwrap_or(([0.0; 3], [1.0; 3]))
}

/// A view from which everything that is not back-facing needs splitting when `error_px` is 0.
fn far_view(pm: &ProgressiveMesh) -> Viewpoint {
    let (lo, hi) = bbox(pm);
    Viewpoint::new(&Camera::framing(lo, hi, 1.0), 64, 64, 0.0)
}

/// Frame `k` of a camera path around the mesh: an orbit that zooms in (some frames see only
/// part of the model, some parts leave the frustum) and out again.
fn path_view(pm: &ProgressiveMesh, k: usize, frames: usize, error_px: f32) -> Viewpoint {
    let (lo, hi) = bbox(pm);
    let (w, h) = (640u32, 480u32);
    let base = Camera::framing(lo, hi, w as f32 / h as f32);
    let t = k as f32 / frames as f32;
    let angle = t * std::f32::consts::TAU * 0.75;
    let zoom = 1.0 - 0.8 * (t * std::f32::consts::PI).sin();
    let offset = (base.eye - base.target) * zoom;
    let rot = glam::Quat::from_rotation_y(angle) * glam::Quat::from_rotation_x(0.4 * (3.0 * t).sin());
    let size = (Vec3::from(hi) - Vec3::from(lo)).length().max(1e-3);
    let target = base.target + Vec3::new(0.2 * size * (5.0 * t).sin(), 0.0, 0.0);
    let cam = Camera { eye: target + rot * offset, target, near: base.near * zoom * 0.1, far: base.far * 2.0, ..base };
    let mut v = Viewpoint::new(&cam, w, h, error_px);
    v.attribute_scale = 0.05 * size;
    v
}

/// Checks that one pass splits every active vertex the criteria ask to split.
fn pass_checked(pm: &ProgressiveMesh, a: &mut Adapter, view: &Viewpoint) -> codec::pm::PassStats {
    let wanted: Vec<u32> = a
        .next_splits()
        .iter()
        .filter(|&&s| s != NONE && view.needs_split(pm, s as usize))
        .map(|&s| pm.splits[s as usize].v_u)
        .collect();
    let st = a.adapt(view);
    assert_eq!(st.splits, wanted.len(), "a pass must perform every wanted split");
    for u in wanted {
        assert!(a.active().binary_search(&u).is_ok(), "wanted split to {u} not performed in the pass");
    }
    st
}

/// Passes until converged, each checked.
fn converge(pm: &ProgressiveMesh, tree: &SplitTree, a: &mut Adapter, view: &Viewpoint) -> usize {
    for passes in 0..MAX_PASSES {
        let st = pass_checked(pm, a, view);
        check_state(pm, tree, a);
        if st.converged() {
            return passes;
        }
    }
    panic!("no convergence in {MAX_PASSES} passes");
}

/// A converged state is the fixpoint: no active vertex asks to split, every collapsible pair's
/// collapse is asked to stay split, and a further pass changes nothing.
fn check_converged(pm: &ProgressiveMesh, a: &mut Adapter, view: &Viewpoint) {
    let active = a.active().to_vec();
    for (i, &s) in a.next_splits().iter().enumerate() {
        assert!(s == NONE || !view.needs_split(pm, s as usize), "vertex {} still wants split {s}", active[i]);
    }
    let nodes = a.nodes();
    let target = |node: u32| if node != NONE && node & 1 == 1 { pm.splits[(node >> 1) as usize].v } else { NONE };
    for (i, &node) in nodes.iter().enumerate() {
        // A right child whose sibling and itself are leaves of the cut could collapse; the view
        // must still ask for that split.
        let t = target(node);
        if t != NONE && active[i - 1] == t && (i + 1 == active.len() || target(nodes[i + 1]) != active[i]) {
            assert!(view.needs_split(pm, (node >> 1) as usize), "pair {} {} could collapse", active[i - 1], active[i]);
        }
    }
    let faces = sorted_canonical(a.face_fvids());
    let st = a.adapt(view);
    assert!(st.converged());
    assert!(a.active() == &active[..]);
    assert!(sorted_canonical(a.face_fvids()) == faces);
}

/// Adapts frame to frame along a camera path and from the base mesh for every frame; both
/// must converge to the same mesh. Returns (min, max) faces seen.
fn check_path(pm: &ProgressiveMesh, frames: usize, error_px: f32) -> (usize, usize) {
    let tree = SplitTree::new(pm);
    let mut a = Adapter::new(pm);
    let (mut lo, mut hi) = (usize::MAX, 0);
    for k in 0..frames {
        let view = path_view(pm, k, frames, error_px);
        converge(pm, &tree, &mut a, &view);
        check_converged(pm, &mut a, &view);
        let mut b = Adapter::new(pm);
        converge(pm, &tree, &mut b, &view);
        assert!(a.active() == b.active(), "frame {k}: frame-to-frame and from-base active sets differ");
        assert!(sorted_canonical(a.face_fvids()) == sorted_canonical(b.face_fvids()), "frame {k}: faces differ");
        lo = lo.min(a.faces().len());
        hi = hi.max(a.faces().len());
    }
    (lo, hi)
}

/// Passes of every level ([`Levels::All`]) along the camera path: with an unbounded descent
/// budget each frame's first pass reaches a valid state that a second pass leaves as it is;
/// with a budget of 3 splits a vertex, every pass reaches a valid state and the passes
/// converge; either way the state is the one the paper's one-level passes converge to, frame
/// to frame and from the base mesh. Returns the splits and collapses the passes did.
fn check_all_levels(pm: &ProgressiveMesh, frames: usize, error_px: f32) -> (usize, usize) {
    let tree = SplitTree::new(pm);
    let mut one = Adapter::new(pm);
    let (mut splits, mut collapses) = (0, 0);
    let mut adapters = [u32::MAX, 3].map(|budget| {
        let mut a = Adapter::new(pm).with_levels(Levels::All);
        a.set_descent_budget(budget);
        (budget, a)
    });
    for k in 0..frames {
        let view = path_view(pm, k, frames, error_px);
        converge(pm, &tree, &mut one, &view);
        for (budget, all) in &mut adapters {
            for pass in 0.. {
                let st = all.adapt(&view);
                check_state(pm, &tree, all);
                assert_eq!((st.vertices, st.faces), (all.active().len(), all.faces().len()));
                splits += st.splits;
                collapses += st.collapses;
                if st.converged() || *budget == u32::MAX {
                    break;
                }
                assert!(pass < MAX_PASSES, "frame {k}: no convergence with a budget of {budget}");
            }
            check_converged(pm, all, &view);
            assert!(all.active() == one.active(), "frame {k}, budget {budget}: the all-levels passes differ");
            assert!(sorted_canonical(all.face_fvids()) == sorted_canonical(one.face_fvids()), "frame {k}: faces");
        }
        let mut fresh = Adapter::new(pm).with_levels(Levels::All);
        fresh.set_descent_budget(u32::MAX);
        fresh.adapt(&view);
        assert!(fresh.active() == one.active(), "frame {k}: from the base mesh, the all-levels pass differs");
    }
    (splits, collapses)
}

/// Criteria are monotone: a split's values are at least its children's.
fn check_monotone(pm: &ProgressiveMesh) {
    let tree = SplitTree::new(pm);
    assert_eq!(pm.criteria.len(), pm.splits.len());
    assert_eq!(pm.normals.len(), pm.positions.len());
    for (s, c) in pm.criteria.iter().enumerate() {
        assert!((0.0..=1.0).contains(&c.sin_alpha) && c.geometric_error >= 0.0 && c.attribute_error >= 0.0);
        // The geometric error bounds the region (it is the farthest finest vertex, raised to
        // the neighbours' errors); the radius is the same bound with a slack of 1e-5 a level.
        assert!(c.geometric_error >= c.radius * 0.999, "split {s}: {c:?}");
        for ch in tree.children[s] {
            if ch != NONE {
                let d = pm.criteria[ch as usize];
                assert!(d.sin_alpha <= c.sin_alpha && d.geometric_error <= c.geometric_error, "split {s}");
                assert!(d.attribute_error <= c.attribute_error && d.radius <= c.radius, "split {s}");
            }
        }
    }
}

const MESHES: [&str; 5] = [
    "odedstein/bunny_npm_lowres.obj",
    "odedstein/spot_low_resolution.obj",
    "odedstein/plane_holes.obj.gz",
    "classic/beetle.obj",
    "classic/spot.obj",
];

#[test]
fn shared_meshes_refine_fully_to_their_input() {
    for rel in MESHES {
        let rel = testkit::find_mesh(rel);
        let mesh = load(&rel);
        let pm = build(&mesh).unwrap();
        check_monotone(&pm);
        check_refine_fully(&mesh, &pm);
        eprintln!("{rel}: {} triangles, {} splits", mesh.triangles.len(), pm.splits.len());
    }
}

#[test]
fn shared_meshes_frame_to_frame_equals_from_base() {
    for rel in MESHES {
        let rel = testkit::find_mesh(rel);
        let mesh = load(&rel);
        let pm = build(&mesh).unwrap();
        let (lo, hi) = check_path(&pm, 24, 1.0);
        eprintln!("{rel}: {} triangles; adapted {lo}..{hi} faces over 24 frames", mesh.triangles.len());
        assert!(hi > 0, "{rel}: the path never shows a face");
    }
}

#[test]
fn an_all_levels_pass_reaches_what_one_level_passes_converge_to() {
    for rel in MESHES {
        let rel = testkit::find_mesh(rel);
        let pm = build(&load(&rel)).unwrap();
        let (splits, collapses) = check_all_levels(&pm, 24, 1.0);
        eprintln!("{rel}: {splits} splits and {collapses} collapses in the all-levels passes");
        assert!(splits > 0 && collapses > 0, "{rel}: the path must both refine and coarsen");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn random_soups_adapt_in_one_all_levels_pass(mesh in soup(), error_px in 0.5f32..40.0) {
        let pm = build(&mesh).unwrap();
        check_all_levels(&pm, 12, error_px);
    }

    #[test]
    fn random_soups_adapt_consistently(mesh in soup(), error_px in 0.5f32..40.0) {
        let pm = build(&mesh).unwrap();
        check_monotone(&pm);
        check_refine_fully(&mesh, &pm);
        check_path(&pm, 20, error_px);
    }
}

#[test]
fn base_mesh_and_refine_fully_on_a_tetrahedron() {
    let mesh = Mesh {
        positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        triangles: vec![[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]],
        ..Default::default()
    };
    let pm = build(&mesh).unwrap();
    let mut a = Adapter::new(&pm);
    assert_eq!(a.active(), &pm.base_vertices[..]);
    assert!(a.faces().is_empty());
    a.refine_fully();
    assert_eq!(a.faces().len(), 4);
    // Coarsening everything (a view far behind) goes back to the base mesh.
    let mut far = far_view(&pm);
    far.error_px = f32::INFINITY;
    let passes = a.adapt_until_converged(&far, 100).expect("converges");
    assert!(passes >= 1);
    assert_eq!(a.active(), &pm.base_vertices[..]);
    assert!(a.faces().is_empty());
}

/// The speed figure: `cargo test -p tessera-codec --release --test pm_adapt -- --ignored --nocapture`.
#[test]
#[ignore = "adapts the 70k-triangle bunny along a path; run in release"]
fn bunny_adaptation_speed() {
    let mesh = load("stanford/bunny_zipper_c3d.obj.gz");
    let start = Instant::now();
    let pm = build(&mesh).unwrap();
    eprintln!("bunny: {} tris, build {:.3}s", mesh.triangles.len(), start.elapsed().as_secs_f64());
    let mut a = Adapter::new(&pm);
    let start = Instant::now();
    let passes = a.refine_fully();
    let secs = start.elapsed().as_secs_f64();
    eprintln!(
        "refine_fully: {} splits in {passes} passes, {:.1} ms = {:.2} M splits/s, {:.2} M faces/s",
        pm.splits.len(),
        secs * 1e3,
        pm.splits.len() as f64 / secs / 1e6,
        a.faces().len() as f64 / secs / 1e6
    );
    let frames = 120;
    for error_px in [0.5f32, 1.0, 4.0] {
        let mut a = Adapter::new(&pm);
        let (mut passes, mut ops, mut faces) = (0usize, 0usize, 0usize);
        let start = Instant::now();
        for k in 0..frames {
            // One pass per frame, as a renderer would do it.
            let st = a.adapt(&path_view(&pm, k, frames, error_px));
            passes += 1;
            ops += st.splits + st.collapses;
            faces += st.faces;
        }
        let secs = start.elapsed().as_secs_f64();
        eprintln!(
            "error {error_px} px: {frames} frames (1 pass each) in {:.1} ms = {:.3} ms/pass, {} ops ({:.2} M ops/s), avg {} faces",
            secs * 1e3,
            secs * 1e3 / passes as f64,
            ops,
            ops as f64 / secs / 1e6,
            faces / frames
        );
        let tree = SplitTree::new(&pm);
        let view = path_view(&pm, frames / 2, frames, error_px);
        let start = Instant::now();
        let mut b = Adapter::new(&pm);
        let p = b.adapt_until_converged(&view, MAX_PASSES).unwrap();
        eprintln!(
            "error {error_px} px: from base to converged at the mid frame: {p} passes, {:.1} ms, {} faces",
            start.elapsed().as_secs_f64() * 1e3,
            b.faces().len()
        );
        check_state(&pm, &tree, &b);
    }
}

/// Why converging after a turn costs many passes (issue 16's adaptation target):
/// `cargo test -p tessera-codec --release --test pm_adapt -- --ignored --nocapture orbit_steps`.
/// The dragon at 1920x1080 and 0.5 px on a 16-frame orbit (22.5 degrees a frame), converged
/// every frame by the CPU reference in one-level passes (the paper's, which the GPU adapter
/// passes in lockstep with) and in all-levels passes ([`Levels::All`]): per frame the passes,
/// the splits and collapses of each, and the time of the passes against one pass over the
/// converged view, which changes nothing. All-levels frames take one changing pass and land
/// on the one-level state.
#[test]
#[ignore = "adapts the 871k-triangle dragon along an orbit; run in release"]
fn orbit_steps_converge_in_passes_of_shrinking_change() {
    let mesh = load("stanford/dragon_vrip.ply.gz");
    let pm = build(&mesh).unwrap();
    let (lo, hi) = bbox(&pm);
    let cam = Camera::framing(lo, hi, 1920.0 / 1080.0);
    let mut one = Adapter::new(&pm);
    let mut all = Adapter::new(&pm).with_levels(Levels::All);
    let frames = 16;
    let mut ratios = [vec![], vec![]];
    for k in 0..frames {
        let rot = glam::Quat::from_axis_angle(cam.up.normalize(), std::f32::consts::TAU * k as f32 / frames as f32);
        let view = Viewpoint::new(&Camera { eye: cam.target + rot * (cam.eye - cam.target), ..cam }, 1920, 1080, 0.5);
        for (m, a) in [&mut one, &mut all].into_iter().enumerate() {
            let start = Instant::now();
            let mut steps = vec![];
            loop {
                let st = a.adapt(&view);
                if st.converged() {
                    break;
                }
                steps.push((st.splits, st.collapses));
                assert!(steps.len() < MAX_PASSES, "frame {k}: not converged in {MAX_PASSES} passes");
            }
            let ms = start.elapsed().as_secs_f64() * 1e3;
            let start = Instant::now();
            assert!(a.adapt(&view).converged());
            let still = start.elapsed().as_secs_f64() * 1e3;
            let changes: usize = steps.iter().map(|(s, c)| s + c).sum();
            eprintln!(
                "frame {k} {:?}: {} passes that change (+1 that does not), {ms:.0} ms = {:.1}x a converged pass \
                 ({still:.1} ms), {changes} splits and collapses for {} vertices; per pass {steps:?}",
                a_levels(m),
                steps.len(),
                ms / still,
                a.active().len()
            );
            if k > 0 {
                ratios[m].push(ms / still);
            }
            if m == 1 && k > 0 {
                assert!(steps.len() <= 1, "frame {k}: an all-levels frame took {} changing passes", steps.len());
            }
        }
        assert!(one.active() == all.active(), "frame {k}: the two kinds of pass differ");
    }
    for (m, r) in ratios.iter_mut().enumerate() {
        r.sort_by(f64::total_cmp);
        eprintln!(
            "{:?}: frame / converged pass: median {:.1}x, max {:.1}x",
            a_levels(m),
            r[r.len() / 2],
            r[r.len() - 1]
        );
    }
}

fn a_levels(m: usize) -> Levels {
    [Levels::One, Levels::All][m]
}

/// A tile's view is the sub-frustum through the tile: the whole screen gives the same planes,
/// and points projecting into a tile are inside its frustum (and outside its neighbours').
#[test]
fn tile_views_are_the_tiles_sub_frusta() {
    let cam = Camera::framing([-1.0; 3], [1.0; 3], 1.5);
    let view = Viewpoint::new(&cam, 300, 200, 0.5);
    let whole = view.for_tile([0, 0, 300, 200]);
    for (a, b) in whole.planes().iter().zip(view.planes()) {
        assert!((*a - b).abs().max_element() < 1e-5, "{a} vs {b}");
    }
    let inside = |v: &Viewpoint, p: Vec3| v.planes().iter().all(|q| q.truncate().dot(p) + q.w >= -1e-5);
    let grid = codec::view::TileGrid::new(300, 200, 3, 2).unwrap();
    let mut hits = 0;
    for k in 0..400 {
        // Points on a plane through the target, spread over the screen.
        let (x, y) = ((k % 20) as f32 / 19.0 * 2.0 - 1.0, (k / 20) as f32 / 19.0 * 2.0 - 1.0);
        let p = cam.target + Vec3::new(1.1 * x, 0.75 * y, 0.3 * (x * y));
        let clip = view.view_proj * p.extend(1.0);
        let (px, py) = ((clip.x / clip.w + 1.0) * 0.5 * 300.0, (1.0 - clip.y / clip.w) * 0.5 * 200.0);
        for t in 0..grid.tiles() {
            let r = grid.tile_rect(t);
            let margin = 0.01; // pixels from a border: either side is fine
            let strictly_in = px > r[0] as f32 + margin
                && px < r[2] as f32 - margin
                && py > r[1] as f32 + margin
                && py < r[3] as f32 - margin;
            let strictly_out = px < r[0] as f32 - margin
                || px > r[2] as f32 + margin
                || py < r[1] as f32 - margin
                || py > r[3] as f32 + margin;
            let tile = view.for_tile(r);
            if strictly_in {
                assert!(inside(&tile, p), "point at ({px}, {py}) not in tile {t}");
                hits += 1;
            }
            if strictly_out {
                assert!(!inside(&tile, p), "point at ({px}, {py}) in tile {t}");
            }
        }
    }
    assert!(hits > 300, "{hits} points in tiles");
}

/// The adaptation from the compressed operations ([`DpmAdapter`]) against the reference over
/// the decoded mesh: after every pass of a camera path (each frame to convergence), then of a
/// full refinement, the same statistics, active vertices and triangle set.
fn check_from_compressed(mesh: &Mesh, frames: usize, error_px: f32, what: &str, levels: Levels) -> (usize, usize) {
    let pm = build(mesh).unwrap();
    let bytes = encode(&pm, EncodeOptions::default()).unwrap().bytes;
    let dpm = Dpm::parse(&bytes).unwrap();
    let decoded = decode(&bytes).unwrap().pm;
    let mut reference = Adapter::new(&decoded).with_levels(levels);
    let mut compressed = DpmAdapter::new(&dpm).unwrap().with_levels(levels);
    let (mut passes, mut collapses) = (0, 0);
    let mut compare = |r: codec::pm::PassStats, c: codec::pm::PassStats, at: &str, a: &Adapter, d: &DpmAdapter| {
        assert_eq!(r, c, "{what}, {at}: pass statistics");
        assert_eq!(a.active(), &d.active()[..], "{what}, {at}: active vertices");
        assert_eq!(sorted_canonical(a.face_fvids()), sorted_canonical(d.face_fvids()), "{what}, {at}: triangles");
        passes += 1;
        collapses += r.collapses;
    };
    for k in 0..frames {
        let view = path_view(&decoded, k, frames, error_px);
        for p in 0..64 {
            let (r, c) = (reference.adapt(&view), compressed.adapt(&view).unwrap());
            compare(r, c, &format!("frame {k}, pass {p}"), &reference, &compressed);
            if r.converged() {
                break;
            }
        }
    }
    loop {
        let (r, c) = (reference.refine_step(), compressed.refine_step().unwrap());
        compare(r, c, "full refinement", &reference, &compressed);
        if r.splits == 0 {
            break;
        }
    }
    assert_eq!(reference.active().len(), decoded.positions.len(), "{what}: fully refined");
    (passes, collapses)
}

#[test]
fn adapting_from_the_compressed_operations_equals_the_reference() {
    for rel in MESHES.iter().copied().chain(["stanford/bunny_zipper_c3d.obj.gz"]) {
        let rel = testkit::find_mesh(rel);
        let mesh = load(&rel);
        for levels in [Levels::One, Levels::All] {
            let (passes, collapses) = check_from_compressed(&mesh, 16, 1.0, &rel, levels);
            eprintln!("{rel}, {levels:?}: {passes} passes alike, {collapses} collapses among them");
            assert!(collapses > 0, "{rel}: the path never coarsens");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 60, ..ProptestConfig::default() })]

    #[test]
    fn random_soups_adapt_alike_from_the_compressed_operations(mesh in soup(), error_px in 0.5f32..40.0) {
        check_from_compressed(&mesh, 8, error_px, "a random soup", Levels::One);
        check_from_compressed(&mesh, 8, error_px, "a random soup", Levels::All);
    }
}

/// A soup (found by `random_soups_adapt_consistently`) in which a split's right child has an
/// error raised by its neighbours beyond its region, so that its sphere did not nest in its
/// parent's: the child asked for a split its parent did not, and frame-to-frame and from-base
/// adaptations differed. The builder now raises the parent's radius to nest it.
#[test]
fn a_child_sphere_raised_by_its_neighbours_nests_in_its_parent() {
    let p: Vec<[f32; 3]> = vec![
        [0.0, 3.0, 3.0],
        [3.0, 3.0, 0.0],
        [0.0, 2.0, 2.0],
        [3.0, 3.0, 3.0],
        [1.0, 2.0, 3.0],
        [0.0, 1.0, 2.0],
        [3.0, 0.0, 2.0],
        [3.0, 0.0, 1.0],
        [3.0, 2.0, 0.0],
        [0.0, 1.0, 1.0],
        [3.0, 3.0, 2.0],
        [3.0, 2.0, 0.0],
        [3.0, 3.0, 0.0],
        [3.0, 0.0, 1.0],
        [2.0, 0.0, 2.0],
        [3.0, 2.0, 0.0],
        [1.0, 2.0, 2.0],
        [2.0, 1.0, 0.0],
        [2.0, 2.0, 2.0],
    ];
    let t = vec![[12, 12, 8], [8, 11, 7], [0, 1, 8], [7, 14, 9], [8, 1, 0], [0, 0, 0], [0, 1, 7]];
    let pm = build(&Mesh::new(p, t)).unwrap();
    check_monotone(&pm);
    let tree = SplitTree::new(&pm);
    for k in 0..20 {
        let view = path_view(&pm, k, 20, 26.401794);
        for s in 0..pm.splits.len() {
            for ch in tree.children[s].into_iter().filter(|&c| c != NONE) {
                assert!(!view.needs_split(&pm, ch as usize) || view.needs_split(&pm, s), "frame {k}: split {s}");
            }
        }
    }
    check_path(&pm, 20, 26.401794);
}

/// Out of core (section 5.7): the adaptation from the resident nodes of an out-of-core file,
/// loaded by priority within a budget that holds the nodes every frame requires but not the
/// model, equals the in-core adaptation pass for pass over a camera path (an operation in a node
/// of priority below 1 is never asked for), with operations waiting for their nodes on the
/// way, and the resident bytes stay within the budget; the loader thread, waited for, gives
/// the same.
#[test]
fn out_of_core_adaptation_equals_in_core_within_a_budget() {
    use codec::pm::format::NodeFile;
    use codec::pm::NodeCache;
    use std::sync::Arc;
    let pm = build(&load("stanford/bunny_zipper_c3d.obj.gz")).unwrap();
    let incore = encode(&pm, EncodeOptions::default()).unwrap().bytes;
    let ooc = encode(&pm, EncodeOptions { node_bytes: 4096, ..EncodeOptions::default() }).unwrap().bytes;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("spot.dpm");
    std::fs::write(&path, &ooc).unwrap();
    let file = Arc::new(NodeFile::open(&path).unwrap());
    let (dpm, prefix) = (Dpm::parse(&incore).unwrap(), Dpm::parse_prefix(file.prefix()).unwrap());
    let decoded = decode(&incore).unwrap().pm;
    let (frames, error_px) = (12, 1.0);
    let total: u64 = prefix.nodes.iter().map(|n| n.len as u64).sum();
    // A close look around one part of the model: most of it is outside the frustum.
    let (lo, hi) = bbox(&decoded);
    let size = (Vec3::from(hi) - Vec3::from(lo)).length();
    let close = |k: usize| {
        let target = Vec3::from(decoded.positions[decoded.positions.len() / 3]);
        let a = k as f32 * 0.15;
        let eye = target + Vec3::new(a.cos(), 0.3, a.sin()) * 0.25 * size;
        let base = Camera::framing(lo, hi, 4.0 / 3.0);
        let cam = Camera { eye, target, near: size * 0.001, far: size * 4.0, ..base };
        Viewpoint::new(&cam, 640, 480, error_px)
    };
    let required = (0..frames)
        .map(|k| {
            let view = close(k);
            let planes = view.planes();
            prefix.nodes.iter().filter(|n| n.priority(&view, &planes) >= 1.0).map(|n| n.len as u64).sum::<u64>()
        })
        .max()
        .unwrap();
    let budget = required + 2 * 4096;
    eprintln!("budget {budget} bytes of the model's {total}");
    for (background, levels) in [(false, Levels::One), (true, Levels::One), (true, Levels::All)] {
        let mut cache = NodeCache::new(&prefix, file.clone(), budget, background);
        let (mut a, mut b) =
            (DpmAdapter::new(&dpm).unwrap().with_levels(levels), DpmAdapter::new(&prefix).unwrap().with_levels(levels));
        let mut waited = 0;
        for k in 0..frames {
            let view = close(k);
            let st = cache.schedule(&view).unwrap();
            cache.wait().unwrap();
            for p in 0..64 {
                let (r, c) = (a.adapt(&view).unwrap(), b.adapt_resident(&view, &cache).unwrap());
                let at = format!("background {background}, {levels:?}, frame {k}, pass {p}");
                assert_eq!(r, c, "{at}");
                assert_eq!(a.active(), b.active(), "{at}");
                assert_eq!(sorted_canonical(a.face_fvids()), sorted_canonical(b.face_fvids()), "{at}");
                waited = waited.max(b.pending());
                if r.converged() {
                    break;
                }
            }
            assert!(st.resident_bytes <= budget && st.required_resident <= st.required);
            let resident: u64 =
                (0..prefix.nodes.len() as u32).filter_map(|i| cache.get(i)).map(|b| b.len() as u64).sum();
            assert!(resident <= budget, "frame {k}: {resident} bytes resident, budget {budget}");
        }
        assert!(waited > 0, "no operation ever waited for its node");
    }
}
