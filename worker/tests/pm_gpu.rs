//! The GPU adaptation (worker::pm_adapt, worker/src/pm_adapt/shaders/*.wgsl) against the CPU reference
//! (codec::pm::Adapter): after every pass of a camera path, the same active vertices, the
//! same per-pass statistics and the same triangle set (as FVID triples, orientation kept).
//! Needs a wgpu adapter; without a GPU that is Mesa's lavapipe.
//! The dragon's 50 frames take about 20 s on lavapipe (with its PM build).

use std::time::Instant;

use codec::pm::format::{decode, encode, Dpm, EncodeOptions};
use codec::pm::{build, Adapter, Levels, ProgressiveMesh, Viewpoint};
use codec::view::Camera;
use glam::Vec3;
use testkit::sorted_canonical;
use worker::gpu::Gpu;
use worker::pm_adapt::{GpuAdapter, DEFAULT_N_ALLOC};
use worker::render::Renderer;

/// A device, and a lock that runs this file's GPU tests one at a time: on lavapipe each
/// device compiles and runs on every core, and six at once took 529 s in CI against about
/// 60 s in turn.
fn device() -> (std::sync::MutexGuard<'static, ()>, Gpu) {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    (guard, Gpu::new().unwrap_or_else(|e| panic!("{e}")))
}

/// The `.dpm` of a mesh and the progressive mesh it decodes to (the CPU reference's input:
/// the GPU adapts from the compressed operations).
fn dpm_of(rel: &str) -> (Vec<u8>, ProgressiveMesh) {
    dpm_with(rel, EncodeOptions::default())
}

/// [`dpm_of`] with other encoding options.
fn dpm_with(rel: &str, options: EncodeOptions) -> (Vec<u8>, ProgressiveMesh) {
    let pm = build(&testkit::load_mesh(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"));
    let bytes = encode(&pm, options).unwrap().bytes;
    let pm = decode(&bytes).unwrap().pm;
    (bytes, pm)
}

fn bbox(pm: &ProgressiveMesh) -> (Vec3, Vec3) {
    let (lo, hi) = codec::mesh::bounding_box(&pm.positions).expect("a mesh with vertices");
    (Vec3::from(lo), Vec3::from(hi))
}

/// Frame `k` of `frames` of a path that orbits, zooms in until parts of the model leave the
/// frustum, pans, and zooms out again, at 1920x1080 with normal error counted.
fn path_view(pm: &ProgressiveMesh, k: usize, frames: usize, error_px: f32) -> Viewpoint {
    let (lo, hi) = bbox(pm);
    let (w, h) = (1920u32, 1080u32);
    let base = Camera::framing(lo.to_array(), hi.to_array(), w as f32 / h as f32);
    let t = k as f32 / frames as f32;
    let zoom = 1.0 - 0.8 * (t * std::f32::consts::PI).sin();
    let rot = glam::Quat::from_rotation_y(t * std::f32::consts::TAU * 0.75)
        * glam::Quat::from_rotation_x(0.4 * (3.0 * t).sin());
    let size = (hi - lo).length().max(1e-3);
    let target = base.target + Vec3::new(0.2 * size * (5.0 * t).sin(), 0.0, 0.0);
    let cam = Camera {
        eye: target + rot * ((base.eye - base.target) * zoom),
        target,
        near: base.near * zoom * 0.1,
        far: base.far * 2.0,
        ..base
    };
    let mut v = Viewpoint::new(&cam, w, h, error_px);
    v.attribute_scale = 0.05 * size;
    v
}

/// One pass on both, then everything compared.
fn pass_both(pm: &ProgressiveMesh, cpu: &mut Adapter, gpu: &mut GpuAdapter, view: Option<&Viewpoint>, what: &str) {
    let (c, g) = match view {
        Some(v) => (cpu.adapt(v), gpu.adapt(v).unwrap()),
        None => (cpu.refine_step(), gpu.refine_step().unwrap()),
    };
    gpu.check().unwrap();
    assert_eq!(c, g, "{what}: pass statistics differ");
    assert_eq!(gpu.active().unwrap(), cpu.active(), "{what}: active vertices differ");
    let gf = sorted_canonical(gpu.face_fvids().unwrap());
    let cf = sorted_canonical(cpu.face_fvids());
    if gf != cf {
        let only_gpu = gf.iter().filter(|t| cf.binary_search(t).is_err()).count();
        let only_cpu = cf.iter().filter(|t| gf.binary_search(t).is_err()).count();
        panic!("{what}: triangle sets differ ({only_gpu} only on the GPU, {only_cpu} only on the CPU)");
    }
    assert!(pm.positions.len() >= cpu.active().len());
}

/// Adapts along a path of `frames` frames, one pass per frame, on both, with passes of one
/// level or of all.
/// Returns the most descents a pass ran and the stack's slots at the end.
fn check_path(rel: &str, frames: usize, error_px: f32, device: &Gpu, levels: Levels) -> (u32, u32) {
    check_path_with(rel, frames, error_px, device, levels, |_| {})
}

/// [`check_path`] with the GPU adapter set up further by `setup`.
fn check_path_with(
    rel: &str,
    frames: usize,
    error_px: f32,
    device: &Gpu,
    levels: Levels,
    setup: impl Fn(&mut GpuAdapter),
) -> (u32, u32) {
    let (bytes, pm) = dpm_of(rel);
    let dpm = Dpm::parse(&bytes).unwrap();
    let mut cpu = Adapter::new(&pm).with_levels(levels);
    let mut gpu = GpuAdapter::new(device, &dpm, 4096).unwrap();
    gpu.set_levels(levels);
    setup(&mut gpu);
    cpu.set_descent_budget(gpu.descent_budget());
    let start = Instant::now();
    let (mut lo, mut hi) = (usize::MAX, 0);
    let mut most = 0;
    for k in 0..frames {
        let view = path_view(&pm, k, frames, error_px);
        pass_both(&pm, &mut cpu, &mut gpu, Some(&view), &format!("{rel} {levels:?} frame {k}"));
        most = most.max(gpu.last_descents().0);
        lo = lo.min(cpu.faces().len());
        hi = hi.max(cpu.faces().len());
    }
    eprintln!(
        "{rel} {levels:?}: {frames} frames equal, {lo}..{hi} faces, {} reallocations, {:.1}s",
        gpu.reallocations(),
        start.elapsed().as_secs_f64()
    );
    assert!(hi > lo, "{rel}: the path never changes the mesh");
    (most, gpu.last_descents().1)
}

#[test]
fn bunny_path_matches_the_cpu_reference() {
    let (_one_at_a_time, device) = device();
    for levels in [Levels::One, Levels::All] {
        check_path("stanford/bunny_zipper_c3d.obj.gz", 60, 0.5, &device, levels);
    }
}

/// More descents in a pass than the stacks hold: the slots take them from the queue in
/// turn, and the passes stay those of the CPU reference.
#[test]
fn descents_beyond_the_stacks_run_in_several_dispatches() {
    let (_one_at_a_time, device) = device();
    // 48 slots of 32 entries of 24 words and a resume record of 12 vectors.
    let slot = 32 * 96 + 12 * 16;
    let (most, slots) = check_path_with("stanford/bunny_zipper_c3d.obj.gz", 20, 0.5, &device, Levels::All, |g| {
        g.set_stack_limit(48 * slot)
    });
    assert_eq!(slots, 48);
    assert!(most > 3 * slots, "at most {most} descents a pass: one dispatch held them");
}

/// Descents that never pause (one dispatch each, however long): on lavapipe, whose compiler
/// (llvmpipe) ends an invocation's loops after 65535 iterations in all, the dragon's long
/// descents from its base mesh are cut short, and the pass fails with the loop limit in one
/// line, never silently wrong; on a GPU without the limit it equals the CPU reference's.
#[test]
fn a_descent_the_gpu_cuts_short_fails_the_pass() {
    let (_one_at_a_time, device) = device();
    let (bytes, pm) = dpm_of("stanford/dragon_vrip.ply.gz");
    let dpm = Dpm::parse(&bytes).unwrap();
    let mut cpu = Adapter::new(&pm).with_levels(Levels::All);
    let mut gpu = GpuAdapter::new(&device, &dpm, DEFAULT_N_ALLOC).unwrap();
    gpu.set_levels(Levels::All);
    gpu.set_descent_budget(1 << 12);
    gpu.set_round_steps(u32::MAX);
    cpu.set_descent_budget(1 << 12);
    let view = path_view(&pm, 0, 1, 0.5);
    match gpu.adapt(&view) {
        Ok(g) => {
            assert!(!device.is_software(), "lavapipe's loop limit went unnoticed");
            assert_eq!(cpu.adapt(&view), g, "pass statistics differ");
            assert_eq!(gpu.active().unwrap(), cpu.active(), "active vertices differ");
        }
        Err(e) => {
            assert!(matches!(e, worker::pm_adapt::AdaptError::LoopLimit { .. }), "{e}");
            let line = e.to_string();
            assert!(line.contains("loop limit") && !line.contains('\n'), "{line}");
            eprintln!("{line}");
        }
    }
}

/// Where the count's scratch area cannot hold what it finds, the pass walks its descents
/// again: with no scratch area every all-levels pass does, with 64 kB the larger ones do and
/// the others place what was kept; both stay the CPU reference's passes.
#[test]
fn descents_walk_again_where_the_scratch_is_full() {
    let (_one_at_a_time, device) = device();
    for bytes in [0, 64 << 10] {
        check_path_with("stanford/bunny_zipper_c3d.obj.gz", 20, 0.5, &device, Levels::All, |g| {
            g.set_scratch_limit(bytes)
        });
    }
}

/// A model whose split trees are far deeper than a one-level pass can follow (the planar
/// alligator: its one-level passes from the base mesh take over a thousand) converges with the
/// default kind of pass in a few dozen: after `DEEP_PASSES` one-level passes the view goes
/// back to all levels. The mesh is the CPU reference's.
#[test]
fn deep_split_trees_go_back_to_all_levels() {
    let (_one_at_a_time, device) = device();
    let (bytes, pm) = dpm_of("classic/alligator.obj");
    let dpm = Dpm::parse(&bytes).unwrap();
    let view = path_view(&pm, 0, 1, 0.5);
    let mut cpu = Adapter::new(&pm).with_levels(Levels::All);
    let mut gpu = GpuAdapter::new(&device, &dpm, DEFAULT_N_ALLOC).unwrap();
    cpu.set_descent_budget(gpu.descent_budget());
    let cpu_passes = cpu.adapt_until_converged(&view, 10_000).expect("the CPU converges");
    let passes = gpu.adapt_until_converged(&view, 10_000).unwrap().expect("the GPU converges");
    eprintln!("alligator from its base mesh: {passes} passes on the GPU, {cpu_passes} all-levels passes on the CPU");
    // The all-levels passes, and the one-level ones before the switch back (32).
    assert!(passes <= cpu_passes + 40, "{passes} passes");
    assert_eq!(gpu.active().unwrap(), cpu.active(), "active vertices differ");
    assert_eq!(sorted_canonical(gpu.face_fvids().unwrap()), sorted_canonical(cpu.face_fvids()), "faces differ");
}

/// Rounds far longer than llvmpipe's loop limit allows (4096 steps a slot before it pauses)
/// along the bunny's path: on lavapipe the count reaches the limit (the probe after every
/// step, or a decode it cut short, reports it) and the adapter halves the steps a round until
/// it does not; every pass equals the CPU reference's. On a GPU without the limit nothing is
/// halved.
#[test]
fn rounds_past_the_loop_limit_are_halved() {
    let (_one_at_a_time, device) = device();
    let (bytes, pm) = dpm_of("stanford/bunny_zipper_c3d.obj.gz");
    let dpm = Dpm::parse(&bytes).unwrap();
    let mut cpu = Adapter::new(&pm).with_levels(Levels::All);
    let mut gpu = GpuAdapter::new(&device, &dpm, DEFAULT_N_ALLOC).unwrap();
    gpu.set_levels(Levels::All);
    gpu.set_round_steps(4096);
    cpu.set_descent_budget(gpu.descent_budget());
    let frames = 20;
    for k in 0..frames {
        let view = path_view(&pm, k, frames, 0.5);
        pass_both(&pm, &mut cpu, &mut gpu, Some(&view), &format!("frame {k}"));
    }
    eprintln!("{} steps a round after the path", gpu.round_steps());
    assert_eq!(gpu.round_steps() < 4096, device.is_software(), "{} steps a round", gpu.round_steps());
}

/// Descents that pause every few steps and go on in the next dispatch (as on lavapipe, but
/// after 5 steps instead of 128) make the CPU reference's passes along the bunny's path.
#[test]
fn paused_descents_go_on_in_the_next_dispatch() {
    let (_one_at_a_time, device) = device();
    check_path_with("stanford/bunny_zipper_c3d.obj.gz", 20, 0.5, &device, Levels::All, |g| g.set_round_steps(5));
}

#[test]
fn refining_everything_on_the_gpu_matches_the_cpu() {
    let (_one_at_a_time, device) = device();
    // Small meshes with boundaries, non-manifold edges and degenerate faces; a tiny n_alloc
    // so that buffers are reallocated in most passes. Coarsened in passes of one level and of
    // all, alternately. The last with the widest quantization the format allows (24-bit
    // positions, 16-bit normals, whose codes take 17 bits), which a vertex's state packs
    // into one vector.
    for (k, rel) in [
        "classic/teapot.obj",
        "degenerate/non_manifold_face_graph.obj",
        "degenerate/fused_vertices.obj",
        "odedstein/bunny_oded_6k.obj",
    ]
    .into_iter()
    .enumerate()
    {
        let rel = if testkit::mesh_path(rel).exists() {
            rel.to_string()
        } else {
            format!("stanford/{}", rel.rsplit('/').next().unwrap())
        };
        let options = match k {
            3 => EncodeOptions { position_bits: 24, normal_bits: 16, ..EncodeOptions::default() },
            _ => EncodeOptions::default(),
        };
        let (bytes, pm) = dpm_with(&rel, options);
        let dpm = Dpm::parse(&bytes).unwrap();
        let mut cpu = Adapter::new(&pm);
        let mut gpu = GpuAdapter::new(&device, &dpm, 16).unwrap();
        let mut passes = 0;
        loop {
            pass_both(&pm, &mut cpu, &mut gpu, None, &format!("{rel} refine pass {passes}"));
            passes += 1;
            if cpu.next_splits().iter().all(|&s| s == codec::pm::NONE) {
                break;
            }
        }
        assert_eq!(cpu.active().len(), pm.positions.len(), "{rel}: not fully refined");
        // And back down: a far, coarse view collapses what the criteria allow, pass by pass.
        let (lo, hi) = bbox(&pm);
        let cam = Camera::framing(lo.to_array(), hi.to_array(), 1.0);
        let far = Camera { eye: cam.target + (cam.eye - cam.target) * 50.0, far: cam.far * 100.0, ..cam };
        let view = Viewpoint::new(&far, 64, 64, 4.0);
        let levels = [Levels::One, Levels::All][k % 2];
        cpu.set_levels(levels);
        gpu.set_levels(levels);
        cpu.set_descent_budget(gpu.descent_budget());
        for k in 0..passes + 2 {
            pass_both(&pm, &mut cpu, &mut gpu, Some(&view), &format!("{rel} {levels:?} coarsen pass {k}"));
        }
        assert!(gpu.reallocations() > 2, "{rel}: n_alloc = 16 should force reallocations");
        eprintln!("{rel}: {passes} refine passes, {} reallocations", gpu.reallocations());
    }
}

#[test]
fn dragon_path_matches_the_cpu_reference() {
    let (_one_at_a_time, device) = device();
    for levels in [Levels::One, Levels::All] {
        check_path("stanford/dragon_vrip.ply.gz", 50, 0.5, &device, levels);
    }
}

/// Median of `v` (sorted in place).
fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The performance figures of issue 6 on whatever adapter wgpu finds (lavapipe here):
/// `cargo test -p tessera-worker --release --test pm_gpu -- --ignored --nocapture pm_speed`.
/// For each view of the dragon at 1920x1080 and 0.5 px: the full original mesh's render time
/// (draw + read back; the mesh is resident, so no upload), against adapting frame to frame
/// along a slow orbit (one pass per frame, as a renderer would) plus rendering the adapted mesh
/// from the GPU buffers; generated triangles per second (faces created by splits from the base
/// mesh to the converged view, per second of adaptation); the CPU reference's time for the
/// same passes; and GPU memory per adapted vertex against the paper's (112 + 8k) bytes, k = 6.
#[test]
#[ignore = "times the dragon on the GPU; run in release"]
fn pm_speed() {
    let rel = std::env::var("TESSERA_PM_MESH").unwrap_or_else(|_| "stanford/dragon_vrip.ply.gz".into());
    let (bytes, pm) = dpm_of(&rel);
    let dpm = Dpm::parse(&bytes).unwrap();
    let (_one_at_a_time, device) = device();
    eprintln!("adapter: {}", device.adapter_name());
    let mut renderer = Renderer::new(&device).unwrap();
    let (w, h) = (1920u32, 1080u32);
    let rect = [0, 0, w, h];

    let mut full = Adapter::new(&pm);
    full.refine_fully();
    let full_faces = full.faces().len();
    let mesh = worker::RenderMesh {
        positions: full.active().iter().map(|&f| pm.positions[f as usize]).collect(),
        normals: full.active().iter().map(|&f| pm.normals[f as usize]).collect(),
        colors: Vec::new(),
        indices: full.faces().iter().flatten().copied().collect(),
    };
    let (lo, hi) = bbox(&pm);
    let base = Camera::framing(lo.to_array(), hi.to_array(), w as f32 / h as f32);
    // Views: framing the model, farther away, and close up (much of the model off screen).
    for (name, scale) in [("framing", 1.0f32), ("far", 3.0), ("farther", 5.0), ("close", 0.35)] {
        let cam_at = |k: usize| {
            let rot = glam::Quat::from_rotation_y(0.01 * k as f32);
            let eye = base.target + rot * ((base.eye - base.target) * scale);
            Camera { eye, near: base.near * scale.min(1.0) * 0.5, far: base.far * scale.max(1.0), ..base }
        };
        let vp = cam_at(0).view_proj(w as f32 / h as f32);
        let mut full_ms: Vec<f64> = (0..5)
            .map(|_| {
                let (_, t) = renderer.render(&mesh, vp, (w, h), rect).unwrap();
                t.render_ms + t.readback_ms
            })
            .collect();
        let full_ms = median(&mut full_ms);

        // From the base mesh to the converged view: generated triangles per second.
        let view0 = Viewpoint::new(&cam_at(0), w, h, 0.5);
        let mut gpu = GpuAdapter::new(&device, &dpm, DEFAULT_N_ALLOC).unwrap();
        let start = Instant::now();
        let passes = gpu.adapt_until_converged(&view0, 1000).unwrap().expect("converges");
        let gen_s = start.elapsed().as_secs_f64();
        let faces = gpu.counts().1 as usize;
        let mut cpu = Adapter::new(&pm);
        let start = Instant::now();
        cpu.adapt_until_converged(&view0, 1000).expect("converges");
        let cpu_gen_s = start.elapsed().as_secs_f64();

        // Frame to frame: one pass per frame on both, then the render.
        let (mut adapt_ms, mut draw_ms, mut cpu_ms, mut removed) = (vec![], vec![], vec![], vec![]);
        let (mut classify_ms, mut apply_ms, mut state_ms) = (vec![], vec![], vec![]);
        gpu.set_profiling(true);
        for k in 1..=20 {
            let view = Viewpoint::new(&cam_at(k), w, h, 0.5);
            let start = Instant::now();
            gpu.adapt(&view).unwrap();
            adapt_ms.push(start.elapsed().as_secs_f64() * 1e3);
            classify_ms.push(gpu.last_pass_ms()[0]);
            apply_ms.push(gpu.last_pass_ms()[1]);
            state_ms.push(gpu.last_pass_ms()[2]);
            let vp = cam_at(k).view_proj(w as f32 / h as f32);
            let (_, t) = renderer.render_pm(gpu.mesh(), vp, (w, h), rect).unwrap();
            draw_ms.push(t.render_ms + t.readback_ms);
            let start = Instant::now();
            cpu.adapt(&view);
            cpu_ms.push(start.elapsed().as_secs_f64() * 1e3);
            removed.push(1.0 - gpu.counts().1 as f64 / full_faces as f64);
        }
        let (a, d, c) = (median(&mut adapt_ms), median(&mut draw_ms), median(&mut cpu_ms));
        let (n, _) = gpu.counts();
        eprintln!(
            "{rel} {name}: {faces} of {full_faces} faces ({:.1}% removed); full render {full_ms:.1} ms; \
             adapt {a:.2} + render {d:.1} ms per frame = {:.2} x full; from base: {passes} passes, {:.2} Mtri/s \
             generated (CPU reference {:.2} Mtri/s); frame pass GPU {a:.2} ms vs CPU {c:.2} ms = {:.2} x; \
             dynamic memory {:.1} bytes per adapted vertex ({} vertices; paper 160), static {:.1} MB; \
             GPU pass = classify {:.2} (state update and collapses {:.2}) + apply {:.2} ms",
            100.0 * median(&mut removed),
            (a + d) / full_ms,
            faces as f64 / gen_s / 1e6,
            faces as f64 / cpu_gen_s / 1e6,
            a / c,
            gpu.dynamic_bytes() as f64 / n as f64,
            n,
            gpu.static_bytes() as f64 / 1e6,
            median(&mut classify_ms),
            median(&mut state_ms),
            median(&mut apply_ms),
        );
    }
}

/// The fixed cost of a pass on a small mesh (what a worker with many small tiles pays per
/// tile and pass): `cargo test -p tessera-worker --release --test pm_gpu -- --ignored --nocapture pass_overhead`.
#[test]
#[ignore = "timing; run in release"]
fn pass_overhead() {
    let (bytes, pm) = dpm_of("stanford/bunny_oded_6k.obj");
    let dpm = Dpm::parse(&bytes).unwrap();
    let (_one_at_a_time, device) = device();
    let mut gpu = GpuAdapter::new(&device, &dpm, DEFAULT_N_ALLOC).unwrap();
    let view = path_view(&pm, 0, 1, 0.5);
    gpu.adapt_until_converged(&view, 1000).unwrap().expect("converges");
    let mut idle: Vec<f64> = (0..50)
        .map(|_| {
            let start = Instant::now();
            assert!(gpu.adapt(&view).unwrap().converged());
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    let mut busy: Vec<f64> = (0..50)
        .map(|k| {
            let view = path_view(&pm, k % 2, 4, 0.5);
            let start = Instant::now();
            gpu.adapt(&view).unwrap();
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    eprintln!(
        "{} faces: a pass that changes nothing {:.2} ms, one that changes the mesh {:.2} ms (medians)",
        gpu.counts().1,
        median(&mut idle),
        median(&mut busy)
    );
}

/// Out of core: the bunny in 4 kB nodes adapted on the GPU from a pool of node slots within a
/// budget (two thirds of the nodes), against the CPU's
/// `DpmAdapter::adapt_resident` with a cache of the same slots: after every pass the same
/// statistics, active vertices and triangle set, with operations waiting for their nodes on
/// the way; the GPU keeps no more node bytes than the budget. Once with the nodes read while
/// scheduling, once by the loader thread (waited for).
#[test]
fn out_of_core_path_matches_the_cpu_reference() {
    use codec::pm::format::NodeFile;
    use codec::pm::{DpmAdapter, NodeCache};
    use std::sync::Arc;
    use worker::pm_adapt::OutOfCore;
    let (_one_at_a_time, device) = device();
    let rel = "stanford/bunny_zipper_c3d.obj.gz";
    let pm = build(&testkit::load_mesh(rel)).unwrap();
    let bytes = encode(&pm, EncodeOptions { node_bytes: 4096, ..EncodeOptions::default() }).unwrap().bytes;
    let decoded = decode(&bytes).unwrap().pm;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bunny.dpm");
    std::fs::write(&path, &bytes).unwrap();
    let file = Arc::new(NodeFile::open(&path).unwrap());
    let dpm = Dpm::parse_prefix(file.prefix()).unwrap();
    let slot = worker::pm_adapt::decoder::slot_bytes(&dpm) as u64;
    let (frames, error_px) = (24, 0.5);
    // Two thirds of the model: the path's whole views require more (then the required nodes
    // of highest priority go in first), its close views less.
    let slots = dpm.nodes.len() as u64 * 2 / 3;
    for (background, levels) in [(false, Levels::One), (true, Levels::All)] {
        let ooc = OutOfCore { file: file.clone(), pool_bytes: slots * slot, background };
        let mut gpu = GpuAdapter::out_of_core(&device, &dpm, ooc, 4096).unwrap();
        gpu.set_levels(levels);
        assert_eq!(gpu.node_slots(), Some(slots as u32));
        let mut cache = NodeCache::with_slots(&dpm, file.clone(), slots, slot, false);
        let mut cpu = DpmAdapter::new(&dpm).unwrap().with_levels(levels);
        cpu.set_descent_budget(gpu.descent_budget());
        let (mut waited, mut passes) = (0, 0);
        for k in 0..frames {
            let view = path_view(&decoded, k, frames, error_px);
            cache.schedule(&view).unwrap();
            gpu.schedule(&view).unwrap();
            gpu.wait_for_nodes().unwrap();
            for p in 0..12 {
                let what = format!("background {background}, {levels:?}, frame {k}, pass {p}");
                let (c, g) = (cpu.adapt_resident(&view, &cache).unwrap(), gpu.adapt(&view).unwrap());
                gpu.check().unwrap();
                assert_eq!(c, g, "{what}: pass statistics differ");
                assert_eq!(gpu.active().unwrap(), cpu.active(), "{what}: active vertices differ");
                assert_eq!(sorted_canonical(gpu.face_fvids().unwrap()), sorted_canonical(cpu.face_fvids()), "{what}");
                waited = waited.max(cpu.pending());
                passes += 1;
                if c.converged() {
                    break;
                }
            }
            gpu.check().unwrap();
        }
        let pool = gpu.node_pool_bytes();
        eprintln!(
            "{rel} out of core (background {background}, {levels:?}): {passes} passes equal; {slots} slots of {slot} bytes \
             ({pool} bytes of nodes on the GPU, file {}), {} bytes uploaded, up to {waited} vertices waiting",
            bytes.len(),
            gpu.uploaded_bytes()
        );
        assert!(pool <= slots * slot, "{pool} bytes of node pool for a budget of {}", slots * slot);
        assert!(waited > 0, "no operation ever waited for its node");
    }
}

/// Occlusion culling one frame late: after a frame is drawn, its depth pyramid stops the
/// refinement of vertices whose spheres it hid. On a view down the model's length (its front
/// hides much of the rest) the adapted triangles drop, and the frame drawn from the culled
/// mesh matches the unculled one for at least 99% of its covered pixels within 8/255.
fn occlusion_on(rel: &str, min_saving: f64) {
    let (bytes, pm) = dpm_of(rel);
    let dpm = Dpm::parse(&bytes).unwrap();
    let (_one_at_a_time, device) = device();
    let mut renderer = Renderer::new(&device).unwrap();
    let (w, h) = (960u32, 540u32);
    let rect = [0, 0, w, h];
    let (lo, hi) = bbox(&pm);
    let base = Camera::framing(lo.to_array(), hi.to_array(), w as f32 / h as f32);
    // Along the longest axis of the box, from outside its end.
    let ext = hi - lo;
    let axis = if ext.x >= ext.y.max(ext.z) {
        Vec3::X
    } else if ext.z >= ext.y {
        Vec3::Z
    } else {
        Vec3::Y
    };
    let center = (lo + hi) * 0.5;
    let eye = center + (axis * 1.4 + Vec3::Y * 0.3).normalize() * ext.length() * 1.1;
    let cam = Camera { eye, target: center, near: base.near * 0.1, far: base.far * 3.0, ..base };
    let vp = cam.view_proj(w as f32 / h as f32);
    let view = Viewpoint::new(&cam, w, h, 0.5);
    let mut gpu = GpuAdapter::new(&device, &dpm, DEFAULT_N_ALLOC).unwrap();
    gpu.adapt_until_converged(&view, 1000).unwrap().expect("converges");
    let all = gpu.counts().1;
    let (plain, _) = renderer.render_pm(gpu.mesh(), vp, (w, h), rect).unwrap();
    let depth = renderer.read_depth(rect).unwrap();
    assert_eq!(depth.len(), (w * h) as usize);
    assert!(depth.iter().any(|&d| d < 1.0) && depth.contains(&1.0), "the model and the background");
    gpu.set_occluder(Some(worker::pm_adapt::occlusion::Occluder::new(vp, (w, h), rect, &depth)));
    gpu.adapt_until_converged(&view, 1000).unwrap().expect("converges");
    gpu.check().unwrap();
    let culled = gpu.counts().1;
    let (image, _) = renderer.render_pm(gpu.mesh(), vp, (w, h), rect).unwrap();
    let (mut covered, mut close) = (0usize, 0usize);
    for (a, b) in plain.chunks_exact(4).zip(image.chunks_exact(4)) {
        if a[3] > 0 || b[3] > 0 {
            covered += 1;
            close += a.iter().zip(b).all(|(x, y)| x.abs_diff(*y) <= 8) as usize;
        }
    }
    let saving = 1.0 - culled as f64 / all as f64;
    let matching = close as f64 / covered as f64;
    eprintln!("{rel}: {all} triangles, {culled} with occlusion culling ({:.1}% fewer); {:.2}% of {covered} covered pixels within 8/255",
        saving * 100.0, matching * 100.0);
    assert!(saving >= min_saving, "{rel}: culling saved {:.1}% of the triangles", saving * 100.0);
    assert!(matching >= 0.99, "{rel}: {:.2}% of the covered pixels match", matching * 100.0);
    // Off again: back to the unculled mesh.
    gpu.set_occluder(None);
    gpu.adapt_until_converged(&view, 1000).unwrap().expect("converges");
    assert_eq!(gpu.counts().1, all);
}

#[test]
fn occlusion_culling_lowers_the_triangles_and_keeps_the_frame() {
    occlusion_on("stanford/bunny_zipper_c3d.obj.gz", 0.05);
}

/// `cargo test --release -p tessera-worker --test pm_gpu -- --ignored --nocapture occlusion`
#[test]
#[ignore = "the dragon; run in release"]
fn occlusion_culling_on_the_dragon() {
    occlusion_on("stanford/dragon_vrip.ply.gz", 0.05);
}

/// A memory budget (`GpuAdapter::set_budget`) bounds everything the adapter takes: on a
/// close view of the bunny whose mesh needs about twice the room the budget leaves it, every
/// pass stays within the budget, the passes that would overflow split nothing and raise the
/// error scale, and the converged mesh is the CPU reference's at the raised error (57.7x: so
/// close, the coarse spheres hold the eye and the error barely thins the mesh). A coarse view
/// afterwards fits at its own error again: the scale comes back to 1 and the mesh is the
/// CPU's for that view. A budget below the base mesh is refused.
#[test]
fn a_budget_bounds_the_graphics_memory() {
    let (_one_at_a_time, device) = device();
    let (bytes, pm) = dpm_of("stanford/bunny_zipper_c3d.obj.gz");
    let dpm = Dpm::parse(&bytes).unwrap();
    let close = path_view(&pm, 6, 24, 0.5);
    // The whole bunny at 48 px: a quarter of the triangles of the close view.
    let far = path_view(&pm, 0, 24, 48.0);
    let converge = |gpu: &mut GpuAdapter, view: &Viewpoint, budget: u64| {
        for pass in 0..200 {
            let st = gpu.adapt(view).unwrap();
            assert!(gpu.gpu_bytes() <= budget, "pass {pass}: {} bytes, budget {budget}", gpu.gpu_bytes());
            if st.converged() {
                return;
            }
        }
        panic!("not converged in 200 passes");
    };
    let cpu_at = |view: &Viewpoint, scale: f32| {
        let mut cpu = Adapter::new(&pm);
        cpu.adapt_until_converged(&Viewpoint { error_px: view.error_px * scale, ..*view }, 200).unwrap();
        sorted_canonical(cpu.face_fvids())
    };
    let mut free = GpuAdapter::new(&device, &dpm, 4096).unwrap();
    converge(&mut free, &close, u64::MAX);
    let (fixed, full) = (free.static_bytes(), free.gpu_bytes());
    let budget = fixed + (full - fixed) / 2;

    let mut gpu = GpuAdapter::new(&device, &dpm, 4096).unwrap();
    gpu.set_budget(Some(budget)).unwrap();
    converge(&mut gpu, &close, budget);
    let scale = gpu.error_scale();
    assert!(scale > 1.0, "the budget raised the error");
    let (tri, free_tri) = (gpu.counts().1, free.counts().1);
    assert!(tri < free_tri, "{tri} triangles within the budget, {free_tri} without");
    assert_eq!(sorted_canonical(gpu.face_fvids().unwrap()), cpu_at(&close, scale), "the CPU's mesh at {scale}x");
    eprintln!(
        "bunny, close view at 0.5 px: {free_tri} triangles in {full} bytes; within {budget} bytes {tri} triangles \
         at {scale}x the error ({} bytes)",
        gpu.gpu_bytes()
    );
    converge(&mut gpu, &far, budget);
    assert_eq!(gpu.error_scale(), 1.0, "a view that fits adapts at its own error");
    assert_eq!(sorted_canonical(gpu.face_fvids().unwrap()), cpu_at(&far, 1.0));

    let small = fixed + 1000;
    assert!(matches!(gpu.set_budget(Some(small)), Err(worker::pm_adapt::AdaptError::MeshBudget { .. })));
}

/// The adaptation of an orbit on the GPU, as `orbit_steps` in `codec/tests/pm_adapt.rs` on the
/// CPU: `cargo test -p tessera-worker --release --test pm_gpu -- --ignored --nocapture gpu_orbit_steps`.
/// The dragon at 1920x1080 and 0.5 px, 16 frames of 22.5 degrees, each converged, in passes of
/// all levels (the adapter's descent budget) and of one level; per frame the passes and their
/// time against one pass over the converged view (which changes nothing). (All levels run
/// first: run after the one-level adapter in the same process, lavapipe once took 3.3 s a
/// frame instead of 0.47 s; not reproduced with three adapters in turn over three frames.)
#[test]
#[ignore = "adapts the dragon along an orbit on the GPU; run in release"]
fn gpu_orbit_steps() {
    let rel = std::env::var("TESSERA_PM_MESH").unwrap_or_else(|_| "stanford/dragon_vrip.ply.gz".into());
    let (bytes, pm) = dpm_of(&rel);
    let dpm = Dpm::parse(&bytes).unwrap();
    let (_one_at_a_time, device) = device();
    let (lo, hi) = bbox(&pm);
    let cam = Camera::framing(lo.to_array(), hi.to_array(), 1920.0 / 1080.0);
    let frames = 16;
    // The default (all levels, one level for the rest of a view after a deep all-levels
    // pass), then each kind alone.
    for levels in [None, Some(Levels::All), Some(Levels::One)] {
        let mut gpu = GpuAdapter::new(&device, &dpm, DEFAULT_N_ALLOC).unwrap();
        if let Some(l) = levels {
            gpu.set_levels(l);
        }
        let name = levels.map_or("default".to_string(), |l| format!("{l:?}"));
        let mut first = 0.0;
        let (mut ratios, mut frame_ms, mut pass_ms, mut passes) = (vec![], vec![], vec![], vec![]);
        for k in 0..=frames {
            let rot = glam::Quat::from_axis_angle(cam.up.normalize(), std::f32::consts::TAU * k as f32 / frames as f32);
            let view =
                Viewpoint::new(&Camera { eye: cam.target + rot * (cam.eye - cam.target), ..cam }, 1920, 1080, 0.5);
            let start = Instant::now();
            let p = gpu.adapt_until_converged(&view, 1000).unwrap().expect("converges");
            let ms = start.elapsed().as_secs_f64() * 1e3;
            let start = Instant::now();
            assert!(gpu.adapt(&view).unwrap().converged());
            let still = start.elapsed().as_secs_f64() * 1e3;
            if std::env::var("VERBOSE").is_ok() {
                eprintln!("{name} frame {k}: {p} passes, {ms:.0} ms, converged pass {still:.1} ms");
            }
            if k == 0 {
                first = ms;
            } else {
                ratios.push(ms / still);
                frame_ms.push(ms);
                pass_ms.push(still);
                passes.push(p as f64);
            }
        }
        eprintln!(
            "{rel} {name} (descent budget {}), {}: from the base mesh {first:.0} ms; per frame {:.1} changing \
             passes, {:.0} ms = {:.1}x a converged pass ({:.1} ms; medians), at most {:.1}x",
            gpu.descent_budget(),
            device.adapter_name(),
            median(&mut passes),
            median(&mut frame_ms),
            median(&mut ratios.clone()),
            median(&mut pass_ms),
            ratios.iter().cloned().fold(0.0, f64::max)
        );
    }
}
