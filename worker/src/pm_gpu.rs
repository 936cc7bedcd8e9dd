//! View-dependent adaptation of a dependency-free progressive mesh on the GPU: the stages of
//! Algorithms 1 to 5 of Derzapf and Guthe as WGSL compute pipelines (`shaders/pm/*.wgsl`, one
//! file per stage, `common.wgsl` prepended to each but the generic scan), driven pass by pass from here. It is the
//! GPU twin of the CPU reference [`codec::pm::Adapter`]: same state, same decisions, same
//! triangle set after every pass (tested in `worker/tests/pm_gpu.rs`).
//!
//! One [`GpuAdapter::adapt`] pass is two submissions:
//!
//! 1. state update (Algorithm 1), collapses (Algorithm 2, in place), and the work-efficient
//!    scans of the vertex and face counts; the totals and the collapse counters are then read
//!    back (40 bytes): the host needs them to size the buffers (the paper's `n_alloc` policy)
//!    and to size the remaining dispatches;
//! 2. vertex reorganisation (Algorithm 3) into the other of two vertex buffer sets, split
//!    compaction, splits with binary search (Algorithm 4), index update (Algorithm 5) and the
//!    in-place face compaction (section 5.6).
//!
//! The adapted mesh stays on the GPU between passes (temporal coherence). It is drawn straight
//! from these buffers: the face index buffer is the draw's index buffer, and the vertex shader
//! pulls each vertex's position and normal through its FVID (see `vs_pulled` in
//! `shaders/render.wgsl`), so rendering reads nothing back.
//!
//! Where this differs from the paper:
//!
//! * The split records (criteria, children, faces) are uploaded decoded, once, from the
//!   `.dpm` decoded on the CPU; the paper decodes each operation on the GPU from its address.
//!   The split/collapse cache is then the split record itself, one indexed load away.
//! * The vertex VBO is not copied during reorganisation: positions and normals are static per
//!   FVID and pulled through the FVID buffer, so a pass moves 12 bytes per vertex, not 36.
//! * Splits write `v` and `v_u` during reorganisation, so that the new FVID buffer is complete
//!   before the split stage binary-searches it; the split stage appends the faces.
//! * Faces carry the split that created them (4 bytes per face): the collapse removes exactly
//!   those, as in the CPU reference (inputs may hold faces that are degenerate at every level).
//! * The split compaction and the face compaction use atomic cursors instead of scans: the
//!   order they produce does not matter (face slots come from the face prefix sum, and the
//!   face order of the adapted mesh is free), so the triangle *set*, not the face order, is
//!   what equals the CPU reference.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use codec::pm::{PassStats, ProgressiveMesh, SplitTree, Viewpoint, NONE};
use thiserror::Error;
use wgpu::util::DeviceExt;

use crate::gpu::{Gpu, GpuError};
use crate::render::{AdaptedMesh, PmPoint};

const WG: u32 = 256;
const SCAN_BLOCK: u32 = 2048;
/// The default of the paper's `n_alloc`: spare elements a reallocated buffer gets.
pub const DEFAULT_N_ALLOC: u32 = 1 << 15;

/// Why an adaptation could not start or a pass failed.
#[derive(Debug, Error)]
pub enum AdaptError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("GPU error: the PM stages need {need} storage buffers per shader stage; the adapter allows {allowed}")]
    TooFewStorageBuffers { need: u32, allowed: u32 },
    /// The totals read back after the classification do not add up (a GPU fault).
    #[error("GPU error: inconsistent pass totals: {vertices} vertices, {after} after, {collapses} collapses")]
    InconsistentTotals { vertices: u32, after: u32, collapses: u32 },
    /// A face read back refers to a vertex that is not active (a GPU fault).
    #[error("GPU error: face index {index} out of {vertices} vertices")]
    FaceIndex { index: u32, vertices: usize },
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct GpuSplit {
    v: u32,
    v_u: u32,
    face_off: u32,
    face_cnt: u32,
    child: [u32; 2],
    parent: u32,
    pad: u32,
    crit: [f32; 4],
}

/// `Params` of `shaders/pm/common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable, Default)]
struct Params {
    planes: [[f32; 4]; 6],
    eye: [f32; 4],
    pixels_per_unit: f32,
    error_px: f32,
    c_lod: f32,
    attribute_scale: f32,
    n: u32,
    m: u32,
    mode: u32,
    n_new: u32,
    f_add: u32,
    m_new: u32,
    splits: u32,
    pad: u32,
}

const STAT_COLLAPSES: usize = 0;
const STAT_CANCELLED: usize = 1;
const STAT_REMOVED_FACES: usize = 2;
const STATS_BYTES: u64 = 32;
/// Readback: vertex total, face total, then the 8 counters.
const READBACK_BYTES: u64 = 8 + STATS_BYTES;

/// A compute pipeline and its bind group layout, taken from it once: `get_bind_group_layout`
/// registers a new layout handle on every call, and calling it for every bind group of every
/// pass grew a worker's memory by megabytes a frame (measured on lavapipe).
struct Stage {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl std::ops::Deref for Stage {
    type Target = wgpu::ComputePipeline;
    fn deref(&self) -> &wgpu::ComputePipeline {
        &self.pipeline
    }
}

struct Pipelines {
    state: Stage,
    collapse: Stage,
    scan_blocks: Stage,
    add_blocks: Stage,
    reorganise: Stage,
    compact_splits: Stage,
    split: Stage,
    index_update: Stage,
    holes: Stage,
    fill: Stage,
}

impl Pipelines {
    fn new(device: &wgpu::Device) -> Pipelines {
        let common = include_str!("../../shaders/pm/common.wgsl");
        let module = |label: &str, stage: &str| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(format!("{common}\n{stage}").into()),
            })
        };
        let pipeline = |module: &wgpu::ShaderModule, label: &str, entry: &str| {
            let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: None,
                module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            });
            let layout = pipeline.get_bind_group_layout(0);
            Stage { pipeline, layout }
        };
        let single = |label: &str, src: &str| pipeline(&module(label, src), label, "main");
        let scan = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("pm: scan"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../../shaders/pm/scan.wgsl").into()),
        });
        let compact = module("pm: face compaction", include_str!("../../shaders/pm/face_compact.wgsl"));
        Pipelines {
            state: single("pm: state update", include_str!("../../shaders/pm/state.wgsl")),
            collapse: single("pm: collapse", include_str!("../../shaders/pm/collapse.wgsl")),
            scan_blocks: pipeline(&scan, "pm: scan blocks", "scan_blocks"),
            add_blocks: pipeline(&scan, "pm: scan add", "add_blocks"),
            reorganise: single("pm: reorganise", include_str!("../../shaders/pm/reorganise.wgsl")),
            compact_splits: single("pm: compact splits", include_str!("../../shaders/pm/compact_splits.wgsl")),
            split: single("pm: split", include_str!("../../shaders/pm/split.wgsl")),
            index_update: single("pm: index update", include_str!("../../shaders/pm/index_update.wgsl")),
            holes: pipeline(&compact, "pm: face holes", "holes"),
            fill: pipeline(&compact, "pm: face fill", "fill"),
        }
    }
}

/// A buffer with a capacity in elements, resized by the paper's `n_alloc` policy.
struct Sized {
    buffer: wgpu::Buffer,
    /// Capacity in elements.
    cap: u64,
}

/// One level of the recursive scan: its block sums, a uniform with its element count, and
/// its number of blocks.
struct ScanLevel {
    sums: Sized,
    uniform: wgpu::Buffer,
    blocks: u32,
}

/// The per-vertex buffers (one of two sets: reorganisation copies from one into the other).
struct VertexSet {
    fvid: Sized,
    next: Sized,
    node: Sized,
}

impl VertexSet {
    fn new(device: &wgpu::Device, name: &str, cap: u64) -> VertexSet {
        VertexSet {
            fvid: storage(device, &format!("pm: vertex fvid {name}"), cap, 4, VERTEX_USAGE),
            next: storage(device, &format!("pm: vertex next {name}"), cap, 4, VERTEX_USAGE),
            node: storage(device, &format!("pm: vertex node {name}"), cap, 4, VERTEX_USAGE),
        }
    }
}

struct FaceSet {
    /// Current vertex indices, 3 per face: the draw's index buffer.
    idx: Sized,
    fvid: Sized,
    owner: Sized,
}

impl FaceSet {
    fn new(device: &wgpu::Device, cap: u64) -> FaceSet {
        FaceSet {
            idx: storage(device, "pm: face indices", cap, 12, VERTEX_USAGE | wgpu::BufferUsages::INDEX),
            fvid: storage(device, "pm: face fvids", cap, 12, VERTEX_USAGE),
            owner: storage(device, "pm: face owners", cap, 4, VERTEX_USAGE),
        }
    }
}

/// The adaptation state of one progressive mesh on the GPU (see the module docs).
pub struct GpuAdapter {
    gpu: Gpu,
    /// Pipelines and static data, shared by every adapter of the same mesh on this device.
    shared: Arc<Shared>,
    n_alloc: u32,
    params: wgpu::Buffer,
    stats: wgpu::Buffer,
    readback: wgpu::Buffer,
    sets: [VertexSet; 2],
    cur: usize,
    faces: FaceSet,
    vcnt: Sized,
    fcnt: Sized,
    list: Sized,
    hole: Sized,
    /// Per scan level, for the current pass ([`GpuAdapter::prepare_scan`]).
    levels: Vec<ScanLevel>,
    /// Active vertices and faces.
    n: u32,
    m: u32,
    reallocations: u64,
    /// Wait for each pass's second submission and time it ([`GpuAdapter::set_profiling`]).
    profile: bool,
    /// Milliseconds of the last pass: classification (to the totals read back), application.
    times: [f64; 3],
}

/// What adapters of the same progressive mesh share: the pipelines, the static buffers, and
/// the base mesh.
struct Shared {
    pipelines: Pipelines,
    max_groups: u32,
    splits: wgpu::Buffer,
    split_faces: wgpu::Buffer,
    points: wgpu::Buffer,
    base: BaseState,
}

const VERTEX_USAGE: wgpu::BufferUsages =
    wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_SRC).union(wgpu::BufferUsages::COPY_DST);

fn storage(device: &wgpu::Device, label: &str, elements: u64, element_bytes: u64, usage: wgpu::BufferUsages) -> Sized {
    // Never empty: a binding needs at least one element.
    let size = (elements.max(1) * element_bytes).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT).max(16);
    let buffer =
        device.create_buffer(&wgpu::BufferDescriptor { label: Some(label), size, usage, mapped_at_creation: false });
    Sized { buffer, cap: elements }
}

fn init(device: &wgpu::Device, label: &str, data: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
    let mut padded;
    let contents = if data.len() < 16 || !data.len().is_multiple_of(4) {
        padded = data.to_vec();
        padded.resize(data.len().max(16).next_multiple_of(4), 0);
        &padded[..]
    } else {
        data
    };
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
}

/// Whether a buffer of `cap` elements must be reallocated for `need`: too small, or larger
/// than `need + 2 n_alloc` (section 5.3).
fn needs_resize(cap: u64, need: u64, n_alloc: u32) -> bool {
    cap < need || cap > need + 2 * n_alloc as u64
}

impl GpuAdapter {
    /// Uploads `pm` to `gpu`'s device and starts at the base mesh. `n_alloc` is the paper's
    /// reallocation slack in elements ([`DEFAULT_N_ALLOC`]).
    pub fn new(gpu: &Gpu, pm: &ProgressiveMesh, n_alloc: u32) -> Result<GpuAdapter, AdaptError> {
        let limits = gpu.limits();
        if limits.max_storage_buffers_per_shader_stage < 10 {
            return Err(AdaptError::TooFewStorageBuffers {
                need: 10,
                allowed: limits.max_storage_buffers_per_shader_stage,
            });
        }
        let tree = SplitTree::new(pm);
        let mut face_off = 0u32;
        let splits: Vec<GpuSplit> = pm
            .splits
            .iter()
            .enumerate()
            .map(|(s, split)| {
                let c = pm.criteria.get(s).copied().unwrap_or_default();
                let g = GpuSplit {
                    v: split.v,
                    v_u: split.v_u,
                    face_off,
                    face_cnt: split.faces.len() as u32,
                    child: tree.children[s],
                    parent: tree.parent[s],
                    pad: 0,
                    crit: [c.sin_alpha, c.geometric_error, c.attribute_error, c.radius],
                };
                face_off += split.faces.len() as u32;
                g
            })
            .collect();
        let split_faces: Vec<u32> = pm.splits.iter().flat_map(|s| s.faces.iter().flatten().copied()).collect();
        let points: Vec<PmPoint> = pm
            .positions
            .iter()
            .enumerate()
            .map(|(f, p)| {
                let n = pm.normals.get(f).copied().unwrap_or_default();
                PmPoint { pos: [p[0], p[1], p[2], 1.0], nrm: [n[0], n[1], n[2], 0.0] }
            })
            .collect();
        gpu.scoped(|| {
            let device = gpu.device();
            let read_only = wgpu::BufferUsages::STORAGE;
            let splits = init(device, "pm: splits", bytemuck::cast_slice(&splits), read_only);
            let split_faces = init(device, "pm: split faces", bytemuck::cast_slice(&split_faces), read_only);
            let points = init(device, "pm: points", bytemuck::cast_slice(&points), read_only);
            let shared = Arc::new(Shared {
                pipelines: Pipelines::new(device),
                max_groups: limits.max_compute_workgroups_per_dimension,
                splits,
                split_faces,
                points,
                base: base_state(pm, &tree),
            });
            Ok(GpuAdapter::with_shared(gpu.clone(), shared, n_alloc.max(1)))
        })
    }

    /// A second adapter of the same mesh on the same device, at the base mesh, sharing the
    /// pipelines and static buffers (a worker keeps one per tile it renders).
    pub fn sibling(&self) -> GpuAdapter {
        self.sibling_with_slack(self.n_alloc)
    }

    /// [`GpuAdapter::sibling`] with its own `n_alloc`: a worker that keeps one adapter per
    /// tile gives each a share of the slack, so that the slack summed over its tiles stays
    /// one adapter's whatever the tile count.
    pub fn sibling_with_slack(&self, n_alloc: u32) -> GpuAdapter {
        GpuAdapter::with_shared(self.gpu.clone(), self.shared.clone(), n_alloc.max(1))
    }

    /// A new adapter at the base mesh.
    fn with_shared(gpu: Gpu, shared: Arc<Shared>, n_alloc: u32) -> GpuAdapter {
        let d = gpu.device();
        let mut adapter = GpuAdapter {
            shared,
            n_alloc,
            params: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pm: params"),
                size: std::mem::size_of::<Params>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            stats: storage(d, "pm: stats", 8, 4, VERTEX_USAGE).buffer,
            readback: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pm: readback"),
                size: READBACK_BYTES,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            sets: [VertexSet::new(d, "A", 0), VertexSet::new(d, "B", 0)],
            cur: 0,
            faces: FaceSet::new(d, 0),
            vcnt: storage(d, "pm: vertex counts", 0, 4, VERTEX_USAGE),
            fcnt: storage(d, "pm: face counts", 0, 4, VERTEX_USAGE),
            list: storage(d, "pm: split list", 0, 4, VERTEX_USAGE),
            hole: storage(d, "pm: face holes", 0, 4, VERTEX_USAGE),
            levels: Vec::new(),
            n: 0,
            m: 0,
            reallocations: 0,
            profile: false,
            times: [0.0; 3],
            gpu,
        };
        adapter.reset();
        adapter
    }

    /// Goes back to the base mesh.
    pub fn reset(&mut self) {
        let shared = self.shared.clone();
        let (fvid, next, faces_idx, faces_fvid) = &shared.base;
        let (n, m) = (fvid.len() as u64, faces_idx.len() as u64);
        let node = vec![NONE; fvid.len()];
        let owner = vec![NONE; faces_idx.len()];
        self.cur = 0;
        let na = self.n_alloc as u64;
        if needs_resize(self.sets[0].fvid.cap, n, self.n_alloc) {
            self.sets[0] = VertexSet::new(self.gpu.device(), "A", n + na);
        }
        let set = &self.sets[0];
        for (s, data) in [(&set.fvid, fvid), (&set.next, next), (&set.node, &node)] {
            if !data.is_empty() {
                self.gpu.queue().write_buffer(&s.buffer, 0, bytemuck::cast_slice(data));
            }
        }
        if needs_resize(self.faces.idx.cap, m, self.n_alloc) {
            self.faces = FaceSet::new(self.gpu.device(), m + na);
        }
        let faces = &self.faces;
        if m > 0 {
            self.gpu.queue().write_buffer(&faces.idx.buffer, 0, bytemuck::cast_slice(faces_idx));
            self.gpu.queue().write_buffer(&faces.fvid.buffer, 0, bytemuck::cast_slice(faces_fvid));
            self.gpu.queue().write_buffer(&faces.owner.buffer, 0, bytemuck::cast_slice(&owner));
        }
        self.n = n as u32;
        self.m = m as u32;
    }

    /// Active vertices and faces.
    pub fn counts(&self) -> (u32, u32) {
        (self.n, self.m)
    }

    /// With `true`, every pass waits until its second submission has run, so that
    /// [`Self::last_pass_ms`] can time it (a renderer would rather let it overlap).
    pub fn set_profiling(&mut self, on: bool) {
        self.profile = on;
    }

    /// Milliseconds of the last pass: state update, collapses and scans up to the totals read
    /// back; then (when profiling) reorganisation, splits, index update and face compaction;
    /// and (when profiling) the state update and collapses alone, part of the first figure.
    pub fn last_pass_ms(&self) -> [f64; 3] {
        self.times
    }

    /// How many times a buffer was reallocated by the `n_alloc` policy so far.
    pub fn reallocations(&self) -> u64 {
        self.reallocations
    }

    /// Bytes of GPU memory the dynamic (per adapted mesh) buffers take now, at their capacities.
    pub fn dynamic_bytes(&self) -> u64 {
        let sets: u64 =
            self.sets.iter().map(|s| s.fvid.buffer.size() + s.next.buffer.size() + s.node.buffer.size()).sum();
        let faces = self.faces.idx.buffer.size() + self.faces.fvid.buffer.size() + self.faces.owner.buffer.size();
        let tmp = self.vcnt.buffer.size() + self.fcnt.buffer.size() + self.list.buffer.size() + self.hole.buffer.size();
        let levels: u64 = self.levels.iter().map(|l| l.sums.buffer.size()).sum();
        sets + faces + tmp + levels
    }

    /// Bytes of the static (per progressive mesh) buffers: decoded split records, their faces,
    /// and positions and normals per FVID.
    pub fn static_bytes(&self) -> u64 {
        self.shared.splits.size() + self.shared.split_faces.size() + self.shared.points.size()
    }

    /// One adaptation pass for `view` (Algorithms 1 to 5).
    pub fn adapt(&mut self, view: &Viewpoint) -> Result<PassStats, AdaptError> {
        self.pass(Some(view))
    }

    /// One pass that splits every vertex that can split and collapses nothing (the CPU
    /// reference's `refine_step`).
    pub fn refine_step(&mut self) -> Result<PassStats, AdaptError> {
        self.pass(None)
    }

    /// Applies every split: [`Self::refine_step`] until no vertex can split; returns the number
    /// of passes that split (as the CPU reference's `refine_fully`).
    pub fn refine_fully(&mut self) -> Result<usize, AdaptError> {
        let mut passes = 0;
        while self.refine_step()?.splits > 0 {
            passes += 1;
        }
        Ok(passes)
    }

    /// Passes until one changes nothing, at most `max_passes`; returns the number of passes
    /// that changed something, or `None` if still not converged.
    pub fn adapt_until_converged(&mut self, view: &Viewpoint, max_passes: usize) -> Result<Option<usize>, AdaptError> {
        for k in 0..max_passes {
            if self.adapt(view)?.converged() {
                return Ok(Some(k));
            }
        }
        Ok(None)
    }

    fn pass(&mut self, view: Option<&Viewpoint>) -> Result<PassStats, AdaptError> {
        let gpu = self.gpu.clone();
        gpu.scoped(|| self.pass_unscoped(view))
    }

    fn pass_unscoped(&mut self, view: Option<&Viewpoint>) -> Result<PassStats, AdaptError> {
        let pass_start = std::time::Instant::now();
        self.times = [0.0; 3];
        let (n, m) = (self.n, self.m);
        let unchanged = PassStats { vertices: n as usize, faces: m as usize, ..Default::default() };
        if n == 0 {
            return Ok(unchanged);
        }
        let na = self.n_alloc as u64;
        // Temporaries hold n + 1 counts (the last one the scan's total).
        if needs_resize(self.vcnt.cap, n as u64 + 1, self.n_alloc) {
            let cap = n as u64 + 1 + na;
            self.vcnt = storage(self.gpu.device(), "pm: vertex counts", cap, 4, VERTEX_USAGE);
            self.fcnt = storage(self.gpu.device(), "pm: face counts", cap, 4, VERTEX_USAGE);
            self.list = storage(self.gpu.device(), "pm: split list", cap, 4, VERTEX_USAGE);
            self.reallocations += 1;
        }
        self.prepare_scan(n as u64 + 1);
        let mut params = Params { n, m, mode: 1, ..Default::default() };
        if let Some(v) = view {
            params.mode = 0;
            params.planes = v.planes().map(|p| p.to_array());
            params.eye = [v.eye.x, v.eye.y, v.eye.z, 1.0];
            params.pixels_per_unit = v.pixels_per_unit;
            params.error_px = v.error_px;
            params.c_lod = v.c_lod;
            params.attribute_scale = v.attribute_scale;
        }
        self.gpu.queue().write_buffer(&self.params, 0, bytemuck::bytes_of(&params));

        // Submission 1: state update, collapses, scans, and the totals read back.
        let mut enc =
            self.gpu.device().create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pm: classify") });
        enc.clear_buffer(&self.stats, 0, None);
        {
            let set = &self.sets[self.cur];
            let p = &self.shared.pipelines;
            let state = self.bind(
                &p.state,
                &[
                    &self.params,
                    &self.shared.splits,
                    &self.shared.points,
                    &set.fvid.buffer,
                    &set.next.buffer,
                    &set.node.buffer,
                    &self.vcnt.buffer,
                    &self.fcnt.buffer,
                ],
            );
            let collapse = self.bind(
                &p.collapse,
                &[
                    &self.params,
                    &self.shared.splits,
                    &set.next.buffer,
                    &set.node.buffer,
                    &self.vcnt.buffer,
                    &self.stats,
                ],
            );
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("pm: classify"),
                timestamp_writes: None,
            });
            self.dispatch(&mut pass, &p.state, &state, n + 1);
            self.dispatch(&mut pass, &p.collapse, &collapse, n);
        }
        if self.profile {
            // Time the state update and collapses apart from the scans.
            self.gpu.wait_for(self.gpu.queue().submit([enc.finish()]))?;
            self.times[2] = pass_start.elapsed().as_secs_f64() * 1e3;
            enc =
                self.gpu.device().create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pm: scans") });
        }
        {
            let mut pass = enc
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("pm: scans"), timestamp_writes: None });
            self.scan(&mut pass, &self.vcnt.buffer);
            self.scan(&mut pass, &self.fcnt.buffer);
        }
        enc.copy_buffer_to_buffer(&self.vcnt.buffer, n as u64 * 4, &self.readback, 0, 4);
        enc.copy_buffer_to_buffer(&self.fcnt.buffer, n as u64 * 4, &self.readback, 4, 4);
        enc.copy_buffer_to_buffer(&self.stats, 0, &self.readback, 8, STATS_BYTES);
        self.gpu.queue().submit([enc.finish()]);
        let totals = self.read_totals()?;
        self.times[0] = pass_start.elapsed().as_secs_f64() * 1e3;
        let (n_new, f_add) = (totals[0], totals[1]);
        let counters = &totals[2..];
        let (collapses, cancelled, removed) =
            (counters[STAT_COLLAPSES], counters[STAT_CANCELLED], counters[STAT_REMOVED_FACES]);
        let splits = (n_new + collapses).checked_sub(n).ok_or(AdaptError::InconsistentTotals {
            vertices: n,
            after: n_new,
            collapses,
        })?;
        if splits == 0 && collapses == 0 {
            return Ok(PassStats { cancelled: cancelled as usize, ..unchanged });
        }
        let m_new = m - removed + f_add;

        // Memory management (section 5.3): the other vertex set receives the reorganised
        // vertices, so it is reallocated without copying; the face buffers keep their content.
        let dst = 1 - self.cur;
        if needs_resize(self.sets[dst].fvid.cap, n_new as u64, self.n_alloc) {
            let cap = n_new as u64 + na;
            self.sets[dst] = VertexSet::new(self.gpu.device(), if dst == 0 { "A" } else { "B" }, cap);
            self.reallocations += 1;
        }
        let total = m as u64 + f_add as u64;
        if self.faces.idx.cap < total {
            self.resize_faces(total + na, m as u64);
        }
        if self.hole.cap < removed as u64 {
            self.hole = storage(self.gpu.device(), "pm: face holes", removed as u64 + na, 4, VERTEX_USAGE);
            self.reallocations += 1;
        }
        params.n_new = n_new;
        params.f_add = f_add;
        params.m_new = m_new;
        params.splits = splits;
        self.gpu.queue().write_buffer(&self.params, 0, bytemuck::bytes_of(&params));

        // Submission 2: reorganisation, splits, index update, face compaction.
        let mut enc =
            self.gpu.device().create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pm: apply") });
        {
            let (src, dstset) = (&self.sets[self.cur], &self.sets[dst]);
            let (p, f) = (&self.shared.pipelines, &self.faces);
            let reorganise = self.bind(
                &p.reorganise,
                &[
                    &self.params,
                    &self.shared.splits,
                    &src.fvid.buffer,
                    &src.next.buffer,
                    &src.node.buffer,
                    &self.vcnt.buffer,
                    &dstset.fvid.buffer,
                    &dstset.next.buffer,
                    &dstset.node.buffer,
                ],
            );
            let compact =
                self.bind(&p.compact_splits, &[&self.params, &self.vcnt.buffer, &self.list.buffer, &self.stats]);
            let split = self.bind(
                &p.split,
                &[
                    &self.params,
                    &self.shared.splits,
                    &self.shared.split_faces,
                    &src.next.buffer,
                    &self.vcnt.buffer,
                    &self.fcnt.buffer,
                    &self.list.buffer,
                    &dstset.fvid.buffer,
                    &f.idx.buffer,
                    &f.fvid.buffer,
                    &f.owner.buffer,
                ],
            );
            let index = self.bind(
                &p.index_update,
                &[
                    &self.params,
                    &src.node.buffer,
                    &self.vcnt.buffer,
                    &dstset.fvid.buffer,
                    &f.idx.buffer,
                    &f.fvid.buffer,
                    &f.owner.buffer,
                ],
            );
            let holes = self.bind_at(
                &p.holes,
                &[(0, &self.params), (3, &f.owner.buffer), (4, &self.hole.buffer), (5, &self.stats)],
            );
            let fill = self.bind(
                &p.fill,
                &[&self.params, &f.idx.buffer, &f.fvid.buffer, &f.owner.buffer, &self.hole.buffer, &self.stats],
            );
            let mut pass = enc
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("pm: apply"), timestamp_writes: None });
            self.dispatch(&mut pass, &p.reorganise, &reorganise, n);
            self.dispatch(&mut pass, &p.compact_splits, &compact, n);
            self.dispatch(&mut pass, &p.split, &split, splits);
            self.dispatch(&mut pass, &p.index_update, &index, m);
            self.dispatch(&mut pass, &p.holes, &holes, m_new);
            self.dispatch(&mut pass, &p.fill, &fill, m + f_add - m_new);
        }
        self.gpu.queue().submit([enc.finish()]);
        if self.profile {
            self.gpu.wait_for(self.gpu.queue().submit([]))?;
            self.times[1] = pass_start.elapsed().as_secs_f64() * 1e3 - self.times[0];
        }
        if needs_resize(self.faces.idx.cap, m_new as u64, self.n_alloc) {
            self.resize_faces(m_new as u64 + na, m_new as u64);
        }
        self.cur = dst;
        self.n = n_new;
        self.m = m_new;
        Ok(PassStats {
            splits: splits as usize,
            collapses: collapses as usize,
            cancelled: cancelled as usize,
            vertices: n_new as usize,
            faces: m_new as usize,
        })
    }

    /// Reallocates the face buffers to `cap` faces, keeping the first `keep`.
    fn resize_faces(&mut self, cap: u64, keep: u64) {
        let d = self.gpu.device();
        let new = FaceSet::new(d, cap);
        if keep > 0 {
            let mut enc = d.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pm: face resize") });
            enc.copy_buffer_to_buffer(&self.faces.idx.buffer, 0, &new.idx.buffer, 0, keep * 12);
            enc.copy_buffer_to_buffer(&self.faces.fvid.buffer, 0, &new.fvid.buffer, 0, keep * 12);
            enc.copy_buffer_to_buffer(&self.faces.owner.buffer, 0, &new.owner.buffer, 0, keep * 4);
            self.gpu.queue().submit([enc.finish()]);
        }
        self.faces = new;
        self.reallocations += 1;
    }

    /// Sizes the block-sum buffers of the scan levels for `count` elements and writes each
    /// level's count.
    fn prepare_scan(&mut self, count: u64) {
        let mut counts = vec![count];
        while *counts.last().expect("non-empty") > SCAN_BLOCK as u64 {
            counts.push(counts.last().expect("non-empty").div_ceil(SCAN_BLOCK as u64));
        }
        while self.levels.len() < counts.len() {
            let k = self.levels.len();
            let uniform = self.gpu.device().create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("pm: scan level {k}")),
                size: 16,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            self.levels.push(ScanLevel {
                sums: storage(self.gpu.device(), "pm: scan sums", 0, 4, VERTEX_USAGE),
                uniform,
                blocks: 0,
            });
        }
        self.levels.truncate(counts.len());
        for (level, &c) in self.levels.iter_mut().zip(&counts) {
            let blocks = c.div_ceil(SCAN_BLOCK as u64);
            if level.sums.cap < blocks {
                level.sums = storage(self.gpu.device(), "pm: scan sums", blocks * 2, 4, VERTEX_USAGE);
            }
            level.blocks = blocks as u32;
            self.gpu.queue().write_buffer(&level.uniform, 0, bytemuck::cast_slice(&[c as u32, 0, 0, 0]));
        }
    }

    /// Exclusive scan of `data` in place over the levels set by [`Self::prepare_scan`].
    fn scan(&self, pass: &mut wgpu::ComputePass<'_>, data: &wgpu::Buffer) {
        let p = &self.shared.pipelines;
        let mut adds = Vec::with_capacity(self.levels.len());
        // Down: scan each level's blocks, the block sums becoming the next level's data.
        for (k, level) in self.levels.iter().enumerate() {
            let input = if k == 0 { data } else { &self.levels[k - 1].sums.buffer };
            let buffers = [&level.uniform, input, &level.sums.buffer];
            self.dispatch_groups(pass, &p.scan_blocks, &self.bind(&p.scan_blocks, &buffers), level.blocks);
            adds.push(buffers);
        }
        // Up: add the scanned block sums back (the top level is a single block).
        for (level, buffers) in self.levels.iter().zip(&adds).rev().skip(1) {
            self.dispatch_groups(pass, &p.add_blocks, &self.bind(&p.add_blocks, buffers), level.blocks);
        }
    }

    fn bind(&self, pipeline: &Stage, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        let entries: Vec<(u32, &wgpu::Buffer)> = buffers.iter().enumerate().map(|(i, &b)| (i as u32, b)).collect();
        self.bind_at(pipeline, &entries)
    }

    fn bind_at(&self, pipeline: &Stage, buffers: &[(u32, &wgpu::Buffer)]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .map(|&(binding, b)| wgpu::BindGroupEntry { binding, resource: b.as_entire_binding() })
            .collect();
        self.gpu.device().create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.layout,
            entries: &entries,
        })
    }

    /// Dispatches one thread per element, `threads` in all (nothing for zero).
    fn dispatch(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        pipeline: &wgpu::ComputePipeline,
        bg: &wgpu::BindGroup,
        threads: u32,
    ) {
        self.dispatch_groups(pass, pipeline, bg, threads.div_ceil(WG));
    }

    /// Dispatches `groups` workgroups, in two dimensions beyond the per-dimension limit.
    fn dispatch_groups(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        pipeline: &wgpu::ComputePipeline,
        bg: &wgpu::BindGroup,
        groups: u32,
    ) {
        if groups == 0 {
            return;
        }
        let x = groups.min(self.shared.max_groups);
        let y = groups.div_ceil(x);
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, bg, &[]);
        pass.dispatch_workgroups(x, y, 1);
    }

    fn read_totals(&self) -> Result<[u32; 10], GpuError> {
        self.gpu.map_read(&self.readback, READBACK_BYTES, |mapped| {
            let mut out = [0u32; 10];
            out.copy_from_slice(bytemuck::cast_slice(mapped));
            out
        })
    }

    /// Reads a buffer's first `bytes` bytes back (tests and `pm adapt --gpu`; not the render path).
    fn read_buffer(&self, buffer: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
        self.gpu.read_buffer("pm: read back", buffer, bytes)
    }

    /// Active vertex FVIDs, ascending (read back).
    pub fn active(&self) -> Result<Vec<u32>, AdaptError> {
        let bytes = self.read_buffer(&self.sets[self.cur].fvid.buffer, self.n as u64 * 4)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }

    /// The current faces as indices into [`Self::active`] (read back; the order is the GPU's).
    pub fn faces(&self) -> Result<Vec<[u32; 3]>, AdaptError> {
        let bytes = self.read_buffer(&self.faces.idx.buffer, self.m as u64 * 12)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }

    /// The current faces as FVID triples of active vertices (read back), for comparison with
    /// [`codec::pm::Adapter::face_fvids`].
    pub fn face_fvids(&self) -> Result<Vec<[u32; 3]>, AdaptError> {
        let active = self.active()?;
        self.faces()?
            .into_iter()
            .map(|t| {
                let mut out = [0u32; 3];
                for (o, i) in out.iter_mut().zip(t) {
                    *o = *active.get(i as usize).ok_or(AdaptError::FaceIndex { index: i, vertices: active.len() })?;
                }
                Ok(out)
            })
            .collect()
    }

    /// The current mesh, for [`crate::render::Renderer::render_pm`]: the FVID buffer of the
    /// active vertices, the per-FVID points, and the face index buffer, all on the device.
    pub fn mesh(&self) -> AdaptedMesh<'_> {
        AdaptedMesh {
            fvid: &self.sets[self.cur].fvid.buffer,
            points: &self.shared.points,
            indices: &self.faces.idx.buffer,
            index_count: self.m * 3,
        }
    }
}

/// The base mesh as the adapter's initial buffers: FVIDs, next splits, face indices, face FVIDs.
type BaseState = (Vec<u32>, Vec<u32>, Vec<[u32; 3]>, Vec<[u32; 3]>);

/// Builds the [`BaseState`] of `pm`.
fn base_state(pm: &ProgressiveMesh, tree: &SplitTree) -> BaseState {
    let fvid = pm.base_vertices.clone();
    let idx =
        pm.base_faces.iter().map(|t| t.map(|f| fvid.partition_point(|&x| x <= f).saturating_sub(1) as u32)).collect();
    (fvid, tree.roots.clone(), idx, pm.base_faces.clone())
}
