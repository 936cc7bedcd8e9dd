//! The adaptation's buffers: the records it uploads (twins of the WGSL structs), and the
//! per-vertex and per-face buffers resized by the paper's `n_alloc` policy.

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

/// `VState` of `worker/src/pm_adapt/shaders/common.wgsl`: an active vertex's operation and its creator's.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable, Default, Debug)]
pub(crate) struct GpuVState {
    pub(super) v_end: u32,
    pub(super) addr: u32,
    pub(super) faces: u32,
    pub(super) c_addr: u32,
    pub(super) c_v: u32,
    pub(super) c_v_end: u32,
    pub(super) c_faces: u32,
    /// Out of core: [`PENDING`], `ABSENT` (`common.wgsl`).
    pub(super) flags: u32,
    pub(super) pc: [u32; 4],
    /// Quantized position and octahedral normal, packed ([`pack_pn`]).
    pub(super) pn: [u32; 4],
    pub(super) crit: [f32; 4],
    pub(super) c_pc: [u32; 4],
    pub(super) c_crit: [f32; 4],
}

/// `pack_pn` of `worker/src/pm_adapt/shaders/common.wgsl`: a quantized position (at most 24 bits a
/// coordinate) and an octahedral normal (at most 17 bits a component) in four words.
pub(super) fn pack_pn(pos: [u32; 3], nrm: [u32; 2]) -> [u32; 4] {
    [pos[0] | (nrm[0] >> 16) << 24, pos[1] | (nrm[1] >> 16) << 24, pos[2], (nrm[0] & 0xffff) | nrm[1] << 16]
}

/// The quantized position of [`pack_pn`]'s four words.
pub(super) fn unpack_position(pn: [u32; 4]) -> [u32; 3] {
    [pn[0] & 0xff_ffff, pn[1] & 0xff_ffff, pn[2]]
}

/// `PENDING` of `worker/src/pm_adapt/shaders/common.wgsl`: the vertex's operation waits for its node.
pub(crate) const PENDING: u32 = 1;

/// `Params` of `worker/src/pm_adapt/shaders/common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable, Default)]
pub(crate) struct Params {
    pub(super) planes: [[f32; 4]; 6],
    pub(super) eye: [f32; 4],
    pub(super) pixels_per_unit: f32,
    pub(super) error_px: f32,
    pub(super) c_lod: f32,
    pub(super) attribute_scale: f32,
    pub(super) n: u32,
    pub(super) m: u32,
    pub(super) mode: u32,
    pub(super) n_new: u32,
    pub(super) f_add: u32,
    pub(super) m_new: u32,
    pub(super) splits: u32,
    /// 1: an all-levels pass (`codec::pm::Levels::All`), 0: one level.
    pub(super) levels: u32,
    /// An all-levels pass: the most splits one vertex's descent performs.
    pub(super) budget: u32,
    /// An all-levels pass: the descents' stack slots (`descent.wgsl`), the threads of
    /// `count` and `descend`.
    pub(super) stack_slots: u32,
    /// The most steps a slot takes in one dispatch (a descent resumes in the next), and the
    /// dispatches (rounds) of `count` or `descend` the host runs.
    pub(super) round_steps: u32,
    pub(super) rounds: u32,
    /// 2, the iterations of `descent.wgsl`'s probe of llvmpipe's loop limit (read at run
    /// time, so that the compiler cannot unroll the probe).
    pub(super) loop_probe: u32,
    /// An all-levels pass: the leaves, splits and faces the count's scratch area holds
    /// (`count` of `state.wgsl`, `place.wgsl`).
    pub(super) sc_leaves: u32,
    pub(super) sc_splits: u32,
    pub(super) sc_faces: u32,
    /// Occlusion ([`super::Occluder`]): the view-projection of the frame whose depth it is,
    /// the rectangle of that frame the depth covers (x0, y0, x1, y1 in pixels), and the
    /// frame's width, height, the finest cell's side in pixels, and 1 when on (0 off).
    pub(super) occ_vp: [[f32; 4]; 4],
    pub(super) occ_rect: [f32; 4],
    pub(super) occ_size: [f32; 4],
}

/// `Level` of `worker/src/pm_adapt/shaders/scan.wgsl`: the element count of one level of the scan.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct LevelUniform {
    pub(super) count: u32,
    pub(super) pad: [u32; 3],
}

/// The counters the stages accumulate with atomics (`stats`), read back once per pass; the
/// indices are the `STAT_*` constants of `common.wgsl`.
pub(crate) type Stats = [u32; 8];
pub(crate) const STAT_COLLAPSES: usize = 0;
pub(crate) const STAT_CANCELLED: usize = 1;
pub(crate) const STAT_REMOVED_FACES: usize = 2;
/// An all-levels pass: the vertices that split.
pub(crate) const STAT_SPLIT_VERTICES: usize = 6;
/// An all-levels pass: the vertices that descend (listed by `mark`, counted by `count`).
pub(crate) const STAT_DESCENTS: usize = 7;
pub(super) const STATS_BYTES: u64 = std::mem::size_of::<Stats>() as u64;
/// The queues of the descents of `count` (words 0-7) and `descend` (8-15), `Q_*` of
/// `descent.wgsl`: per stage the next descent to take, the descents paused, and of the
/// finished ones the steps in all (64 bits) and the most steps of one.
pub(crate) type Queue = [u32; 16];
/// The `Q_*` words of `common.wgsl` the host reads or clears: where `descend`'s queue starts,
/// and in `count`'s the next descent to take, the descents paused, the steps in all (two
/// words), the most of one, and the leaves its scratch area was asked to keep (then the
/// splits and the faces).
pub(super) const Q_DESCEND: u64 = 8;
pub(super) const Q_NEXT: usize = 0;
pub(super) const Q_PAUSED: usize = 1;
pub(super) const Q_STEPS: usize = 2;
pub(super) const Q_MOST: usize = 4;
pub(super) const Q_SC_LEAVES: usize = 5;
/// Vectors of a leaf's record in the count's scratch area (`SC_LEAF_VECS` of `state.wgsl`)
/// and of a split's; bytes of a face there.
pub(super) const SC_LEAF_BYTES: u64 = 10 * 16;
pub(super) const SC_SPLIT_BYTES: u64 = 2 * 16;
pub(super) const SC_FACE_BYTES: u64 = 12;
pub(super) const QUEUE_BYTES: u64 = std::mem::size_of::<Queue>() as u64;
/// The first operation a pass failed to decode: its `DEC_*` status (0: none) and address,
/// never cleared by a pass (`report` of `reorganise.wgsl`).
pub(crate) type Errors = [u32; 2];
pub(super) const ERRORS_BYTES: u64 = std::mem::size_of::<Errors>() as u64;
/// Readback: vertex total, face total, the 8 counters, then the errors.
pub(super) const READBACK_BYTES: u64 = 8 + STATS_BYTES + ERRORS_BYTES;

/// A buffer with a capacity in elements, resized by the paper's `n_alloc` policy.
pub(super) struct Sized {
    pub(super) buffer: wgpu::Buffer,
    /// Capacity in elements.
    pub(super) cap: u64,
}

/// One level of the recursive scan: its block sums, a uniform with its element count, and
/// its number of blocks.
pub(super) struct ScanLevel {
    pub(super) sums: Sized,
    pub(super) uniform: wgpu::Buffer,
    pub(super) blocks: u32,
}

/// The per-vertex buffers (one of two sets: reorganisation copies from one into the other):
/// FVIDs, states, and the points the renderer pulls.
pub(super) struct VertexSet {
    pub(super) fvid: Sized,
    pub(super) state: Sized,
    pub(super) point: Sized,
}

impl VertexSet {
    pub(super) fn new(device: &wgpu::Device, name: &str, cap: u64) -> VertexSet {
        VertexSet {
            fvid: storage(device, &format!("pm: vertex fvid {name}"), cap, 4, VERTEX_USAGE),
            state: storage(device, &format!("pm: vertex state {name}"), cap, STATE_BYTES, VERTEX_USAGE),
            point: storage(device, &format!("pm: vertex point {name}"), cap, POINT_BYTES, VERTEX_USAGE),
        }
    }

    pub(super) fn bytes(&self) -> u64 {
        self.fvid.buffer.size() + self.state.buffer.size() + self.point.buffer.size()
    }
}

pub(super) const STATE_BYTES: u64 = std::mem::size_of::<GpuVState>() as u64;
pub(super) const POINT_BYTES: u64 = std::mem::size_of::<crate::render::PmPoint>() as u64;

pub(super) struct FaceSet {
    /// Current vertex indices, 3 per face: the draw's index buffer.
    pub(super) idx: Sized,
    pub(super) fvid: Sized,
    pub(super) owner: Sized,
}

impl FaceSet {
    pub(super) fn new(device: &wgpu::Device, cap: u64) -> FaceSet {
        FaceSet {
            idx: storage(device, "pm: face indices", cap, 12, VERTEX_USAGE | wgpu::BufferUsages::INDEX),
            fvid: storage(device, "pm: face fvids", cap, 12, VERTEX_USAGE),
            owner: storage(device, "pm: face owners", cap, 4, VERTEX_USAGE),
        }
    }
}

pub(super) const VERTEX_USAGE: wgpu::BufferUsages =
    wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_SRC).union(wgpu::BufferUsages::COPY_DST);

pub(super) fn storage(
    device: &wgpu::Device,
    label: &str,
    elements: u64,
    element_bytes: u64,
    usage: wgpu::BufferUsages,
) -> Sized {
    // Never empty: a binding needs at least one element.
    let size = (elements.max(1) * element_bytes).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT).max(16);
    let buffer =
        device.create_buffer(&wgpu::BufferDescriptor { label: Some(label), size, usage, mapped_at_creation: false });
    Sized { buffer, cap: elements }
}

pub(super) fn init(device: &wgpu::Device, label: &str, data: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
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
pub(super) fn needs_resize(cap: u64, need: u64, n_alloc: u32) -> bool {
    cap < need || cap > need + 2 * n_alloc as u64
}
