//! The compute pipelines of the adaptation's stages, one per entry point of
//! `shaders/pm/*.wgsl`.

pub(super) const WG: u32 = 256;
pub(super) const SCAN_BLOCK: u32 = 2048;

/// A compute pipeline and its bind group layout, taken from it once: `get_bind_group_layout`
/// registers a new layout handle on every call, and calling it for every bind group of every
/// pass grew a worker's memory by megabytes a frame (measured on lavapipe).
pub(super) struct Stage {
    pub(super) pipeline: wgpu::ComputePipeline,
    pub(super) layout: wgpu::BindGroupLayout,
}

impl std::ops::Deref for Stage {
    type Target = wgpu::ComputePipeline;
    fn deref(&self) -> &wgpu::ComputePipeline {
        &self.pipeline
    }
}

pub(super) struct Pipelines {
    pub(super) state: Stage,
    pub(super) collapse: Stage,
    pub(super) scan_blocks: Stage,
    pub(super) add_blocks: Stage,
    pub(super) reorganise: Stage,
    pub(super) compact_splits: Stage,
    pub(super) split: Stage,
    pub(super) index_update: Stage,
    pub(super) holes: Stage,
    pub(super) fill: Stage,
}

impl Pipelines {
    pub(super) fn new(device: &wgpu::Device) -> Pipelines {
        let common = include_str!("../../../shaders/pm/common.wgsl");
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
            source: wgpu::ShaderSource::Wgsl(include_str!("../../../shaders/pm/scan.wgsl").into()),
        });
        let compact = module("pm: face compaction", include_str!("../../../shaders/pm/face_compact.wgsl"));
        Pipelines {
            state: single("pm: state update", include_str!("../../../shaders/pm/state.wgsl")),
            collapse: single("pm: collapse", include_str!("../../../shaders/pm/collapse.wgsl")),
            scan_blocks: pipeline(&scan, "pm: scan blocks", "scan_blocks"),
            add_blocks: pipeline(&scan, "pm: scan add", "add_blocks"),
            reorganise: single("pm: reorganise", include_str!("../../../shaders/pm/reorganise.wgsl")),
            compact_splits: single("pm: compact splits", include_str!("../../../shaders/pm/compact_splits.wgsl")),
            split: single("pm: split", include_str!("../../../shaders/pm/split.wgsl")),
            index_update: single("pm: index update", include_str!("../../../shaders/pm/index_update.wgsl")),
            holes: pipeline(&compact, "pm: face holes", "holes"),
            fill: pipeline(&compact, "pm: face fill", "fill"),
        }
    }
}
