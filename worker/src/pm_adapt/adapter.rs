//! [`GpuAdapter`]: the adaptation state of one progressive mesh on the GPU, its buffers, and
//! the frame-level calls (set the view, adapt, hand the renderer its mesh).

use std::sync::Arc;

use codec::pm::format::{Dpm, NodeFile, OpContext};
use codec::pm::{CacheStats, NodeCache, PassStats, Viewpoint, LEVELS_PER_PASS, NONE};

use super::buffers::{
    init, needs_resize, pack_pn, storage, unpack_position, FaceSet, GpuVState, Params, ScanLevel, Sized, VertexSet,
    ERRORS_BYTES, PENDING, QUEUE_BYTES, READBACK_BYTES, SC_FACE_BYTES, SC_LEAF_BYTES, SC_SPLIT_BYTES, STATE_BYTES,
    STATS_BYTES, VERTEX_USAGE,
};
use super::decoder::{decoder_data, slot_bytes, slots_within};
use super::nodes::NodePool;
use super::occlusion::Occluder;
use super::pipelines::Pipelines;
use super::settings::{MemoryBudget, Tuning};
use crate::gpu::{Gpu, GpuError};
use crate::render::{AdaptedMesh, PmPoint};

use super::error::AdaptError;
use super::limits::{RESUME_VECS, STACK_WORDS};

/// The count's scratch area for `k` leaves (and `k` splits, `3 k` faces): the records, and
/// the faces.
pub(super) fn scratch_buffers(d: &wgpu::Device, k: u64) -> (Sized, Sized) {
    (
        storage(d, "pm: count scratch", k * (SC_LEAF_BYTES + SC_SPLIT_BYTES) / 16, 16, VERTEX_USAGE),
        storage(d, "pm: count scratch faces", 3 * k, SC_FACE_BYTES, VERTEX_USAGE),
    )
}

/// The labels of the all-levels marks ([`GpuAdapter`]'s `marks`).
pub(super) const MARKS: [&str; 4] = ["pm: undone ranges", "pm: region reach", "pm: undone starts", "pm: region roots"];

/// Where an out-of-core adapter reads its nodes and how many it keeps.
pub struct OutOfCore {
    /// The file, open for reading nodes ([`NodeFile::open`]).
    pub file: Arc<NodeFile>,
    /// Bytes of graphics memory for nodes: the pool holds this many bytes' worth of slots
    /// of the largest node's size. (The whole adapter's memory is bounded by
    /// [`GpuAdapter::set_budget`].)
    pub pool_bytes: u64,
    /// Read nodes on a thread of their own (the paper's); else while scheduling.
    pub background: bool,
}

/// An out-of-core adapter's nodes: the cache that decides (on the host) and the pool that
/// follows it (on the GPU).
pub(super) struct Resident {
    pub(super) cache: NodeCache,
    pub(super) pool: NodePool,
    /// Node bytes uploaded to the pool so far.
    pub(super) uploaded: u64,
}

/// The adaptation state of one progressive mesh on the GPU (see the module docs).
pub struct GpuAdapter {
    pub(super) gpu: Gpu,
    /// Pipelines and static data, shared by every adapter of the same mesh on this device.
    pub(super) shared: Arc<Shared>,
    pub(super) n_alloc: u32,
    pub(super) params: wgpu::Buffer,
    pub(super) stats: wgpu::Buffer,
    /// The first operation that failed to decode ([`buffers::Errors`]).
    pub(super) errors: wgpu::Buffer,
    pub(super) readback: wgpu::Buffer,
    pub(super) sets: [VertexSet; 2],
    pub(super) cur: usize,
    pub(super) faces: FaceSet,
    pub(super) vcnt: Sized,
    pub(super) fcnt: Sized,
    pub(super) list: Sized,
    pub(super) hole: Sized,
    /// An all-levels pass's marks (`state.wgsl`): `diff`, `reach`, `up`, `root`.
    pub(super) marks: [Sized; 4],
    /// How passes are run: levels, descent budget, rounds, limits, profiling.
    pub(super) tuning: Tuning,
    /// An all-levels pass's descent stacks (`descent.wgsl`): [`STACK_WORDS`] words an entry,
    /// min([`LEVELS_PER_PASS`], descent budget) entries a slot, one slot a descent running;
    /// grown to the descents of a pass (on a software adapter to [`SOFTWARE_DESCENT_SLOTS`])
    /// up to [`Self::stack_max_bytes`]; the slots take the descents from a queue.
    pub(super) stack: Sized,
    /// The slots (threads) of this pass's descents, and their queues ([`buffers::Queue`]).
    pub(super) slots: u32,
    pub(super) queue: wgpu::Buffer,
    /// The steps of the last count's descents in all and the most of one (they size the
    /// rounds of `descend`).
    pub(super) steps: u64,
    pub(super) most: u64,
    /// Whether this pass's classification ran `count` (its loop-limit failure can be retried).
    pub(super) count_ran: bool,
    /// The count's scratch area (`state.wgsl`, `place.wgsl`): leaf and split records, and the
    /// splits' faces; what it holds (leaves, splits, faces) and what the last count kept
    /// (more than it holds: the pass walks the descents again instead).
    pub(super) scratch: Sized,
    pub(super) sc_faces: Sized,
    pub(super) sc_cap: [u32; 3],
    pub(super) sc_kept: [u32; 3],
    /// The vertices that descended in the last pass ([`Self::last_descents`]).
    pub(super) descents: u32,
    /// With the default kind of pass ([`Tuning::mixed`]): one level for the rest of a view
    /// once an all-levels pass for it descended deep (`deep`, [`DEEP_DESCENT`]), unless the
    /// view then took [`DEEP_PASSES`] one-level passes that changed the mesh (`deep_passes`;
    /// `deep_tree`: all levels for the rest of the view).
    pub(super) deep: bool,
    pub(super) deep_passes: u32,
    pub(super) deep_tree: bool,
    /// Per scan level, for the current pass ([`GpuAdapter::prepare_scan`]).
    pub(super) scan_levels: Vec<ScanLevel>,
    /// Active vertices and faces.
    pub(super) n: u32,
    pub(super) m: u32,
    pub(super) reallocations: u64,
    /// Milliseconds of the last pass: classification (to the totals read back), application.
    pub(super) times: [f64; 3],
    /// Out of core: the resident nodes.
    pub(super) resident: Option<Resident>,
    /// The occlusion pyramid of the state update (`occ`; one word when off), and the
    /// occluder it was uploaded from (`None`: off), whose parameters every pass writes and
    /// whose test ranks hidden nodes last out of core.
    pub(super) occ: Sized,
    pub(super) occluder: Option<Occluder>,
    /// The graphics memory budget and the error scale that keeps the mesh within it.
    pub(super) memory: MemoryBudget,
}

/// What adapters of the same progressive mesh share: the pipelines, the static buffers (the
/// compressed operations, the decoder's tables and parameters), and the base mesh.
pub(super) struct Shared {
    pub(super) pipelines: Pipelines,
    pub(super) max_groups: u32,
    pub(super) ops: wgpu::Buffer,
    pub(super) tables: wgpu::Buffer,
    pub(super) decode: wgpu::Buffer,
    pub(super) base: BaseState,
}

impl GpuAdapter {
    /// Uploads `dpm`'s compressed operations and decoding tables to `gpu`'s device and starts
    /// at the base mesh (whose operations' criteria the CPU decodes: a few per component).
    /// `n_alloc` is the paper's reallocation slack in elements ([`DEFAULT_N_ALLOC`](super::DEFAULT_N_ALLOC)).
    pub fn new(gpu: &Gpu, dpm: &Dpm, n_alloc: u32) -> Result<GpuAdapter, AdaptError> {
        if dpm.out_of_core() {
            return Err(AdaptError::WrongLayout(
                "an out-of-core .dpm (built with --node-kb) needs a GPU budget for its nodes",
            ));
        }
        Self::make(gpu, dpm, n_alloc, None)
    }

    /// An adapter of an out-of-core file (`dpm` its head, [`Dpm::parse_prefix`]): its nodes
    /// come from `ooc.file` as [`Self::schedule`] asks for them and stay within
    /// `ooc.pool_bytes` of graphics memory, a pool of slots of the largest node's size,
    /// chosen by the paper's priority ([`NodeCache`]). It starts at the base mesh with every
    /// operation pending; a vertex splits once its operation's node is resident.
    pub fn out_of_core(gpu: &Gpu, dpm: &Dpm, ooc: OutOfCore, n_alloc: u32) -> Result<GpuAdapter, AdaptError> {
        if !dpm.out_of_core() {
            return Err(AdaptError::WrongLayout("an in-core .dpm has no nodes to keep within a GPU budget"));
        }
        let slot = slot_bytes(dpm);
        // At most one slot per node, and within what one binding and a 32-bit address allow.
        let limit = gpu.device().limits().max_storage_buffer_binding_size.min(u32::MAX as u64);
        let slots = slots_within(dpm, ooc.pool_bytes.min(limit));
        if slots == 0 {
            return Err(AdaptError::Budget { budget: ooc.pool_bytes, slot_bytes: slot });
        }
        let cache = NodeCache::with_slots(dpm, ooc.file, slots as u64, slot as u64, ooc.background);
        Self::make(gpu, dpm, n_alloc, Some((cache, slots)))
    }

    fn make(gpu: &Gpu, dpm: &Dpm, n_alloc: u32, nodes: Option<(NodeCache, u32)>) -> Result<GpuAdapter, AdaptError> {
        let limits = gpu.device().limits();
        let need = super::pipelines::storage_buffers_per_stage()?;
        if limits.max_storage_buffers_per_shader_stage < need {
            return Err(AdaptError::TooFewStorageBuffers {
                need,
                allowed: limits.max_storage_buffers_per_shader_stage,
            });
        }
        let base = base_state(dpm)?;
        let (words, params) = decoder_data(dpm);
        gpu.scoped(|| {
            let device = gpu.device();
            let read_only = wgpu::BufferUsages::STORAGE;
            // Out of core the page table at the tables' end changes between passes.
            let tables_usage = read_only | wgpu::BufferUsages::COPY_DST;
            let tables = init(device, "pm: decoding tables", bytemuck::cast_slice(&words), tables_usage);
            let (ops, resident) = match nodes {
                None => (init(device, "pm: operations", dpm.ops, read_only), None),
                Some((cache, slots)) => {
                    let pool =
                        NodePool::new(device, dpm.nodes.len(), slots, params.slot_bytes, params.lens_at + params.nodes);
                    (pool.ops.clone(), Some(Resident { cache, pool, uploaded: 0 }))
                }
            };
            let decode = init(device, "pm: decode params", bytemuck::bytes_of(&params), wgpu::BufferUsages::STORAGE);
            let shared = Arc::new(Shared {
                pipelines: Pipelines::new(gpu)?,
                max_groups: limits.max_compute_workgroups_per_dimension,
                ops,
                tables,
                decode,
                base,
            });
            Ok(GpuAdapter::with_shared(gpu.clone(), shared, n_alloc.max(1), resident))
        })
    }

    /// A new adapter at the base mesh.
    fn with_shared(gpu: Gpu, shared: Arc<Shared>, n_alloc: u32, resident: Option<Resident>) -> GpuAdapter {
        let d = gpu.device();
        let (scratch, sc_faces) = scratch_buffers(d, 0);
        let mut adapter = GpuAdapter {
            shared,
            n_alloc,
            params: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pm: params"),
                size: std::mem::size_of::<Params>() as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            stats: storage(d, "pm: stats", STATS_BYTES / 4, 4, VERTEX_USAGE).buffer,
            errors: storage(d, "pm: errors", ERRORS_BYTES / 4, 4, VERTEX_USAGE).buffer,
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
            marks: MARKS.map(|name| storage(d, name, 0, 4, VERTEX_USAGE)),
            stack: storage(d, "pm: descent stacks", 0, 4, VERTEX_USAGE),
            slots: 0,
            steps: 0,
            most: 0,
            count_ran: false,
            scratch,
            sc_faces,
            sc_cap: [0; 3],
            sc_kept: [0; 3],
            queue: storage(d, "pm: descent queues", QUEUE_BYTES / 4, 4, VERTEX_USAGE).buffer,
            descents: 0,
            deep: false,
            deep_passes: 0,
            deep_tree: false,
            tuning: Tuning::for_adapter(gpu.is_software()),
            scan_levels: Vec::new(),
            n: 0,
            m: 0,
            reallocations: 0,
            times: [0.0; 3],
            resident,
            occ: storage(d, "pm: occlusion pyramid", 4, 4, VERTEX_USAGE),
            occluder: None,
            memory: MemoryBudget::default(),
            gpu,
        };
        adapter.reset();
        adapter
    }

    /// Goes back to the base mesh.
    pub fn reset(&mut self) {
        (self.deep, self.deep_passes, self.deep_tree) = (false, 0, false);
        let shared = self.shared.clone();
        let base = &shared.base;
        let (n, m) = (base.fvid.len() as u64, base.face_idx.len() as u64);
        let owner = vec![NONE; base.face_idx.len()];
        self.cur = 0;
        let na = self.n_alloc as u64;
        if needs_resize(self.sets[0].fvid.cap, n, self.n_alloc) {
            self.sets[0] = VertexSet::new(self.gpu.device(), "A", n + na);
        }
        let set = &self.sets[0];
        let q = self.gpu.queue();
        if n > 0 {
            q.write_buffer(&set.fvid.buffer, 0, bytemuck::cast_slice(&base.fvid));
            q.write_buffer(&set.state.buffer, 0, bytemuck::cast_slice(&base.state));
            q.write_buffer(&set.point.buffer, 0, bytemuck::cast_slice(&base.point));
        }
        if needs_resize(self.faces.idx.cap, m, self.n_alloc) {
            self.faces = FaceSet::new(self.gpu.device(), m + na);
        }
        let faces = &self.faces;
        if m > 0 {
            q.write_buffer(&faces.idx.buffer, 0, bytemuck::cast_slice(&base.face_idx));
            q.write_buffer(&faces.fvid.buffer, 0, bytemuck::cast_slice(&base.face_fvid));
            q.write_buffer(&faces.owner.buffer, 0, bytemuck::cast_slice(&owner));
        }
        q.write_buffer(&self.errors, 0, bytemuck::bytes_of(&[0u32; 2]));
        self.n = n as u32;
        self.m = m as u32;
    }

    /// Active vertices and faces.
    pub fn counts(&self) -> (u32, u32) {
        (self.n, self.m)
    }

    /// Milliseconds of the last pass: state update, collapses and scans up to the totals read
    /// back; then (when profiling) reorganisation, splits, index update and face compaction;
    /// and (when profiling) the state update and collapses alone, part of the first figure.
    pub fn last_pass_ms(&self) -> [f64; 3] {
        self.times
    }

    /// The vertices that descended in the last pass (all levels; 0 in a one-level pass), and
    /// the slots it ran them in (threads, each taking the next descent whenever it finished
    /// one).
    pub fn last_descents(&self) -> (u32, u32) {
        (self.descents, self.slots)
    }

    /// How many times a buffer was reallocated by the `n_alloc` policy so far.
    pub fn reallocations(&self) -> u64 {
        self.reallocations
    }

    /// Grows the count's scratch area to hold `kept` (leaves, splits, faces) with a quarter
    /// more ([`Self::scratch_size`]); never shrinks it.
    pub(super) fn grow_scratch(&mut self, kept: [u32; 3]) {
        if let Some(k) = self.scratch_size(kept) {
            (self.scratch, self.sc_faces) = scratch_buffers(self.gpu.device(), k);
            self.sc_cap = [k as u32, k as u32, 3 * k as u32];
            self.reallocations += 1;
        }
    }

    /// The leaves (with as many splits and three faces each) a scratch area for `kept` takes,
    /// a quarter more than `kept` within [`MAX_SCRATCH_BYTES`] (and a 64th of the budget);
    /// `None` where the area holds them or cannot grow.
    fn scratch_size(&self, kept: [u32; 3]) -> Option<u64> {
        if kept.iter().zip(&self.sc_cap).all(|(k, c)| k <= c) {
            return None;
        }
        let max = self.scratch_max_bytes(self.memory.bytes);
        let per_leaf = SC_LEAF_BYTES + SC_SPLIT_BYTES + 3 * SC_FACE_BYTES;
        // A leaf each split and descent, three faces a split: sized by the leaves, the most
        // numerous, or what the faces need.
        let want = (kept[0].max(kept[1]) as u64).max((kept[2] as u64).div_ceil(3)) * 5 / 4;
        let k = want.min(max / per_leaf);
        (k > self.sc_cap[0] as u64).then_some(k)
    }

    /// Bytes of one descent's slot: its stack, min(LEVELS_PER_PASS, descent budget) entries
    /// (a descent pushes one per split, at most one per level), and its resume record.
    pub(super) fn stack_slot_bytes(&self) -> u64 {
        LEVELS_PER_PASS.min(self.tuning.descent_budget) as u64 * STACK_WORDS * 4 + RESUME_VECS * 16
    }

    /// Where the resume records of the pass's slots start in the stacks' buffer, and their
    /// bytes.
    pub(super) fn resume_range(&self) -> (u64, u64) {
        let slots = self.slots as u64;
        let records = slots * RESUME_VECS * 16;
        (slots * self.stack_slot_bytes() - records, records)
    }

    /// The most bytes the descent stacks may take under `budget`: the stack limit
    /// ([`Self::set_stack_limit`]), at most a 64th of the budget, at least one slot.
    pub(super) fn stack_max_bytes(&self, budget: Option<u64>) -> u64 {
        let cap = budget.map_or(self.tuning.stack_limit, |b| (b / 64).min(self.tuning.stack_limit));
        let slot = self.stack_slot_bytes();
        (cap / slot).max(1) * slot
    }

    /// Descents the stacks hold at once now (at least the pass's slots).
    pub(super) fn stack_slots(&self) -> u32 {
        (self.stack.cap * 4 / self.stack_slot_bytes()) as u32
    }

    /// Fails if an operation did not decode in the last pass (a pass checks the one before
    /// it; this checks the last, for a caller about to draw).
    pub fn check(&self) -> Result<(), AdaptError> {
        let bytes = self.read_buffer(&self.errors, ERRORS_BYTES)?;
        let e: [u32; 2] = bytemuck::pod_read_unaligned(&bytes);
        if e[0] != 0 {
            return Err(AdaptError::corrupt(e[0], e[1], self.resident.is_some()));
        }
        Ok(())
    }

    /// Culls with `occluder` from the next pass on (the depth of a frame drawn from this
    /// adapter's mesh: occlusion one frame late, see [`occlusion`](super::occlusion)); `None` turns it off.
    /// A pyramid that would take the adapter past its budget is not kept (culling is off
    /// until one fits).
    pub fn set_occluder(&mut self, occluder: Option<Occluder>) {
        if let Some(o) = &occluder {
            let n = o.words.len() as u64;
            if let Some(b) = self.memory.bytes {
                let grow = (n * 2 * 4).saturating_sub(self.occ.buffer.size());
                if self.occ.cap < n && self.gpu_bytes() + grow > b {
                    self.occluder = None;
                    return;
                }
            }
            if self.occ.cap < n {
                self.occ = storage(self.gpu.device(), "pm: occlusion pyramid", n * 2, 4, VERTEX_USAGE);
            }
            self.gpu.queue().write_buffer(&self.occ.buffer, 0, bytemuck::cast_slice(&o.words));
        }
        self.occluder = occluder;
    }

    /// Out of core: ranks the nodes for `view` by the paper's priority (the nodes the occluder
    /// hides, if one is set, last) and asks for the ones the budget keeps (read by the loader
    /// thread, or now when not in the background); the passes that follow upload what has
    /// arrived. Call it once per frame. `None` in core.
    pub fn schedule(&mut self, view: &Viewpoint) -> Result<Option<CacheStats>, AdaptError> {
        // The nodes of the error the passes adapt to.
        let view = &Viewpoint { error_px: view.error_px * self.memory.error_scale, ..*view };
        match &mut self.resident {
            None => Ok(None),
            Some(r) => Ok(Some(match &self.occluder {
                None => r.cache.schedule(view)?,
                Some(o) => r
                    .cache
                    .schedule_culled(view, &|n| o.hides(glam::Vec3::from(n.bbox_min), glam::Vec3::from(n.bbox_max)))?,
            })),
        }
    }

    /// Out of core: waits until every node asked for has arrived (for a frame that must
    /// converge; the paper's renderer never waits). Nothing in core.
    pub fn wait_for_nodes(&mut self) -> Result<(), AdaptError> {
        if let Some(r) = &mut self.resident {
            r.cache.wait()?;
        }
        Ok(())
    }

    /// Out of core: nodes asked for and not arrived yet (0 in core).
    pub fn nodes_in_flight(&self) -> usize {
        self.resident.as_ref().map_or(0, |r| r.cache.in_flight())
    }

    /// Out of core: nodes resident now (0 in core).
    pub fn nodes_resident(&self) -> usize {
        self.resident.as_ref().map_or(0, |r| r.cache.resident_nodes().count())
    }

    /// Out of core: node bytes uploaded to graphics memory so far (the load traffic).
    pub fn uploaded_bytes(&self) -> u64 {
        self.resident.as_ref().map_or(0, |r| r.uploaded)
    }

    /// Out of core: bytes of graphics memory the node pool takes (0 in core).
    pub fn node_pool_bytes(&self) -> u64 {
        self.resident.as_ref().map_or(0, |r| r.pool.ops.size())
    }

    /// Out of core: the node pool's slots (what the budget holds).
    pub fn node_slots(&self) -> Option<u32> {
        self.resident.as_ref().map(|r| r.pool.slots())
    }

    /// Out of core: installs the nodes that have arrived and brings the pool and its page
    /// table in line with the cache, before a pass.
    pub(super) fn sync_nodes(&mut self) -> Result<(), AdaptError> {
        let Some(r) = &mut self.resident else { return Ok(()) };
        r.cache.install()?;
        let cache = &r.cache;
        let up = r.pool.sync(
            self.gpu.queue(),
            &self.shared.tables,
            cache.resident_nodes().map(|i| (i, cache.get(i).expect("resident"))),
        )?;
        r.uploaded += up;
        Ok(())
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

    /// Reads a buffer's first `bytes` bytes back (tests and `pm adapt --gpu`; not the render path).
    fn read_buffer(&self, buffer: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
        self.gpu.read_buffer("pm: read back", buffer, bytes)
    }

    /// Active vertex FVIDs, ascending (read back).
    pub fn active(&self) -> Result<Vec<u32>, AdaptError> {
        let bytes = self.read_buffer(&self.sets[self.cur].fvid.buffer, self.n as u64 * 4)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }

    /// The active vertices' quantized positions, in [`Self::active`]'s order (read back from
    /// their state; [`Dpm::position`] dequantizes them as the decoder does).
    pub fn quantized_positions(&self) -> Result<Vec<[u32; 3]>, AdaptError> {
        let bytes = self.read_buffer(&self.sets[self.cur].state.buffer, self.n as u64 * STATE_BYTES)?;
        let states: Vec<GpuVState> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(states.iter().map(|s| unpack_position(s.pn)).collect())
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

    /// The current mesh, for [`crate::render::Renderer::render_pm`]: the points of the
    /// active vertices and the face index buffer, on the device.
    pub fn mesh(&self) -> AdaptedMesh<'_> {
        AdaptedMesh {
            points: &self.sets[self.cur].point.buffer,
            indices: &self.faces.idx.buffer,
            index_count: self.m * 3,
        }
    }
}

/// The base mesh as the adapter's initial buffers.
pub(super) struct BaseState {
    pub(super) fvid: Vec<u32>,
    pub(super) state: Vec<GpuVState>,
    pub(super) point: Vec<PmPoint>,
    pub(super) face_idx: Vec<[u32; 3]>,
    pub(super) face_fvid: Vec<[u32; 3]>,
}

/// The base vertices with their first operations' criteria and face counts (decoded on the
/// CPU, as the GPU decodes the rest), and the base faces.
fn base_state(dpm: &Dpm) -> Result<BaseState, AdaptError> {
    let h = &dpm.header;
    let fvid = dpm.base_vertices.clone();
    let mut state = Vec::with_capacity(fvid.len());
    let mut point = Vec::with_capacity(fvid.len());
    for b in 0..fvid.len() {
        let v_end = fvid.get(b + 1).copied().unwrap_or(h.vertices);
        let (pos, nrm) = (dpm.base_positions[b], dpm.base_normals[b]);
        let mut s = GpuVState {
            v_end,
            addr: NONE,
            c_addr: NONE,
            c_v: NONE,
            c_v_end: NONE,
            pn: pack_pn(pos, nrm),
            ..GpuVState::default()
        };
        if let (Some(addr), true) = (dpm.roots[b], dpm.out_of_core()) {
            // Decoded by the node check once its node is resident.
            s.addr = addr as u32;
            s.flags = PENDING;
        } else if let Some(addr) = dpm.roots[b] {
            let ctx = OpContext { v: fvid[b], v_end, parent_criteria: [0; 4], position: pos, normal: nrm };
            let d = dpm.decode_op(addr, &ctx)?;
            let c = d.criteria;
            s.addr = addr as u32;
            s.faces = d.split.faces.len() as u32;
            s.crit = [c.sin_alpha, c.geometric_error, c.attribute_error, c.radius];
        }
        state.push(s);
        let (p, n) = (dpm.position(pos), dpm.normal(nrm));
        point.push(PmPoint { pos: [p[0], p[1], p[2], 1.0], nrm: [n[0], n[1], n[2], 0.0] });
    }
    let face_idx =
        dpm.base_faces.iter().map(|t| t.map(|f| fvid.partition_point(|&x| x <= f).saturating_sub(1) as u32)).collect();
    Ok(BaseState { fvid, state, point, face_idx, face_fvid: dpm.base_faces.clone() })
}
