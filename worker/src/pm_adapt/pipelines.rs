//! The adaptation's stages, one compute pipeline per entry point of `worker/src/pm_adapt/shaders/*.wgsl`, in
//! the order a pass runs them. Each [`StageDef`] is the Rust half of the stage's contract with
//! its WGSL: the bind group layout and every bind group of the stage are built from its
//! binding table, and `wgsl_contract` checks the table against the shader (slot, name,
//! access, and the size of the Rust record behind each binding).

use std::borrow::Cow;

use super::buffers::{Errors, GpuVState, LevelUniform, Params, Queue, Stats};
use super::decoder::{decoder_wgsl, DecodeParams};
use crate::gpu::{Access, Binding, Gpu};
use crate::render::PmPoint;

/// Threads per workgroup of every stage (`WG` of `common.wgsl`, `@workgroup_size`).
pub(crate) const WG: u32 = 256;
/// Elements one workgroup of the scan handles (`BLOCK` of `scan.wgsl`).
pub(crate) const SCAN_BLOCK: u32 = 2048;

/// Types, `Params`, and the refinement test every stage but the scan shares.
const COMMON: &str = include_str!("shaders/common.wgsl");
/// What the stages that decode share after the decoder: error reports, a vertex's split cache.
const VERTEX_OP: &str = include_str!("shaders/vertex_op.wgsl");
/// What the state update and the split decoding share after `vertex_op.wgsl`: the view test
/// with occlusion, and the descent of an all-levels pass.
const DESCENT: &str = include_str!("shaders/descent.wgsl");

/// One WGSL file of the adaptation, compiled as one shader module.
pub(crate) struct ShaderDef {
    pub label: &'static str,
    source: &'static str,
    /// Whether `common.wgsl` is prepended.
    common: bool,
    /// Whether the operation decoder (`decode.wgsl` and its constants) and `vertex_op.wgsl`
    /// are prepended too.
    decoder: bool,
    /// Whether `descent.wgsl` is prepended after them.
    descent: bool,
}

impl ShaderDef {
    /// The WGSL the device compiles (and the contract test parses).
    pub(crate) fn wgsl(&self) -> Cow<'static, str> {
        let levels = format!("const LEVELS_PER_PASS: u32 = {}u;", codec::pm::LEVELS_PER_PASS);
        match (self.common, self.decoder, self.descent) {
            (true, true, true) => {
                format!("{COMMON}\n{levels}\n{}\n{VERTEX_OP}\n{DESCENT}\n{}", decoder_wgsl(), self.source).into()
            }
            (true, true, false) => format!("{COMMON}\n{}\n{VERTEX_OP}\n{}", decoder_wgsl(), self.source).into(),
            (true, false, _) => format!("{COMMON}\n{}", self.source).into(),
            _ => self.source.into(),
        }
    }
}

/// One stage: an entry point of a shader and its bind group 0.
pub(crate) struct StageDef {
    /// Names the pipeline, its layouts and its bind groups.
    pub label: &'static str,
    pub shader: &'static ShaderDef,
    pub entry: &'static str,
    pub bindings: &'static [Binding],
}

const fn with_common(label: &'static str, source: &'static str) -> ShaderDef {
    ShaderDef { label, source, common: true, decoder: false, descent: false }
}

const NODES_WGSL: ShaderDef = ShaderDef {
    label: "pm: node check",
    source: include_str!("shaders/nodes.wgsl"),
    common: true,
    decoder: true,
    descent: false,
};
const STATE_WGSL: ShaderDef = ShaderDef {
    label: "pm: state update",
    source: include_str!("shaders/state.wgsl"),
    common: true,
    decoder: true,
    descent: true,
};
const COLLAPSE_WGSL: ShaderDef = with_common("pm: collapse", include_str!("shaders/collapse.wgsl"));
const SCAN_WGSL: ShaderDef = ShaderDef {
    label: "pm: scan",
    source: include_str!("shaders/scan.wgsl"),
    common: false,
    decoder: false,
    descent: false,
};
const REORGANISE_WGSL: ShaderDef = with_common("pm: reorganise", include_str!("shaders/reorganise.wgsl"));
const SPLIT_DECODE_WGSL: ShaderDef = ShaderDef {
    label: "pm: split decode",
    source: include_str!("shaders/split_decode.wgsl"),
    common: true,
    decoder: true,
    descent: true,
};
const PLACE_WGSL: ShaderDef = with_common("pm: place", include_str!("shaders/place.wgsl"));
const COMPACT_SPLITS_WGSL: ShaderDef = with_common("pm: compact splits", include_str!("shaders/compact_splits.wgsl"));
const SPLIT_WGSL: ShaderDef = with_common("pm: split", include_str!("shaders/split.wgsl"));
const INDEX_UPDATE_WGSL: ShaderDef = with_common("pm: index update", include_str!("shaders/index_update.wgsl"));
const FACE_COMPACT_WGSL: ShaderDef = with_common("pm: face compaction", include_str!("shaders/face_compact.wgsl"));

/// `P`, the parameters every stage of `common.wgsl` binds first.
const PARAMS: Binding = Binding::read::<Params>(0, "P");

/// Out of core, first in a pass: which vertices' nodes are resident, and the pending
/// operations whose nodes came in decoded.
pub(crate) const NODE_CHECK: StageDef = StageDef {
    label: "pm: node check",
    shader: &NODES_WGSL,
    entry: "main",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(1, "vfvid"),
        Binding::read_write::<GpuVState>(2, "vstate"),
        Binding::read::<DecodeParams>(3, "D"),
        Binding::read::<u32>(4, "ops"),
        Binding::read::<u32>(5, "tables"),
        Binding::read_write::<u32>(6, "dec_faces"),
        Binding::read_write::<Errors>(7, "errors"),
    ],
};

/// Algorithm 1.
pub(crate) const STATE: StageDef = StageDef {
    label: "pm: state update",
    shader: &STATE_WGSL,
    entry: "main",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(1, "vfvid"),
        Binding::read::<GpuVState>(2, "vstate"),
        Binding::read::<PmPoint>(3, "vpoint"),
        Binding::read_write::<u32>(4, "vcnt"),
        Binding::read_write::<u32>(5, "fcnt"),
        Binding::read::<u32>(6, "occ"),
    ],
};

/// The decoder's bindings in `state.wgsl`.
const STATE_DECODER: [Binding; 5] = [
    Binding::read::<DecodeParams>(7, "D"),
    Binding::read::<u32>(8, "ops"),
    Binding::read::<u32>(9, "tables"),
    Binding::read_write::<u32>(10, "dec_faces"),
    Binding::read_write::<Errors>(11, "errors"),
];

/// An all-levels pass: the undone splits marked, the vertices that split listed.
pub(crate) const MARK: StageDef = StageDef {
    label: "pm: mark",
    shader: &STATE_WGSL,
    entry: "mark",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(1, "vfvid"),
        Binding::read::<GpuVState>(2, "vstate"),
        Binding::read::<PmPoint>(3, "vpoint"),
        Binding::read_write::<u32>(4, "vcnt"),
        Binding::read_write::<u32>(5, "fcnt"),
        Binding::read::<u32>(6, "occ"),
        Binding::read_write::<u32>(12, "diff"),
        Binding::read_write::<u32>(13, "reach"),
        Binding::read_write::<u32>(14, "up"),
        Binding::read_write::<Stats>(16, "stats"),
        Binding::read_write::<u32>(17, "list"),
    ],
};

/// An all-levels pass: each listed vertex's leaves and faces counted down its subtree.
pub(crate) const COUNT: StageDef = StageDef {
    label: "pm: count",
    shader: &STATE_WGSL,
    entry: "count",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(1, "vfvid"),
        Binding::read::<GpuVState>(2, "vstate"),
        Binding::read::<PmPoint>(3, "vpoint"),
        Binding::read_write::<u32>(4, "vcnt"),
        Binding::read_write::<u32>(5, "fcnt"),
        Binding::read::<u32>(6, "occ"),
        STATE_DECODER[0],
        STATE_DECODER[1],
        STATE_DECODER[2],
        STATE_DECODER[3],
        STATE_DECODER[4],
        Binding::read_write::<Stats>(16, "stats"),
        Binding::read_write::<u32>(17, "list"),
        Binding::read_write::<[u32; 4]>(18, "dstack"),
        Binding::read_write::<Queue>(19, "queue"),
        Binding::read_write::<[u32; 4]>(20, "scratch"),
    ],
};

/// An all-levels pass: the collapsing regions, and the vertices carrying their operations.
pub(crate) const REGIONS: StageDef = StageDef {
    label: "pm: regions",
    shader: &STATE_WGSL,
    entry: "regions",
    bindings: &[
        PARAMS,
        Binding::read::<GpuVState>(2, "vstate"),
        Binding::read_write::<u32>(4, "vcnt"),
        Binding::read_write::<u32>(5, "fcnt"),
        Binding::read_write::<u32>(12, "diff"),
        Binding::read_write::<u32>(13, "reach"),
        Binding::read_write::<u32>(14, "up"),
        Binding::read_write::<u32>(15, "root"),
        Binding::read_write::<Stats>(16, "stats"),
    ],
};

/// Algorithm 2.
pub(crate) const COLLAPSE: StageDef = StageDef {
    label: "pm: collapse",
    shader: &COLLAPSE_WGSL,
    entry: "main",
    bindings: &[
        PARAMS,
        Binding::read_write::<GpuVState>(1, "vstate"),
        Binding::read_write::<u32>(2, "vcnt"),
        Binding::read_write::<Stats>(3, "stats"),
    ],
};

/// The scan's bindings, the same for both of its entry points.
const SCAN_BINDINGS: &[Binding] = &[
    Binding::read::<LevelUniform>(0, "L"),
    Binding::read_write::<u32>(1, "data"),
    Binding::read_write::<u32>(2, "sums"),
];

/// The scan, down: each block scanned, its total to `sums`.
pub(crate) const SCAN_BLOCKS: StageDef =
    StageDef { label: "pm: scan blocks", shader: &SCAN_WGSL, entry: "scan_blocks", bindings: SCAN_BINDINGS };

/// The scan, up: the scanned block totals added back.
pub(crate) const ADD_BLOCKS: StageDef =
    StageDef { label: "pm: scan add", shader: &SCAN_WGSL, entry: "add_blocks", bindings: SCAN_BINDINGS };

/// Algorithm 3.
pub(crate) const REORGANISE: StageDef = StageDef {
    label: "pm: reorganise",
    shader: &REORGANISE_WGSL,
    entry: "main",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(1, "vfvid"),
        Binding::read::<GpuVState>(2, "vstate"),
        Binding::read::<PmPoint>(3, "vpoint"),
        Binding::read::<u32>(4, "vsum"),
        Binding::read_write::<u32>(5, "dfvid"),
        Binding::read_write::<GpuVState>(6, "dstate"),
        Binding::read_write::<PmPoint>(7, "dpoint"),
        Binding::read::<u32>(8, "root"),
    ],
};

/// Algorithm 3's splits: the operations decoded, the children written.
pub(crate) const SPLIT_DECODE: StageDef = StageDef {
    label: "pm: split decode",
    shader: &SPLIT_DECODE_WGSL,
    entry: "main",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(1, "vfvid"),
        Binding::read::<GpuVState>(2, "vstate"),
        Binding::read::<PmPoint>(3, "vpoint"),
        Binding::read::<u32>(4, "vsum"),
        Binding::read::<u32>(5, "fsum"),
        Binding::read::<u32>(6, "list"),
        Binding::read_write::<u32>(7, "dfvid"),
        Binding::read_write::<GpuVState>(8, "dstate"),
        Binding::read_write::<PmPoint>(9, "dpoint"),
        Binding::read::<DecodeParams>(10, "D"),
        Binding::read::<u32>(11, "ops"),
        Binding::read::<u32>(12, "tables"),
        Binding::read_write::<u32>(13, "dec_faces"),
        Binding::read_write::<Errors>(14, "errors"),
    ],
};

/// An all-levels pass's splits: every splitting vertex's leaves and faces written.
pub(crate) const DESCEND: StageDef = StageDef {
    label: "pm: descend",
    shader: &SPLIT_DECODE_WGSL,
    entry: "descend",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(1, "vfvid"),
        Binding::read::<GpuVState>(2, "vstate"),
        Binding::read::<PmPoint>(3, "vpoint"),
        Binding::read::<u32>(4, "vsum"),
        Binding::read::<u32>(5, "fsum"),
        Binding::read::<u32>(6, "list"),
        Binding::read_write::<u32>(7, "dfvid"),
        Binding::read_write::<GpuVState>(8, "dstate"),
        Binding::read_write::<PmPoint>(9, "dpoint"),
        Binding::read::<DecodeParams>(10, "D"),
        Binding::read::<u32>(11, "ops"),
        Binding::read::<u32>(12, "tables"),
        Binding::read_write::<u32>(13, "dec_faces"),
        Binding::read_write::<Errors>(14, "errors"),
        Binding::read::<u32>(15, "occ"),
        Binding::read_write::<u32>(16, "face_owner"),
        Binding::read_write::<[u32; 4]>(17, "dstack"),
        Binding::read_write::<Queue>(18, "queue"),
    ],
};

/// An all-levels pass: the leaves the count kept, to their slots (`place.wgsl`).
pub(crate) const PLACE_LEAVES: StageDef = StageDef {
    label: "pm: place leaves",
    shader: &PLACE_WGSL,
    entry: "place_leaves",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(1, "vsum"),
        Binding::read_write::<u32>(3, "dfvid"),
        Binding::read_write::<GpuVState>(4, "dstate"),
        Binding::read_write::<PmPoint>(5, "dpoint"),
        Binding::read::<[u32; 4]>(8, "scratch"),
        Binding::read::<Queue>(10, "queue"),
    ],
};

/// An all-levels pass: the faces of the splits the count kept, to their slots (`place.wgsl`).
pub(crate) const PLACE_SPLITS: StageDef = StageDef {
    label: "pm: place splits",
    shader: &PLACE_WGSL,
    entry: "place_splits",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(1, "vsum"),
        Binding::read::<u32>(2, "fsum"),
        Binding::read_write::<u32>(6, "dec_faces"),
        Binding::read_write::<u32>(7, "face_owner"),
        Binding::read::<[u32; 4]>(8, "scratch"),
        Binding::read::<u32>(9, "sc_faces"),
        Binding::read::<Queue>(10, "queue"),
    ],
};

/// Algorithm 4's first step.
pub(crate) const COMPACT_SPLITS: StageDef = StageDef {
    label: "pm: compact splits",
    shader: &COMPACT_SPLITS_WGSL,
    entry: "main",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(1, "vsum"),
        Binding::read_write::<u32>(2, "list"),
        Binding::read_write::<Stats>(3, "stats"),
    ],
};

/// Algorithm 4.
pub(crate) const SPLIT: StageDef = StageDef {
    label: "pm: split",
    shader: &SPLIT_WGSL,
    entry: "main",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(1, "vfvid"),
        Binding::read::<u32>(3, "vsum"),
        Binding::read::<u32>(4, "fsum"),
        Binding::read::<u32>(5, "list"),
        Binding::read::<u32>(6, "dfvid"),
        Binding::read_write::<u32>(7, "face_idx"),
        Binding::read::<u32>(8, "face_fvid"),
        Binding::read_write::<u32>(9, "face_owner"),
    ],
};

/// An all-levels pass's Algorithm 4: the new faces indexed, one thread each.
pub(crate) const INDEX_NEW: StageDef = StageDef {
    label: "pm: index new faces",
    shader: &SPLIT_WGSL,
    entry: "index_new",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(6, "dfvid"),
        Binding::read_write::<u32>(7, "face_idx"),
        Binding::read::<u32>(8, "face_fvid"),
    ],
};

/// Algorithm 5.
pub(crate) const INDEX_UPDATE: StageDef = StageDef {
    label: "pm: index update",
    shader: &INDEX_UPDATE_WGSL,
    entry: "main",
    bindings: &[
        PARAMS,
        Binding::read::<u32>(1, "vfvid"),
        Binding::read::<u32>(2, "vsum"),
        Binding::read::<u32>(3, "dfvid"),
        Binding::read_write::<u32>(4, "face_idx"),
        Binding::read::<u32>(5, "face_fvid"),
        Binding::read_write::<u32>(6, "face_owner"),
    ],
};

/// Section 5.6, first half: the dead slots below `m_new` listed. It uses only some of the
/// file's bindings, and its layout holds only those.
pub(crate) const HOLES: StageDef = StageDef {
    label: "pm: face holes",
    shader: &FACE_COMPACT_WGSL,
    entry: "holes",
    bindings: &[
        PARAMS,
        Binding::read_write::<u32>(3, "face_owner"),
        Binding::read_write::<u32>(4, "hole"),
        Binding::read_write::<Stats>(5, "stats"),
    ],
};

/// Section 5.6, second half: the live faces above `m_new` moved into the holes.
pub(crate) const FILL: StageDef = StageDef {
    label: "pm: face fill",
    shader: &FACE_COMPACT_WGSL,
    entry: "fill",
    bindings: &[
        PARAMS,
        Binding::read_write::<u32>(1, "face_idx"),
        Binding::read_write::<u32>(2, "face_fvid"),
        Binding::read_write::<u32>(3, "face_owner"),
        Binding::read_write::<u32>(4, "hole"),
        Binding::read_write::<Stats>(5, "stats"),
    ],
};

/// Every stage, in pass order.
pub(crate) const STAGES: [&StageDef; 19] = [
    &NODE_CHECK,
    &STATE,
    &COLLAPSE,
    &MARK,
    &COUNT,
    &REGIONS,
    &SCAN_BLOCKS,
    &ADD_BLOCKS,
    &COMPACT_SPLITS,
    &SPLIT_DECODE,
    &DESCEND,
    &PLACE_LEAVES,
    &PLACE_SPLITS,
    &REORGANISE,
    &SPLIT,
    &INDEX_NEW,
    &INDEX_UPDATE,
    &HOLES,
    &FILL,
];

/// The most storage buffers one stage binds: what the device must allow per shader stage.
pub(super) fn storage_buffers_per_stage() -> u32 {
    let storage = |s: &StageDef| s.bindings.iter().filter(|b| b.access != Access::Uniform).count();
    STAGES.iter().map(|s| storage(s)).max().unwrap_or(0) as u32
}

/// A compute pipeline, its bind group layout, and the stage it runs. The layout is made from
/// the stage's table and kept: `get_bind_group_layout` would register a new layout handle on
/// every call, and calling it for every bind group of every pass grew a worker's memory by
/// megabytes a frame (measured on lavapipe).
pub(super) struct Stage {
    pub(super) def: &'static StageDef,
    pub(super) pipeline: wgpu::ComputePipeline,
    pub(super) layout: wgpu::BindGroupLayout,
}

impl Stage {
    fn new(gpu: &Gpu, module: &wgpu::ShaderModule, def: &'static StageDef) -> Stage {
        let layout = gpu.bind_group_layout(&format!("{} layout", def.label), wgpu::ShaderStages::COMPUTE, def.bindings);
        let pipeline_layout = gpu.device().create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(&format!("{} pipeline layout", def.label)),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = gpu.device().create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(def.label),
            layout: Some(&pipeline_layout),
            module,
            entry_point: Some(def.entry),
            compilation_options: Default::default(),
            cache: None,
        });
        Stage { def, pipeline, layout }
    }

    /// A bind group of this stage, each buffer bound to the WGSL variable it is named after.
    pub(super) fn bind(&self, gpu: &Gpu, buffers: &[(&str, &wgpu::Buffer)]) -> wgpu::BindGroup {
        gpu.bind_group(self.def.label, &self.layout, self.def.bindings, buffers)
    }

    /// As [`Self::bind`], from the buffers of several stages: those its table names.
    pub(super) fn bind_named(&self, gpu: &Gpu, buffers: &[(&str, &wgpu::Buffer)]) -> wgpu::BindGroup {
        let used: Vec<_> =
            buffers.iter().copied().filter(|(name, _)| self.def.bindings.iter().any(|b| b.name == *name)).collect();
        self.bind(gpu, &used)
    }
}

pub(super) struct Pipelines {
    pub(super) node_check: Stage,
    pub(super) state: Stage,
    pub(super) collapse: Stage,
    pub(super) scan_blocks: Stage,
    pub(super) add_blocks: Stage,
    pub(super) reorganise: Stage,
    pub(super) compact_splits: Stage,
    pub(super) split_decode: Stage,
    pub(super) split: Stage,
    pub(super) mark: Stage,
    pub(super) count: Stage,
    pub(super) regions: Stage,
    pub(super) descend: Stage,
    pub(super) place_leaves: Stage,
    pub(super) place_splits: Stage,
    pub(super) index_new: Stage,
    pub(super) index_update: Stage,
    pub(super) holes: Stage,
    pub(super) fill: Stage,
}

impl Pipelines {
    pub(super) fn new(gpu: &Gpu) -> Pipelines {
        let module = |shader: &ShaderDef| {
            gpu.device().create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(shader.label),
                source: wgpu::ShaderSource::Wgsl(shader.wgsl()),
            })
        };
        // A module per file: the scan, the face compaction, the state update, the split
        // decoding and the split have two entry points or more.
        let scan = module(&SCAN_WGSL);
        let compact = module(&FACE_COMPACT_WGSL);
        let state = module(&STATE_WGSL);
        let split_decode = module(&SPLIT_DECODE_WGSL);
        let split = module(&SPLIT_WGSL);
        let place = module(&PLACE_WGSL);
        let single = |def: &'static StageDef| Stage::new(gpu, &module(def.shader), def);
        Pipelines {
            node_check: single(&NODE_CHECK),
            state: Stage::new(gpu, &state, &STATE),
            collapse: single(&COLLAPSE),
            scan_blocks: Stage::new(gpu, &scan, &SCAN_BLOCKS),
            add_blocks: Stage::new(gpu, &scan, &ADD_BLOCKS),
            reorganise: single(&REORGANISE),
            compact_splits: single(&COMPACT_SPLITS),
            split_decode: Stage::new(gpu, &split_decode, &SPLIT_DECODE),
            split: Stage::new(gpu, &split, &SPLIT),
            mark: Stage::new(gpu, &state, &MARK),
            count: Stage::new(gpu, &state, &COUNT),
            regions: Stage::new(gpu, &state, &REGIONS),
            descend: Stage::new(gpu, &split_decode, &DESCEND),
            place_leaves: Stage::new(gpu, &place, &PLACE_LEAVES),
            place_splits: Stage::new(gpu, &place, &PLACE_SPLITS),
            index_new: Stage::new(gpu, &split, &INDEX_NEW),
            index_update: single(&INDEX_UPDATE),
            holes: Stage::new(gpu, &compact, &HOLES),
            fill: Stage::new(gpu, &compact, &FILL),
        }
    }
}
