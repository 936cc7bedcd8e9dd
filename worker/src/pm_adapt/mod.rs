//! View-dependent adaptation of a dependency-free progressive mesh on the GPU, straight from
//! the `.dpm`'s compressed operations: the stages of Algorithms 1 to 5 of E. Derzapf and M. Guthe,
//! "Dependency-Free Parallel Progressive Meshes", Computer Graphics Forum 31(8), 2012, as
//! WGSL compute pipelines (`worker/src/pm_adapt/shaders/*.wgsl`, one file per stage, `common.wgsl` prepended to
//! each but the generic scan, the operation decoder `decode.wgsl` to the reorganisation),
//! driven pass by pass from here. It keeps the state of [`codec::pm::DpmAdapter`] and reaches
//! the states of the CPU reference [`codec::pm::Adapter`]: same decisions, same triangle set
//! after every pass (tested in `worker/tests/pm_gpu.rs`).
//!
//! It runs on a [`Gpu`] and hands the renderer the adapted mesh as an [`AdaptedMesh`]
//! ([`GpuAdapter::mesh`]); it knows nothing else of the renderer. `buffers` holds the records
//! it shares with the WGSL (the structs' twins) and its `n_alloc`-sized buffers, `pipelines`
//! the stages with their binding tables, `decoder` the operation decoder's tables, and `pass`
//! one adaptation pass.
//!
//! What stays in graphics memory for a model is its compressed operations (the OPER section
//! as it is in the file), the distinct Huffman tables, 326 values and a few parameters: 1.01x
//! the dragon's `.dpm` (4.34 MB for 4.29 MB; it was 45.4 MB of decoded records, faces and
//! points, 10.6x). Everything else follows the adapted mesh.
//!
//! One [`GpuAdapter::adapt`] pass is two submissions:
//!
//! 1. state update (Algorithm 1), collapses (Algorithm 2, in place), and the work-efficient
//!    scans of the vertex and face counts; the totals, the collapse counters and the first
//!    decoding error of the pass before are then read back (48 bytes): the host needs them to
//!    size the buffers (the paper's `n_alloc` policy) and to size the remaining dispatches;
//! 2. vertex reorganisation (Algorithm 3) into the other of two vertex buffer sets, in which a
//!    splitting vertex decodes its operation (children, `v_u`'s position and normal, faces)
//!    and its children's operations up to their face counts (their split caches), split
//!    compaction, splits with binary search (Algorithm 4), index update (Algorithm 5) and the
//!    in-place face compaction (section 5.6).
//!
//! An all-levels pass ([`Levels::All`](codec::pm::Levels::All), the default on hardware; see `codec::pm::Adapter::pass_all_levels`)
//! replaces the state update and collapses by `mark` (the undone splits' ranges, the
//! vertices that split, listed), a read-back of their number, `count` (each listed vertex's
//! leaves and faces down its subtree, `descent.wgsl`), the scan of the ranges and `regions`
//! (the collapsing regions and the vertices carrying their operations); and the split
//! decoding and splits by `descend` (the same descents, writing the leaves and faces) and
//! `index_new` (the new faces' indices by binary search). Reorganisation gives a region's
//! first vertex the region's operation.
//!
//! The adapted mesh stays on the GPU between passes (temporal coherence). It is drawn straight
//! from these buffers: the face index buffer is the draw's index buffer, and the vertex shader
//! pulls each active vertex's position and normal (see `vs_pulled` in `worker/src/render.wgsl`),
//! so rendering reads nothing back.
//!
//! Where this differs from the paper:
//!
//! * A vertex carries its creator's operation (the split whose `v_u` is its FVID) with that
//!   operation's context, so that a collapse knows the operation it becomes without a static
//!   tree or a decode from the root; see [`codec::pm::DpmAdapter`] for why this covers every
//!   collapse. The split cache holds the vertex's operation's criteria and face count, decoded
//!   when the vertex is made; the collapse cache is the creator's criteria.
//! * Operations are decoded on demand per split, in the reorganisation: a pass splits a vertex
//!   once, and its children's criteria are all the next pass needs, so a split costs one full
//!   decode and two up to the face count, and a pass decodes nothing where nothing splits. A
//!   wavefront over tree depths (decoding from the roots down each pass, contexts flowing
//!   down) would redo every active vertex's ancestors each pass, 15.6 levels on average for
//!   the dragon (29 at most); it was not built.
//! * Splits write `v` and `v_u` during reorganisation, so that the new FVID buffer is complete
//!   before the split stage binary-searches it; the split stage gives the faces their indices.
//! * Faces carry the address of the split that created them (4 bytes per face): the collapse
//!   removes exactly those, as in the CPU reference (inputs may hold faces that are degenerate
//!   at every level).
//! * The split compaction and the face compaction use atomic cursors instead of scans: the
//!   order they produce does not matter (face slots come from the face prefix sum, and the
//!   face order of the adapted mesh is free), so the triangle *set*, not the face order, is
//!   what equals the CPU reference.

mod budget;
pub(crate) mod buffers;
pub mod decoder;
mod nodes;
pub mod occlusion;
mod pass;
pub(crate) mod pipelines;
mod tuning;

use std::sync::Arc;

use codec::pm::format::{Dpm, NodeFile, OpContext, NODE_BYTES};
use codec::pm::{CacheStats, NodeCache, PassStats, Viewpoint, LEVELS_PER_PASS, NONE};
use thiserror::Error;

use crate::gpu::{Gpu, GpuError};
use crate::render::{AdaptedMesh, PmPoint};
use budget::MemoryBudget;
use buffers::{
    init, needs_resize, pack_pn, storage, unpack_position, FaceSet, GpuVState, Params, ScanLevel, Sized, VertexSet,
    ERRORS_BYTES, PENDING, QUEUE_BYTES, READBACK_BYTES, SC_FACE_BYTES, SC_LEAF_BYTES, SC_SPLIT_BYTES, STATE_BYTES,
    STATS_BYTES, VERTEX_USAGE,
};
use decoder::{decoder_data, slot_bytes, slots_within, DecodeFailure};
use nodes::NodePool;
use occlusion::Occluder;
use pipelines::Pipelines;
use tuning::Tuning;

/// The most steps a descent slot runs in one dispatch on a software adapter (lavapipe), a
/// step being one vertex visited (its operation's head decoded, and the rest where it
/// splits): llvmpipe ends every loop of an invocation after 65535 iterations in all,
/// silently, and as it counts them (a loop per symbol of eight lanes, running as long as the
/// longest code of any lane) a step took up to 256-512: the dragon's and the bunny's lockstep
/// paths ran in rounds of 128 steps and reached the limit in rounds of 256 (the pass then
/// fails, `loops_alive` of `descent.wgsl`). So a slot pauses its descent after 64 steps and
/// the next dispatch of the same stage goes on with it (as fast as 128: 231 against 229 ms an
/// orbit frame). Hardware GPUs never pause.
pub const SOFTWARE_ROUND_STEPS: u32 = 64;

/// The descent slots (threads of `count` and `descend`) on a software adapter, which takes
/// a descent from the queue whenever it finished one: a few per lane of its cores, so that
/// the lanes of a core stay busy until the queue is empty. A hardware GPU gets as many as
/// the stacks hold, up to one per descent.
pub const SOFTWARE_DESCENT_SLOTS: u32 = 1024;

/// Vectors of a descent's resume record after the stacks (`RESUME_VECS` of `descent.wgsl`).
pub(crate) const RESUME_VECS: u64 = 12;

/// Unless [`GpuAdapter::set_levels`] chose one kind of pass: the splits a descent averages in
/// an all-levels pass past which the later passes for the same view run one level. Measured
/// on lavapipe (the dragon at 1920x1080, 0.5 px): from the base mesh the passes average
/// 14-23, and all levels took 2.5-3.2 s to converge against 1.0-1.3 s in one-level passes; a
/// 22.5 degree orbit step averages about 2-6 and converges in one all-levels pass (11x a
/// converged pass) against 10 one-level passes (24x).
pub const DEEP_DESCENT: u32 = 8;

/// The one-level passes that changed the mesh after which a view switched to them by
/// [`DEEP_DESCENT`] goes back to all levels for good: its split trees are deeper than a
/// one-level pass a level can follow (planar regions, whose errors tie, make long chains:
/// from the base mesh the alligator took 1,110 passes, the fandisk 682), and an all-levels
/// pass moves up to `LEVELS_PER_PASS` (32) levels. The dragon from its base mesh converges
/// in fewer (25 one-level passes in all).
pub const DEEP_PASSES: u32 = 32;

/// Words of one entry of a descent's stack (`STACK_WORDS` of `descent.wgsl`).
pub(crate) const STACK_WORDS: u64 = 24;

/// The most bytes the descent stacks take (a memory budget of `b` bytes allows at most
/// `b / 64`): 10,922 slots, 32 entries each (a slot each for the dragon's 5,000-9,000
/// descents an orbit frame at 1920x1080).
pub const MAX_STACK_BYTES: u64 = 32 << 20;

/// The most bytes the count's scratch area takes (a memory budget of `b` bytes allows at
/// most `b / 64`): 147,000 leaves with their splits and three faces a split. A pass that
/// keeps more (from the base mesh of a large model) walks its descents again instead.
pub const MAX_SCRATCH_BYTES: u64 = 32 << 20;

/// The count's scratch area for `k` leaves (and `k` splits, `3 k` faces): the records, and
/// the faces.
fn scratch_buffers(d: &wgpu::Device, k: u64) -> (Sized, Sized) {
    (
        storage(d, "pm: count scratch", k * (SC_LEAF_BYTES + SC_SPLIT_BYTES) / 16, 16, VERTEX_USAGE),
        storage(d, "pm: count scratch faces", 3 * k, SC_FACE_BYTES, VERTEX_USAGE),
    )
}

/// The labels of the all-levels marks ([`GpuAdapter`]'s `marks`).
const MARKS: [&str; 4] = ["pm: undone ranges", "pm: region reach", "pm: undone starts", "pm: region roots"];

/// The default of the paper's `n_alloc`: spare elements a reallocated buffer gets.
pub const DEFAULT_N_ALLOC: u32 = 1 << 15;

/// The factor by which a pass held back by the memory budget raises the error the passes
/// after it adapt to, and by which a converged mesh with room to spare lowers it again.
/// A step of 1.5 changes the mesh by up to 2.25x (screen-space error e leaves about 1/e^2 of
/// the triangles of a distant view; a close one, whose coarse spheres hold the eye, changes
/// far less: the bunny seen from close needs 57.7x the error for 43% of its triangles).
/// [`GpuAdapter::fits_finer`] lowers the error where the mesh takes at most half the room,
/// and a view goes no lower than the scale that last overflowed for it.
const SCALE_STEP: f32 = 1.5;
/// The largest error scale (a budget that cannot hold even a coarse mesh ends here).
const MAX_SCALE: f32 = 1e6;

/// The share of `--gpu-budget-mb` an out-of-core worker gives its node pool by default; the
/// rest is for the tables and the adapted mesh. The 102M-triangle armadillo at 1920x1080
/// requires 345-460 nodes of 64 kB (22-29 MB) at 3 px and adapts 180-210 MiB of mesh, so a
/// quarter of 512 MiB holds the required nodes four times over, with room for the
/// lower-priority ones.
pub const DEFAULT_POOL_SHARE: f64 = 0.25;

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
    /// An operation of the `.dpm` did not decode on the GPU: where (the operation's byte, and
    /// out of core its node) and why.
    #[error("corrupt .dpm data: {at}: {failure}")]
    Corrupt { at: String, failure: String },
    /// A descent stopped by the GPU's loop limit (llvmpipe: 65535 iterations an invocation),
    /// found because its loop ended without finishing: the pass would be wrong.
    #[error("the GPU ended a descent early ({at}; its loop limit): lower the descent budget")]
    LoopLimit { at: String },
    /// A base vertex's operation did not decode on the CPU, or a node could not be read.
    #[error(transparent)]
    Format(#[from] codec::pm::DpmError),
    /// An out-of-core file given to [`GpuAdapter::new`], or an in-core one to
    /// [`GpuAdapter::out_of_core`].
    #[error("{0}")]
    WrongLayout(&'static str),
    /// The adapted mesh outgrew what the device binds in one buffer.
    #[error(
        "the adapted mesh needs {elements} {what}, {bytes} bytes in one buffer, and this GPU binds at most \
         {limit}: raise --error-px"
    )]
    TooLarge { elements: u64, what: &'static str, bytes: u64, limit: u64 },
    /// The node pool's budget does not hold the largest node.
    #[error(
        "a node pool of {budget} bytes holds no node: the largest takes {slot_bytes} (raise --gpu-budget-mb or \
         --gpu-nodes-mb)"
    )]
    Budget { budget: u64, slot_bytes: u32 },
    /// The GPU budget does not hold the static buffers and the base mesh.
    #[error(
        "a GPU budget of {budget} bytes does not hold the model's tables, nodes and base mesh ({need} bytes): raise \
         --gpu-budget-mb"
    )]
    MeshBudget { budget: u64, need: u64 },
    /// A node pool given as large as the whole budget or larger.
    #[error("a node pool of {pool} bytes (--gpu-nodes-mb) leaves nothing of a GPU budget of {budget} for the mesh")]
    PoolOverBudget { pool: u64, budget: u64 },
    /// The node pool was asked to hold more nodes than it has slots (a bug of the cache).
    #[error("GPU error: the node pool's {slots} slots are all taken")]
    PoolFull { slots: u32 },
    /// A node larger than a slot (a node table that lies).
    #[error("corrupt .dpm data: node {node}: {bytes} bytes, more than the {slot_bytes} of a slot")]
    NodeSize { node: u32, bytes: usize, slot_bytes: u32 },
}

impl AdaptError {
    /// The error of a `DEC_*` status of `decode.wgsl` for the operation at `addr` (out of
    /// core: a node and a local address).
    pub(crate) fn corrupt(status: u32, addr: u32, out_of_core: bool) -> AdaptError {
        let at = if out_of_core {
            format!("node {}: operation at byte {}", addr as usize / NODE_BYTES, addr as usize % NODE_BYTES)
        } else {
            format!("operation at byte {addr}")
        };
        match DecodeFailure::of(status) {
            DecodeFailure::LoopLimit => AdaptError::LoopLimit { at },
            failure => AdaptError::Corrupt { at, failure: failure.to_string() },
        }
    }
}

/// The bytes of an out-of-core worker's node pool: `nodes` where given (less than the
/// budget), else [`DEFAULT_POOL_SHARE`] of `budget`, else (no budget) every node.
pub fn pool_bytes(budget: Option<u64>, nodes: Option<u64>) -> Result<u64, AdaptError> {
    match (budget, nodes) {
        (Some(b), Some(n)) if n >= b => Err(AdaptError::PoolOverBudget { pool: n, budget: b }),
        (_, Some(n)) => Ok(n),
        (Some(b), None) => Ok((b as f64 * DEFAULT_POOL_SHARE) as u64),
        (None, None) => Ok(u64::MAX),
    }
}

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
struct Resident {
    cache: NodeCache,
    pool: NodePool,
    /// Node bytes uploaded to the pool so far.
    uploaded: u64,
}

/// The adaptation state of one progressive mesh on the GPU (see the module docs).
pub struct GpuAdapter {
    gpu: Gpu,
    /// Pipelines and static data, shared by every adapter of the same mesh on this device.
    shared: Arc<Shared>,
    n_alloc: u32,
    params: wgpu::Buffer,
    stats: wgpu::Buffer,
    /// The first operation that failed to decode ([`buffers::Errors`]).
    errors: wgpu::Buffer,
    readback: wgpu::Buffer,
    sets: [VertexSet; 2],
    cur: usize,
    faces: FaceSet,
    vcnt: Sized,
    fcnt: Sized,
    list: Sized,
    hole: Sized,
    /// An all-levels pass's marks (`state.wgsl`): `diff`, `reach`, `up`, `root`.
    marks: [Sized; 4],
    /// How passes are run: levels, descent budget, rounds, limits, profiling.
    tuning: Tuning,
    /// An all-levels pass's descent stacks (`descent.wgsl`): [`STACK_WORDS`] words an entry,
    /// min([`LEVELS_PER_PASS`], descent budget) entries a slot, one slot a descent running;
    /// grown to the descents of a pass (on a software adapter to [`SOFTWARE_DESCENT_SLOTS`])
    /// up to [`Self::stack_max_bytes`]; the slots take the descents from a queue.
    stack: Sized,
    /// The slots (threads) of this pass's descents, and their queues ([`buffers::Queue`]).
    slots: u32,
    queue: wgpu::Buffer,
    /// The steps of the last count's descents in all and the most of one (they size the
    /// rounds of `descend`).
    steps: u64,
    most: u64,
    /// Whether this pass's classification ran `count` (its loop-limit failure can be retried).
    count_ran: bool,
    /// The count's scratch area (`state.wgsl`, `place.wgsl`): leaf and split records, and the
    /// splits' faces; what it holds (leaves, splits, faces) and what the last count kept
    /// (more than it holds: the pass walks the descents again instead).
    scratch: Sized,
    sc_faces: Sized,
    sc_cap: [u32; 3],
    sc_kept: [u32; 3],
    /// The vertices that descended in the last pass ([`Self::last_descents`]).
    descents: u32,
    /// With the default kind of pass ([`Tuning::mixed`]): one level for the rest of a view
    /// once an all-levels pass for it descended deep (`deep`, [`DEEP_DESCENT`]), unless the
    /// view then took [`DEEP_PASSES`] one-level passes that changed the mesh (`deep_passes`;
    /// `deep_tree`: all levels for the rest of the view).
    deep: bool,
    deep_passes: u32,
    deep_tree: bool,
    /// Per scan level, for the current pass ([`GpuAdapter::prepare_scan`]).
    scan_levels: Vec<ScanLevel>,
    /// Active vertices and faces.
    n: u32,
    m: u32,
    reallocations: u64,
    /// Milliseconds of the last pass: classification (to the totals read back), application.
    times: [f64; 3],
    /// Out of core: the resident nodes.
    resident: Option<Resident>,
    /// The occlusion pyramid of the state update (`occ`; one word when off), and the
    /// occluder it was uploaded from (`None`: off), whose parameters every pass writes and
    /// whose test ranks hidden nodes last out of core.
    occ: Sized,
    occluder: Option<Occluder>,
    /// The graphics memory budget and the error scale that keeps the mesh within it.
    memory: MemoryBudget,
}

/// What adapters of the same progressive mesh share: the pipelines, the static buffers (the
/// compressed operations, the decoder's tables and parameters), and the base mesh.
struct Shared {
    pipelines: Pipelines,
    max_groups: u32,
    ops: wgpu::Buffer,
    tables: wgpu::Buffer,
    decode: wgpu::Buffer,
    base: BaseState,
}

impl GpuAdapter {
    /// Uploads `dpm`'s compressed operations and decoding tables to `gpu`'s device and starts
    /// at the base mesh (whose operations' criteria the CPU decodes: a few per component).
    /// `n_alloc` is the paper's reallocation slack in elements ([`DEFAULT_N_ALLOC`]).
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
        let need = pipelines::storage_buffers_per_stage();
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
                pipelines: Pipelines::new(gpu),
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
    fn grow_scratch(&mut self, kept: [u32; 3]) {
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
    fn stack_slot_bytes(&self) -> u64 {
        LEVELS_PER_PASS.min(self.tuning.descent_budget) as u64 * STACK_WORDS * 4 + RESUME_VECS * 16
    }

    /// Where the resume records of the pass's slots start in the stacks' buffer, and their
    /// bytes.
    fn resume_range(&self) -> (u64, u64) {
        let slots = self.slots as u64;
        let records = slots * RESUME_VECS * 16;
        (slots * self.stack_slot_bytes() - records, records)
    }

    /// The most bytes the descent stacks may take under `budget`: the stack limit
    /// ([`Self::set_stack_limit`]), at most a 64th of the budget, at least one slot.
    fn stack_max_bytes(&self, budget: Option<u64>) -> u64 {
        let cap = budget.map_or(self.tuning.stack_limit, |b| (b / 64).min(self.tuning.stack_limit));
        let slot = self.stack_slot_bytes();
        (cap / slot).max(1) * slot
    }

    /// Descents the stacks hold at once now (at least the pass's slots).
    fn stack_slots(&self) -> u32 {
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
    /// adapter's mesh: occlusion one frame late, see [`occlusion`]); `None` turns it off.
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
    fn sync_nodes(&mut self) -> Result<(), AdaptError> {
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
struct BaseState {
    fvid: Vec<u32>,
    state: Vec<GpuVState>,
    point: Vec<PmPoint>,
    face_idx: Vec<[u32; 3]>,
    face_fvid: Vec<[u32; 3]>,
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
