//! The adaptation's stages, one compute pipeline per entry point of `worker/src/pm_adapt/shaders/*.wgsl`, in
//! the order a pass runs them. A [`StageDef`] names the stage's shader and entry point; its
//! binding list is the WGSL's, read once per process (`crate::reflect`), and the stage's
//! bind group layout and bind groups are built from it. `wgsl_contract` checks the Rust
//! record behind every binding's name.

use std::borrow::Cow;
use std::sync::OnceLock;

use super::decoder::decoder_wgsl;
use crate::gpu::{Access, Binding, Compute, Gpu, GpuError};
use crate::reflect::Reflected;

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

/// One stage: an entry point of a shader.
pub(crate) struct StageDef {
    /// Names the pipeline, its layouts and its bind groups.
    pub label: &'static str,
    pub shader: &'static ShaderDef,
    pub entry: &'static str,
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

/// Out of core, first in a pass: which vertices' nodes are resident, and the pending
/// operations whose nodes came in decoded.
pub(crate) const NODE_CHECK: StageDef = StageDef { label: "pm: node check", shader: &NODES_WGSL, entry: "main" };

/// Algorithm 1.
pub(crate) const STATE: StageDef = StageDef { label: "pm: state update", shader: &STATE_WGSL, entry: "main" };

/// An all-levels pass: the undone splits marked, the vertices that split listed.
pub(crate) const MARK: StageDef = StageDef { label: "pm: mark", shader: &STATE_WGSL, entry: "mark" };

/// An all-levels pass: each listed vertex's leaves and faces counted down its subtree.
pub(crate) const COUNT: StageDef = StageDef { label: "pm: count", shader: &STATE_WGSL, entry: "count" };

/// An all-levels pass: the collapsing regions, and the vertices carrying their operations.
pub(crate) const REGIONS: StageDef = StageDef { label: "pm: regions", shader: &STATE_WGSL, entry: "regions" };

/// Algorithm 2.
pub(crate) const COLLAPSE: StageDef = StageDef { label: "pm: collapse", shader: &COLLAPSE_WGSL, entry: "main" };

/// The scan, down: each block scanned, its total to `sums`.
pub(crate) const SCAN_BLOCKS: StageDef =
    StageDef { label: "pm: scan blocks", shader: &SCAN_WGSL, entry: "scan_blocks" };

/// The scan, up: the scanned block totals added back.
pub(crate) const ADD_BLOCKS: StageDef = StageDef { label: "pm: scan add", shader: &SCAN_WGSL, entry: "add_blocks" };

/// Algorithm 3.
pub(crate) const REORGANISE: StageDef = StageDef { label: "pm: reorganise", shader: &REORGANISE_WGSL, entry: "main" };

/// Algorithm 3's splits: the operations decoded, the children written.
pub(crate) const SPLIT_DECODE: StageDef =
    StageDef { label: "pm: split decode", shader: &SPLIT_DECODE_WGSL, entry: "main" };

/// An all-levels pass's splits: every splitting vertex's leaves and faces written.
pub(crate) const DESCEND: StageDef = StageDef { label: "pm: descend", shader: &SPLIT_DECODE_WGSL, entry: "descend" };

/// An all-levels pass: the leaves the count kept, to their slots (`place.wgsl`).
pub(crate) const PLACE_LEAVES: StageDef =
    StageDef { label: "pm: place leaves", shader: &PLACE_WGSL, entry: "place_leaves" };

/// An all-levels pass: the faces of the splits the count kept, to their slots (`place.wgsl`).
pub(crate) const PLACE_SPLITS: StageDef =
    StageDef { label: "pm: place splits", shader: &PLACE_WGSL, entry: "place_splits" };

/// Algorithm 4's first step.
pub(crate) const COMPACT_SPLITS: StageDef =
    StageDef { label: "pm: compact splits", shader: &COMPACT_SPLITS_WGSL, entry: "main" };

/// Algorithm 4.
pub(crate) const SPLIT: StageDef = StageDef { label: "pm: split", shader: &SPLIT_WGSL, entry: "main" };

/// An all-levels pass's Algorithm 4: the new faces indexed, one thread each.
pub(crate) const INDEX_NEW: StageDef =
    StageDef { label: "pm: index new faces", shader: &SPLIT_WGSL, entry: "index_new" };

/// Algorithm 5.
pub(crate) const INDEX_UPDATE: StageDef =
    StageDef { label: "pm: index update", shader: &INDEX_UPDATE_WGSL, entry: "main" };

/// Section 5.6, first half: the dead slots below `m_new` listed. It uses only some of the
/// file's bindings, and its layout holds only those.
pub(crate) const HOLES: StageDef = StageDef { label: "pm: face holes", shader: &FACE_COMPACT_WGSL, entry: "holes" };

/// Section 5.6, second half: the live faces above `m_new` moved into the holes.
pub(crate) const FILL: StageDef = StageDef { label: "pm: face fill", shader: &FACE_COMPACT_WGSL, entry: "fill" };

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

/// Every stage's bindings, one list per bind group, read from its WGSL once per process, in
/// [`STAGES`] order (each shader file parsed once for all of its entry points).
fn stage_bindings() -> Result<&'static [Vec<Vec<Binding>>], GpuError> {
    static BINDINGS: OnceLock<Result<Vec<Vec<Vec<Binding>>>, String>> = OnceLock::new();
    let read = || {
        let mut parsed: Vec<(&str, Reflected)> = Vec::new();
        let mut out = Vec::with_capacity(STAGES.len());
        for stage in STAGES {
            let shader = stage.shader;
            let i = match parsed.iter().position(|(label, _)| *label == shader.label) {
                Some(i) => i,
                None => {
                    parsed.push((shader.label, Reflected::parse(shader.label, &shader.wgsl())?));
                    parsed.len() - 1
                }
            };
            out.push(parsed[i].1.groups(stage.entry)?);
        }
        Ok(out)
    };
    BINDINGS.get_or_init(read).as_deref().map_err(|e| GpuError::Shader(e.clone()))
}

impl StageDef {
    /// The stage's bindings, one list per bind group, as its WGSL declares those its entry
    /// point uses.
    pub(crate) fn bindings(&self) -> Result<&'static [Vec<Binding>], GpuError> {
        // By label: a `const` has no one address to compare.
        let i = STAGES.iter().position(|s| s.label == self.label).expect("every StageDef is in STAGES");
        Ok(&stage_bindings()?[i])
    }
}

/// The most storage buffers one stage binds, over all its groups: what the device must allow
/// per shader stage.
pub(super) fn storage_buffers_per_stage() -> Result<u32, GpuError> {
    let storage = |groups: &Vec<Vec<Binding>>| groups.iter().flatten().filter(|b| b.access != Access::Uniform).count();
    Ok(stage_bindings()?.iter().map(storage).max().unwrap_or(0) as u32)
}

/// A stage's compute pipeline, laid out from its WGSL's bindings.
pub(super) struct Stage {
    pub(super) compute: Compute,
}

impl Stage {
    fn new(gpu: &Gpu, module: &wgpu::ShaderModule, def: &'static StageDef) -> Result<Stage, GpuError> {
        let compute = Compute::new(gpu, def.label, module, def.entry, def.bindings()?.to_vec());
        Ok(Stage { compute })
    }

    /// The bind groups of this stage: each of its bindings bound to the buffer of `buffers`
    /// named as its WGSL variable (`buffers` may name more: a submission hands all its
    /// stages one list).
    pub(super) fn bind(&self, gpu: &Gpu, buffers: &[(&str, &wgpu::Buffer)]) -> Vec<wgpu::BindGroup> {
        self.compute.bind(gpu, buffers)
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
    pub(super) fn new(gpu: &Gpu) -> Result<Pipelines, GpuError> {
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
        Ok(Pipelines {
            node_check: single(&NODE_CHECK)?,
            state: Stage::new(gpu, &state, &STATE)?,
            collapse: single(&COLLAPSE)?,
            scan_blocks: Stage::new(gpu, &scan, &SCAN_BLOCKS)?,
            add_blocks: Stage::new(gpu, &scan, &ADD_BLOCKS)?,
            reorganise: single(&REORGANISE)?,
            compact_splits: single(&COMPACT_SPLITS)?,
            split_decode: Stage::new(gpu, &split_decode, &SPLIT_DECODE)?,
            split: Stage::new(gpu, &split, &SPLIT)?,
            mark: Stage::new(gpu, &state, &MARK)?,
            count: Stage::new(gpu, &state, &COUNT)?,
            regions: Stage::new(gpu, &state, &REGIONS)?,
            descend: Stage::new(gpu, &split_decode, &DESCEND)?,
            place_leaves: Stage::new(gpu, &place, &PLACE_LEAVES)?,
            place_splits: Stage::new(gpu, &place, &PLACE_SPLITS)?,
            index_new: Stage::new(gpu, &split, &INDEX_NEW)?,
            index_update: single(&INDEX_UPDATE)?,
            holes: Stage::new(gpu, &compact, &HOLES)?,
            fill: Stage::new(gpu, &compact, &FILL)?,
        })
    }
}
