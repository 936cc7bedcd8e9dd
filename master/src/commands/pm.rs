//! `tessera pm`: dependency-free progressive meshes in `.dpm` files (build, stats, adapt).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use codec::pm::format::{self, DpmStats, EncodeOptions};
use codec::pm::{Adapter, Viewpoint};
use codec::Mesh;
use serde::Serialize;

use crate::camera::CameraSpec;
use crate::cli::Pm;
use crate::model::{dpm_file_bbox, expect_kind, load_mesh_streamed, pm_bbox, read_input};
use crate::output::{check_distinct, check_extension, mesh_output, summary, write_atomic};
use crate::progress;
use crate::spill;
use codec::kind::ModelKind;

/// How `pm build` meets a model larger than memory.
#[derive(Debug)]
pub struct MemoryPolicy {
    /// Stop before simplifying where the model plainly needs more memory than is available
    /// ([`memory_shortfall`]) and cannot spill either.
    pub check: bool,
    /// Spill large blocks into files in this folder from the start ([`crate::spill`]);
    /// without it, spill into the temporary folder where the memory check finds a shortfall.
    pub spill_dir: Option<PathBuf>,
    /// Blocks of at least this many bytes spill.
    pub spill_threshold: usize,
    /// The memory taken as available instead of what the system says (tests).
    pub available: Option<u64>,
}

/// The disk a spilled build takes, a triangle: what it holds at its peak with the mesh
/// (README, "A hundred million triangles"), and some room.
const SPILL_BYTES_PER_TRIANGLE: u64 = 80;

/// `tessera pm build IN -o OUT.dpm`, meeting a large model as `memory` says.
pub fn build(
    input: &Path,
    output: &Path,
    opts: EncodeOptions,
    build_opts: codec::pm::BuildOptions,
    memory: MemoryPolicy,
) -> Result<()> {
    check_extension(output, &["dpm"], "the output of pm build")?;
    check_distinct(&[input], &[output])?;
    let mut spilling = None;
    let available = || memory.available.or_else(available_memory);
    // Segments by the memory there is and what may spill (see `spill::segment_for`): the
    // spilled arrays take up to 80 bytes a triangle, and a binary PLY holds about 19 bytes a
    // triangle (half a vertex's 12 and a face's 13), so ten times the input's bytes.
    let input_bytes = std::fs::metadata(input).map_or(0, |m| m.len());
    let segment = || spill::segment_for(available().unwrap_or(u64::MAX), input_bytes.saturating_mul(10));
    if let Some(dir) = &memory.spill_dir {
        spill::enable(dir, memory.spill_threshold, segment())
            .with_context(|| format!("cannot keep the build's arrays in {}", dir.display()))?;
        spilling = Some(dir.clone());
    }
    // Where the model plainly cannot fit, spill into the temporary folder, from before the
    // triangles are read where the vertex count says so (a closed mesh has about twice as
    // many triangles as vertices), else once they are counted; or say why not.
    let try_spill = |triangles: u64, vertices: Option<usize>, spilling: &mut Option<PathBuf>| {
        // Before the triangles are read, what is left once they are (12 bytes each).
        let unread = if vertices.is_some() { triangles * 12 } else { 0 };
        let msg = memory_shortfall(triangles, vertices, available()?.saturating_sub(unread))?;
        let dir = std::env::temp_dir();
        let need = triangles * SPILL_BYTES_PER_TRIANGLE;
        let room = spill::free_bytes(&dir).unwrap_or(0);
        let why = if room < need {
            format!("{} has {:.1} GB free of the {:.1} GB spilling would take", dir.display(), gb(room), gb(need))
        } else {
            match spill::enable(&dir, memory.spill_threshold, segment()) {
                Ok(()) => {
                    eprintln!(
                        "note: {}: {msg}; keeping the build's large arrays in files in {} instead (--spill-dir)",
                        input.display(),
                        dir.display()
                    );
                    *spilling = Some(dir);
                    return None;
                }
                Err(e) => format!("cannot spill into {}: {e}", dir.display()),
            }
        };
        Some((msg, why))
    };
    let checking = memory.check && spilling.is_none();
    let mesh = load_mesh_streamed(input, &mut |vertices| {
        if checking {
            // An estimate: where it cannot spill, the check after loading decides.
            let _ = try_spill(2 * vertices as u64, Some(vertices), &mut spilling);
        }
    })?;
    if checking && spilling.is_none() {
        if let Some((msg, why)) = try_spill(mesh.triangles.len() as u64, None, &mut spilling) {
            anyhow::bail!(
                "cannot build {}: {msg}; free memory, add swap, pass --spill-dir DIR on a disk ({why}) \
                 or --no-memory-check to try anyway",
                input.display()
            );
        }
    }
    if spilling.is_some() {
        spill::drop_cached(input);
    }
    let start = Instant::now();
    let pb = progress::bar(mesh.positions.len() as u64, "simplifying (collapses)");
    // Owned: the progressive mesh holds every position and face, so the builder frees the
    // input as soon as it has numbered it and made the normals.
    let (pm, stats) = codec::pm::build_owned(mesh, build_opts, &mut |done, bound| {
        pb.set_length(bound as u64);
        pb.set_position(done as u64);
    })
    .with_context(|| format!("cannot build {}", input.display()))?;
    pb.finish_and_clear();
    let build_s = start.elapsed().as_secs_f64();
    let ops = pm.splits.len();
    let pb = progress::spinner(format!("compressing {ops} operations"));
    let t = Instant::now();
    // Owned, so that the encoder frees the splits once it has them in its own order; the file
    // is written from its parts (a large model's nodes are never copied into one buffer).
    let enc = format::encode_owned(pm, opts, &mut |step| {
        pb.set_message(format!("compressing {ops} operations: {step}"));
    })
    .context("cannot encode the progressive mesh")?;
    pb.finish_and_clear();
    let enc_s = t.elapsed().as_secs_f64();
    write_atomic(output, |w| enc.write_to(w))?;
    let secs = build_s + enc_s;
    summary(
        output,
        format_args!(
            "{} -> {}: {} triangles, {} vertices, {} operations, {} bytes ({:.2} bytes/vertex), \
         built in {:.0} ms + compressed in {:.0} ms ({:.0} ops/s)",
            input.display(),
            output.display(),
            enc.header.triangles,
            enc.header.vertices,
            enc.header.splits,
            enc.len(),
            enc.len() as f64 / enc.header.vertices.max(1) as f64,
            build_s * 1e3,
            enc_s * 1e3,
            enc.header.splits as f64 / secs.max(1e-9)
        ),
    )?;
    if stats.chunks > 1 {
        summary(
            output,
            format_args!("  simplified in {} chunks of at most {} triangles", stats.chunks, build_opts.chunk_faces),
        )?;
    }
    if let Some(dir) = &spilling {
        let st = spill::stats();
        summary(
            output,
            format_args!(
                "  kept up to {:.2} GB of arrays in files in {} (at most {} files at once){}",
                gb(st.peak_bytes),
                dir.display(),
                st.peak_files,
                if st.fallbacks > 0 {
                    format!(" ({} blocks could not be, and stayed in memory)", st.fallbacks)
                } else {
                    String::new()
                }
            ),
        )?;
    }
    let per_vertex = |bits: f64| bits / 8.0 / enc.header.vertices.max(1) as f64;
    summary(
        output,
        format_args!(
            "  entropy-coded symbols: {:.2} bytes/vertex with the static Huffman codes, {:.2} at their entropy \
         (an arithmetic coder's bound before its per-operation termination)",
            per_vertex(enc.symbol_bits.0),
            per_vertex(enc.symbol_bits.1)
        ),
    )?;
    Ok(())
}

/// The bytes a triangle `pm build` holds at its peak beyond the loaded mesh, on large models:
/// it peaks at 66 bytes a triangle (102M triangles) to 77 (13.9M) with the mesh, which takes
/// about 18 (README, "A hundred million triangles").
const BUILD_BYTES_PER_TRIANGLE: u64 = 48;

/// Why a build of `triangles` triangles, its mesh loaded, plainly cannot fit in `available`
/// bytes (the memory and swap free to this process), or `None`; `estimated_from`: the count
/// is twice these vertices, not the triangles read. The estimate is below what the builds
/// measured, so a build that is refused would have run out of memory.
pub fn memory_shortfall(triangles: u64, estimated_from: Option<usize>, available: u64) -> Option<String> {
    let need = triangles.saturating_mul(BUILD_BYTES_PER_TRIANGLE);
    let count = match estimated_from {
        Some(v) => format!("about {triangles} triangles (twice its {v} vertices)"),
        None => format!("{triangles} triangles"),
    };
    (need > available).then(|| {
        format!(
            "{count} need about {:.1} GB more to build (the builder holds the whole model, \
             about 65 bytes a triangle), and {:.1} GB is available",
            gb(need),
            gb(available)
        )
    })
}

fn gb(b: u64) -> f64 {
    b as f64 / 1e9
}

/// The memory and swap available to this process, from `/proc/meminfo` (`MemAvailable` plus
/// `SwapFree`) and, where it sets a lower limit, its cgroup's (v2 `memory.max`, v1
/// `memory.limit_in_bytes`, less what the cgroup uses); `None` where `/proc/meminfo` cannot
/// be read.
fn available_memory() -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok()?;
    let field = |name: &str| -> Option<u64> {
        let line = meminfo.lines().find(|l| l.starts_with(name))?;
        line.split_whitespace().nth(1)?.parse::<u64>().ok().map(|kb| kb * 1024)
    };
    let available = field("MemAvailable:")?.saturating_add(field("SwapFree:").unwrap_or(0));
    let read = |p: String| std::fs::read_to_string(p).ok().and_then(|s| s.trim().parse::<u64>().ok());
    // This process's cgroup: `0::PATH` (v2), `N:memory:PATH` (v1).
    let cgroups = std::fs::read_to_string("/proc/self/cgroup").unwrap_or_default();
    let own = |v1: bool| {
        cgroups.lines().find_map(|l| {
            let mut f = l.splitn(3, ':');
            let (_, controllers, path) = (f.next()?, f.next()?, f.next()?);
            let mine = if v1 { controllers.split(',').any(|c| c == "memory") } else { controllers.is_empty() };
            mine.then(|| path.trim_end_matches('/').to_string())
        })
    };
    let v2 = own(false).map(|p| format!("/sys/fs/cgroup{p}"));
    let v1 = own(true).map(|p| format!("/sys/fs/cgroup/memory{p}"));
    let (limit, usage) = [(v2, "memory.max", "memory.current"), (v1, "memory.limit_in_bytes", "memory.usage_in_bytes")]
        .into_iter()
        .find_map(|(dir, l, u)| {
            let dir = dir?;
            Some((read(format!("{dir}/{l}"))?, read(format!("{dir}/{u}"))?))
        })
        .unwrap_or((u64::MAX, 0));
    Some(available.min(limit.saturating_sub(usage)))
}

/// The numbers `tessera pm stats --json` prints; the `*_per_vertex` fields are the paper's
/// breakdown in bytes per vertex.
#[derive(Debug, Serialize)]
pub struct PmStatsReport {
    pub bytes: usize,
    pub vertices: u32,
    pub triangles: u32,
    pub operations: u32,
    pub base_vertices: u32,
    pub base_faces: u32,
    pub position_bits: u8,
    pub normal_bits: u8,
    pub bytes_per_vertex: f64,
    pub criteria_per_vertex: f64,
    pub tree_pointers_per_vertex: f64,
    pub connectivity_per_vertex: f64,
    pub geometry_per_vertex: f64,
    pub padding_per_vertex: f64,
    pub base_mesh_bytes: usize,
    pub table_bytes: usize,
    /// Out of core: the nodes, the node table's bytes and the node reads of the walk that
    /// decoded every operation (0 in core).
    pub nodes: u32,
    pub node_table_bytes: usize,
    pub node_reads: u64,
    pub framing_bytes: usize,
}

impl PmStatsReport {
    /// The report of a file's stats, and out of core the node reads they took.
    pub fn new(s: DpmStats, node_reads: u64) -> Self {
        let h = s.header;
        PmStatsReport {
            bytes: s.bytes,
            vertices: h.vertices,
            triangles: h.triangles,
            operations: h.splits,
            base_vertices: h.base_vertices,
            base_faces: h.base_faces,
            position_bits: h.position_bits,
            normal_bits: h.normal_bits,
            bytes_per_vertex: s.bytes_per_vertex(),
            criteria_per_vertex: s.per_vertex(s.criteria_bytes),
            tree_pointers_per_vertex: s.per_vertex(s.tree_pointer_bytes),
            connectivity_per_vertex: s.per_vertex(s.connectivity_bytes),
            geometry_per_vertex: s.per_vertex(s.geometry_bytes),
            padding_per_vertex: s.per_vertex(s.padding_bytes),
            base_mesh_bytes: s.base_bytes,
            table_bytes: s.table_bytes,
            nodes: h.nodes,
            node_table_bytes: s.node_table_bytes,
            node_reads,
            framing_bytes: s.framing_bytes,
        }
    }
}

/// `tessera pm stats IN.dpm [--json]` (decodes every operation, so corruption is reported; an
/// out-of-core file node by node, never read whole).
pub fn stats(input: &Path, json: bool) -> Result<()> {
    expect_kind(input, ModelKind::Dpm, "pm stats", "stats")?;
    let at = || format!("{}", input.display());
    let r = match format::NodeFile::open_out_of_core(input).with_context(at)? {
        Some(file) => {
            let (s, reads) = DpmStats::of_out_of_core(&file).with_context(at)?;
            PmStatsReport::new(s, reads)
        }
        None => PmStatsReport::new(DpmStats::of(&read_input(input)?).with_context(at)?, 0),
    };
    if json {
        crate::outln!("{}", serde_json::to_string_pretty(&r)?)?;
    } else {
        crate::outln!("{}", input.display())?;
        crate::outln!("  vertices       {:>12}   ({} in the base mesh)", r.vertices, r.base_vertices)?;
        crate::outln!("  triangles      {:>12}   ({} in the base mesh)", r.triangles, r.base_faces)?;
        crate::outln!("  operations     {:>12}", r.operations)?;
        crate::outln!("  bytes          {:>12}   ({:.2} per vertex)", r.bytes, r.bytes_per_vertex)?;
        crate::outln!("  criteria       {:>12.2} bytes/vertex", r.criteria_per_vertex)?;
        crate::outln!("  tree pointers  {:>12.2} bytes/vertex", r.tree_pointers_per_vertex)?;
        crate::outln!("  connectivity   {:>12.2} bytes/vertex", r.connectivity_per_vertex)?;
        crate::outln!(
            "  geometry       {:>12.2} bytes/vertex ({} bits positions, {} bits normals)",
            r.geometry_per_vertex,
            r.position_bits,
            r.normal_bits
        )?;
        crate::outln!("  padding        {:>12.2} bytes/vertex", r.padding_per_vertex)?;
        crate::outln!("  base, tables   {:>12} + {} bytes", r.base_mesh_bytes, r.table_bytes)?;
        if r.nodes > 0 {
            crate::outln!(
                "  nodes          {:>12}   (out of core; node table {} bytes; {} node reads)",
                r.nodes,
                r.node_table_bytes,
                r.node_reads
            )?;
        }
    }
    Ok(())
}

/// `pm adapt`'s options, as `master::cli` parsed and checked them.
#[derive(Clone, Copy, Debug)]
pub struct AdaptOptions {
    pub size: (u32, u32),
    pub error_px: f32,
    /// Normal error weight, a fraction of the bounding box diagonal (see [`Viewpoint::attribute_scale`]).
    pub normal_weight: f32,
    /// Every split, regardless of the view.
    pub full: bool,
    /// On the GPU ([`worker::pm_adapt::GpuAdapter`]).
    pub gpu: bool,
    /// On the GPU, the bytes of graphics memory the adaptation may take (`None`: what the
    /// device binds).
    pub gpu_budget: Option<u64>,
    /// On the GPU, an out-of-core file's node pool in bytes (`None`: a quarter of the budget,
    /// or every node without one).
    pub gpu_nodes: Option<u64>,
    /// How far a pass moves a vertex in the split tree: every level the view asks for (one
    /// pass reaches the mesh), or one (the paper's passes); `None`: all levels on the CPU,
    /// the GPU adapter's default on the GPU (one on a software adapter).
    pub levels: Option<codec::pm::Levels>,
}

/// `tessera pm adapt IN.dpm [camera] --size WxH --error-px E -o OUT.ply [--full] [--gpu]`.
///
/// The PLY holds the active vertices in FVID order and the faces sorted by their index
/// triples (orientation kept), so that the CPU and GPU paths, whose face orders differ, write
/// the same file for the same mesh.
///
/// An out-of-core file is adapted from the nodes the view needs (read from the file: the nodes
/// of priority at least 1; on the GPU those that its node pool holds, by default slots for
/// all of them), never decoded whole: its memory follows the view. Its default camera frames
/// [`dpm_file_bbox`], as `render`'s does. `--full` on the CPU decodes the file (the mesh is
/// the model).
pub fn adapt(input: &Path, camera: &CameraSpec, opts: &AdaptOptions, output: &Path) -> Result<()> {
    let writer = mesh_output(input, output, "the output of pm adapt")?;
    expect_kind(input, ModelKind::Dpm, "pm adapt", "adapt")?;
    let at = || format!("{}", input.display());
    let adapted = match format::NodeFile::open_out_of_core(input).with_context(at)? {
        Some(file) if opts.gpu || !opts.full => adapt_out_of_core(input, std::sync::Arc::new(file), camera, opts)?,
        _ => adapt_in_core(input, camera, opts)?,
    };
    let (mut mesh, passes, secs, read) = adapted;
    let read = read.map_or(String::new(), |r| {
        let mb = |b: u64| b as f64 / 1e6;
        format!("; read {} of {} nodes ({:.1} of {:.1} MB)", r.nodes, r.of_nodes, mb(r.bytes), mb(r.of_bytes))
    });
    mesh.triangles.sort_unstable();
    write_atomic(output, |w| writer(&mesh, w))?;
    summary(
        output,
        format_args!(
            "{} -> {}: {} triangles, {} vertices ({} passes{}) in {:.1} ms{}",
            input.display(),
            output.display(),
            mesh.triangles.len(),
            mesh.positions.len(),
            passes,
            if opts.gpu { " on the GPU" } else { "" },
            secs * 1e3,
            read
        ),
    )?;
    Ok(())
}

/// The most passes `pm adapt` runs before it calls the adaptation unconverged.
const MAX_PASSES: usize = 10_000;

/// An adapted mesh (faces unsorted), its passes, the seconds they took, and out of core what
/// was read of the file's nodes.
type Adapted = (Mesh, usize, f64, Option<NodesRead>);

/// The nodes an out-of-core `pm adapt` read, of the file's.
struct NodesRead {
    nodes: usize,
    bytes: u64,
    of_nodes: usize,
    of_bytes: u64,
}

impl NodesRead {
    fn new(prefix: &format::Dpm, nodes: usize, bytes: u64) -> NodesRead {
        let of_bytes = prefix.nodes.iter().map(|n| n.len as u64).sum();
        NodesRead { nodes, bytes, of_nodes: prefix.nodes.len(), of_bytes }
    }
}

/// The view `pm adapt` adapts to, for a model in the box `lo`-`hi`.
fn adapt_view(camera: &CameraSpec, opts: &AdaptOptions, (lo, hi): ([f32; 3], [f32; 3])) -> Result<Viewpoint> {
    let size = opts.size;
    let cam = camera.camera(lo, hi, size.0 as f32 / size.1 as f32)?;
    crate::camera::check_camera(&cam, size.1)?;
    let mut view = Viewpoint::new(&cam, size.0, size.1, opts.error_px);
    view.attribute_scale = opts.normal_weight * glam::Vec3::from(hi).distance(glam::Vec3::from(lo));
    Ok(view)
}

/// Sets a GPU adapter up as `opts` ask: its levels per pass and its budget.
fn configure_gpu(adapter: &mut worker::pm_adapt::GpuAdapter, opts: &AdaptOptions) -> Result<()> {
    if let Some(levels) = opts.levels {
        adapter.set_levels(levels);
    }
    adapter.set_budget(opts.gpu_budget)?;
    Ok(())
}

/// Adapts a GPU adapter to `view` (every split without one) and checks it, printing the error
/// it adapted to where its budget made it coarser than asked: the passes and the seconds they
/// took (timed from the base mesh on the device, after the device, pipelines, static buffers
/// and nodes are set up).
fn run_gpu(
    adapter: &mut worker::pm_adapt::GpuAdapter,
    view: Option<&Viewpoint>,
    opts: &AdaptOptions,
) -> Result<(usize, f64)> {
    let start = Instant::now();
    let passes = match view {
        None => adapter.refine_fully()?,
        Some(v) => adapter.adapt_until_converged(v, MAX_PASSES)?.context("the adaptation did not converge")?,
    };
    adapter.check()?;
    let secs = start.elapsed().as_secs_f64();
    let scale = adapter.error_scale();
    if scale > 1.0 {
        eprintln!(
            "note: adapted to {:.3} px ({:.2}x --error-px) to stay within --gpu-budget-mb",
            opts.error_px * scale,
            scale
        );
    }
    Ok((passes, secs))
}

/// `pm adapt` of an in-core file (or `--full` on the CPU): decoded whole.
fn adapt_in_core(input: &Path, camera: &CameraSpec, opts: &AdaptOptions) -> Result<Adapted> {
    let bytes = read_input(input)?;
    let pb = progress::spinner(format!("decoding {}", input.display()));
    let decoded = format::decode(&bytes).with_context(|| format!("{}", input.display()));
    pb.finish_and_clear();
    let pm = decoded?.pm;
    let view = if opts.full { None } else { Some(adapt_view(camera, opts, pm_bbox(&pm.positions))?) };
    let (active, faces, passes, secs) = if opts.gpu {
        let gpu = worker::gpu::Gpu::new()?;
        let dpm = format::Dpm::parse(&bytes)?;
        let mut adapter = worker::pm_adapt::GpuAdapter::new(&gpu, &dpm, worker::pm_adapt::DEFAULT_N_ALLOC)?;
        configure_gpu(&mut adapter, opts)?;
        let (passes, secs) = run_gpu(&mut adapter, view.as_ref(), opts)?;
        (adapter.active()?, adapter.faces()?, passes, secs)
    } else {
        let start = Instant::now();
        let mut adapter = Adapter::new(&pm).with_levels(opts.levels.unwrap_or(codec::pm::Levels::All));
        let passes = match &view {
            None => adapter.refine_fully(),
            Some(v) => adapter.adapt_until_converged(v, MAX_PASSES).context("the adaptation did not converge")?,
        };
        (adapter.active().to_vec(), adapter.faces().to_vec(), passes, start.elapsed().as_secs_f64())
    };
    let positions = active.iter().map(|&f| pm.positions[f as usize]).collect();
    Ok((Mesh::new(positions, faces), passes, secs, None))
}

/// `pm adapt` of an out-of-core file from the nodes its view needs (see [`adapt`]).
fn adapt_out_of_core(
    input: &Path,
    file: std::sync::Arc<format::NodeFile>,
    camera: &CameraSpec,
    opts: &AdaptOptions,
) -> Result<Adapted> {
    let at = || format!("{}", input.display());
    let head = file.clone();
    let prefix = format::Dpm::parse_prefix(head.prefix()).with_context(at)?;
    let view = adapt_view(camera, opts, dpm_file_bbox(&prefix))?;
    // The nodes that can hold an operation the view asks for.
    let planes = view.planes();
    let required = || prefix.nodes.iter().filter(|n| n.priority(&view, &planes) >= 1.0);
    if opts.gpu {
        let gpu = worker::gpu::Gpu::new()?;
        let pool_bytes = match (opts.gpu_budget, opts.gpu_nodes, opts.full) {
            // Slots for the required nodes (every node to refine fully).
            (None, None, false) => {
                let slot = u64::from(worker::pm_adapt::decoder::slot_bytes(&prefix));
                required().count().max(1) as u64 * slot
            }
            (budget, nodes, _) => worker::pm_adapt::pool_bytes(budget, nodes)?,
        };
        let ooc = worker::pm_adapt::OutOfCore { file, pool_bytes, background: false };
        let mut adapter =
            worker::pm_adapt::GpuAdapter::out_of_core(&gpu, &prefix, ooc, worker::pm_adapt::DEFAULT_N_ALLOC)?;
        configure_gpu(&mut adapter, opts)?;
        let stats = adapter.schedule(&view)?.context("an out-of-core adapter without a node cache")?;
        let read = NodesRead::new(&prefix, stats.loaded, stats.loaded_bytes);
        let (passes, secs) = run_gpu(&mut adapter, (!opts.full).then_some(&view), opts)?;
        let positions = adapter.quantized_positions()?.into_iter().map(|q| prefix.position(q)).collect();
        return Ok((Mesh::new(positions, adapter.faces()?), passes, secs, Some(read)));
    }
    // Exactly the required nodes.
    let bytes = required().map(|n| n.len as u64).sum();
    let mut cache = codec::pm::NodeCache::new(&prefix, file, bytes, false);
    let stats = cache.schedule(&view).with_context(at)?;
    let read = NodesRead::new(&prefix, stats.loaded, stats.loaded_bytes);
    let start = Instant::now();
    let mut adapter = codec::pm::DpmAdapter::new(&prefix)
        .with_context(at)?
        .with_levels(opts.levels.unwrap_or(codec::pm::Levels::All));
    let mut passes = None;
    for p in 0..MAX_PASSES {
        if adapter.adapt_resident(&view, &cache).with_context(at)?.converged() {
            passes = Some(p);
            break;
        }
    }
    let passes = passes.context("the adaptation did not converge")?;
    let secs = start.elapsed().as_secs_f64();
    Ok((Mesh::new(adapter.positions(), adapter.faces().to_vec()), passes, secs, Some(read)))
}

/// `tessera pm build|stats|adapt`: the flags resolved into each command's options.
pub fn run(pm: &Pm) -> Result<()> {
    match pm {
        Pm::Build {
            input,
            output,
            position_bits,
            normal_bits,
            node_kb,
            chunk_faces,
            no_memory_check,
            spill_dir,
            spill_min_mb,
            assume_available_mb,
        } => build(
            input,
            output,
            codec::pm::DpmOptions {
                position_bits: *position_bits,
                normal_bits: *normal_bits,
                node_bytes: node_kb.map_or(0, |k| k * 1024),
            },
            codec::pm::BuildOptions { chunk_faces: *chunk_faces },
            MemoryPolicy {
                check: !*no_memory_check,
                spill_dir: spill_dir.clone(),
                spill_threshold: spill_min_mb << 20,
                available: assume_available_mb.map(|mb| mb << 20),
            },
        ),
        Pm::Stats { input, json } => stats(input, *json),
        Pm::Adapt {
            input,
            view,
            error_px,
            output,
            full,
            normal_weight,
            gpu,
            gpu_budget_mb,
            gpu_nodes_mb,
            one_level,
        } => {
            let mb = |mb: f32| (mb as f64 * (1u64 << 20) as f64) as u64;
            let opts = AdaptOptions {
                size: view.size,
                error_px: *error_px,
                normal_weight: *normal_weight,
                full: *full,
                gpu: *gpu,
                gpu_budget: gpu_budget_mb.map(mb),
                gpu_nodes: gpu_nodes_mb.map(mb),
                levels: one_level.then_some(codec::pm::Levels::One),
            };
            adapt(input, &view.camera.spec(), &opts, output)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A model that plainly needs more than is available is refused with the figures and the
    /// way around; one that fits, and the memory this machine reports, pass.
    #[test]
    fn a_build_that_cannot_fit_is_refused_before_it_starts() {
        let msg = memory_shortfall(450_000_000, None, 20_000_000_000).expect("refused");
        assert!(msg.contains("450000000 triangles need about 21.6 GB"), "{msg}");
        assert!(msg.contains("20.0 GB is available"), "{msg}");
        let estimated = memory_shortfall(450_000_000, Some(225_000_000), 20_000_000_000).expect("refused");
        assert!(estimated.starts_with("about 450000000 triangles (twice its 225000000 vertices) need about 21.6 GB"));
        assert!(!msg.contains('\n'));
        assert_eq!(memory_shortfall(100_000_000, None, 20_000_000_000), None);
        assert_eq!(memory_shortfall(0, None, 0), None);
        let available = available_memory().expect("Linux reports its memory");
        assert!(available > 0 && memory_shortfall(1_000_000, None, available).is_none(), "{available} bytes");
    }

    /// The box of an out-of-core file holds every vertex and is cut to the quantization grid,
    /// where the union of its node boxes (the operations' spheres) reaches far past the model.
    #[test]
    fn the_out_of_core_box_holds_the_model_and_no_more_than_its_grid() {
        let mesh = crate::model::load_mesh(&testkit::mesh_path("stanford/bunny_zipper_c3d.obj.gz")).unwrap();
        let pm = codec::pm::build(&mesh).unwrap();
        let opts = EncodeOptions { node_bytes: 4096, ..EncodeOptions::default() };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bunny.dpm");
        std::fs::write(&path, format::encode(&pm, opts).unwrap().bytes).unwrap();
        let file = format::NodeFile::open_out_of_core(&path).unwrap().expect("out of core");
        let dpm = format::Dpm::parse_prefix(file.prefix()).unwrap();
        let (lo, hi) = dpm_file_bbox(&dpm);
        let (elo, ehi) = pm_bbox(&pm.positions);
        let step = dpm.header.step;
        let extent = (0..3).map(|k| ehi[k] - elo[k]).fold(0.0f32, f32::max);
        let (mut ulo, mut uhi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for n in &dpm.nodes {
            for k in 0..3 {
                ulo[k] = ulo[k].min(n.bbox_min[k]);
                uhi[k] = uhi[k].max(n.bbox_max[k]);
            }
        }
        for k in 0..3 {
            assert!(
                lo[k] <= elo[k] + step && hi[k] >= ehi[k] - step,
                "axis {k}: {lo:?}..{hi:?} misses {elo:?}..{ehi:?}"
            );
            assert!(hi[k] - lo[k] <= extent + 2.0 * step, "axis {k}: {lo:?}..{hi:?} wider than the grid");
        }
        // The nodes' union is larger (that is what the cut is for).
        assert!((0..3).any(|k| uhi[k] - ulo[k] > extent * 1.2), "union {ulo:?}..{uhi:?}, extent {extent}");
    }
}
