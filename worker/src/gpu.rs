//! The GPU a worker computes and draws on: one adapter, its device and queue, and what every
//! pipeline of the crate needs from them: error scopes that turn wgpu's validation and
//! out-of-memory errors into values (wgpu's default handler panics), waits for submissions,
//! and buffer read-backs.
//!
//! Bind group layouts and bind groups are built from `Binding`s, each one buffer binding of
//! a shader (slot, variable name, access, byte size) as the WGSL declares it: `reflect` reads
//! them from the shader, so a binding list is written once, in the WGSL.

use std::sync::{mpsc, Arc};

use thiserror::Error;

/// Why the GPU could not be opened, or an operation on it failed.
#[derive(Debug, Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found ({0}); without a GPU, wgpu needs Mesa's lavapipe: install \
         mesa-vulkan-drivers (scripts/setup.sh does)"
    )]
    NoAdapter(wgpu::RequestAdapterError),
    #[error("adapter {adapter} refused a device: {source}")]
    Device { adapter: String, source: wgpu::RequestDeviceError },
    /// A validation or out-of-memory error caught by an error scope (`Gpu::scoped`), with
    /// wgpu's description (its display alone says "Validation Error").
    #[error("GPU error: {}", scope_error(.0))]
    Scope(wgpu::Error),
    /// Waiting for the device failed.
    #[error("GPU error: {0}")]
    Poll(wgpu::PollError),
    /// A buffer could not be mapped for reading.
    #[error("GPU error: {0}")]
    Map(wgpu::BufferAsyncError),
    /// One of Tessera's shaders did not parse or validate, or binds something other than a
    /// buffer (a bug of the build, caught before any pipeline is made).
    #[error("GPU error: shader {0}")]
    Shader(String),
    #[error("GPU error: readback map callback never ran")]
    MapCallbackLost,
    /// The mapped range of a buffer could not be viewed.
    #[error("GPU error: {0}")]
    MappedRange(wgpu::MapRangeError),
}

/// A headless wgpu device and its queue. Cloning is cheap (shared handles): the renderer and
/// every progressive-mesh adapter of a worker hold clones of one `Gpu`, so that the adapted
/// meshes they compute are drawn on the device they live on.
#[derive(Clone)]
pub struct Gpu {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter_name: Arc<str>,
    limits: Arc<wgpu::Limits>,
    /// A software rasteriser (lavapipe): see [`Gpu::is_software`].
    software: bool,
}

impl Gpu {
    /// Opens a headless device: a hardware adapter if there is one, otherwise a fallback
    /// (software) adapter such as lavapipe. `WGPU_BACKEND` and the other `WGPU_*` variables
    /// wgpu reads can narrow the choice. The device gets the adapter's full limits, so large
    /// meshes and frames fit whatever the adapter can hold.
    pub fn new() -> Result<Gpu, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let request = |force_fallback_adapter| {
            pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter,
                ..Default::default()
            }))
        };
        let adapter = request(false).or_else(|_| request(true)).map_err(GpuError::NoAdapter)?;
        let info = adapter.get_info();
        let adapter_name = info.name.clone();
        log::info!("gpu: adapter {adapter_name} ({:?}, {:?})", info.backend, info.device_type);
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("gpu: device"),
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|source| GpuError::Device { adapter: adapter_name.clone(), source })?;
        let software = info.device_type == wgpu::DeviceType::Cpu;
        Ok(Gpu { device, queue, adapter_name: adapter_name.into(), limits: Arc::new(limits), software })
    }

    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }

    pub fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// The device's limits (the adapter's own: see [`Gpu::new`]).
    pub fn limits(&self) -> &wgpu::Limits {
        &self.limits
    }

    /// The adapter's name, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)" for Mesa's lavapipe.
    /// Whether the adapter is a software one (lavapipe, on the CPU). Its compiler (llvmpipe)
    /// caps the loop iterations of one shader invocation at 65535 in all, so long per-thread
    /// loops must be bounded tighter there (the PM adapter's descent budget).
    pub fn is_software(&self) -> bool {
        self.software
    }

    pub fn adapter_name(&self) -> &str {
        &self.adapter_name
    }

    /// Runs `f` with the device's validation and out-of-memory errors captured and returned
    /// (a validation error first) instead of reaching wgpu's default handler, which panics.
    /// The scopes are popped in reverse order.
    pub(crate) fn scoped<T, E: From<GpuError>>(&self, f: impl FnOnce() -> Result<T, E>) -> Result<T, E> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let result = f();
        for scope in [validation, oom] {
            if let Some(e) = pollster::block_on(scope.pop()) {
                return Err(GpuError::Scope(e).into());
            }
        }
        result
    }

    /// Blocks until submission `index` has finished on the device.
    pub(crate) fn wait_for(&self, index: wgpu::SubmissionIndex) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::Wait { submission_index: Some(index), timeout: None })
            .map(drop)
            .map_err(GpuError::Poll)
    }

    /// Maps the first `bytes` bytes of a `MAP_READ` buffer (its copies submitted), waits for
    /// them, hands them to `read`, and unmaps the buffer.
    pub(crate) fn map_read<T>(
        &self,
        buffer: &wgpu::Buffer,
        bytes: u64,
        read: impl FnOnce(&[u8]) -> T,
    ) -> Result<T, GpuError> {
        let (tx, rx) = mpsc::channel();
        buffer.map_async(wgpu::MapMode::Read, ..bytes, move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(GpuError::Poll)?;
        rx.recv().map_err(|_| GpuError::MapCallbackLost)?.map_err(GpuError::Map)?;
        let out = {
            let mapped = buffer.get_mapped_range(..bytes).map_err(GpuError::MappedRange)?;
            read(&mapped)
        };
        buffer.unmap();
        Ok(out)
    }

    /// Copies the first `bytes` bytes of a `COPY_SRC` buffer into a new staging buffer
    /// labelled `label` and reads them back (for tests and tools, not for a frame's path).
    pub(crate) fn read_buffer(&self, label: &str, buffer: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
        if bytes == 0 {
            return Ok(Vec::new());
        }
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
        enc.copy_buffer_to_buffer(buffer, 0, &staging, 0, bytes);
        self.queue.submit([enc.finish()]);
        self.map_read(&staging, bytes, <[u8]>::to_vec)
    }

    /// A bind group layout with one buffer entry per row of `bindings`. A uniform's entry
    /// requires its whole block ([`Binding::bytes`]); a storage entry leaves the minimum size
    /// to wgpu's draw- and dispatch-time check against the shader.
    pub(crate) fn bind_group_layout(
        &self,
        label: &str,
        visibility: wgpu::ShaderStages,
        bindings: &[Binding],
    ) -> wgpu::BindGroupLayout {
        let entries: Vec<wgpu::BindGroupLayoutEntry> = bindings
            .iter()
            .map(|b| wgpu::BindGroupLayoutEntry {
                binding: b.slot,
                visibility,
                ty: wgpu::BindingType::Buffer {
                    ty: match b.access {
                        Access::Uniform => wgpu::BufferBindingType::Uniform,
                        Access::Read => wgpu::BufferBindingType::Storage { read_only: true },
                        Access::ReadWrite => wgpu::BufferBindingType::Storage { read_only: false },
                    },
                    has_dynamic_offset: false,
                    min_binding_size: match b.access {
                        Access::Uniform => wgpu::BufferSize::new(b.bytes),
                        Access::Read | Access::ReadWrite => None,
                    },
                },
                count: None,
            })
            .collect();
        self.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries })
    }

    /// A bind group of `layout` (made from `bindings`) that binds, whole, the buffer of
    /// `buffers` named as each binding's variable; `buffers` may name more (a caller hands
    /// every stage of a submission the same list).
    ///
    /// # Panics
    ///
    /// Unless `buffers` names every binding: a missing buffer is a bug in the caller, not a
    /// condition of the input.
    pub(crate) fn bind_group(
        &self,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        bindings: &[Binding],
        buffers: &[(&str, &wgpu::Buffer)],
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = bindings
            .iter()
            .map(|b| {
                let (_, buffer) = buffers
                    .iter()
                    .find(|(name, _)| *name == b.name)
                    .unwrap_or_else(|| panic!("{label}: no buffer for binding {} ({})", b.slot, b.name));
                wgpu::BindGroupEntry { binding: b.slot, resource: buffer.as_entire_binding() }
            })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
    }
}

/// A compute pipeline laid out from its shader's own binding lists, one per bind group (as
/// `reflect` reads them from the WGSL), with their layouts. The layouts are made once and
/// kept: `get_bind_group_layout` would register a new layout handle on every call, and
/// calling it for every bind group of every pass grew a worker's memory by megabytes a frame
/// (measured on lavapipe).
pub(crate) struct Compute {
    label: String,
    pipeline: wgpu::ComputePipeline,
    groups: Vec<(wgpu::BindGroupLayout, Vec<Binding>)>,
}

impl Compute {
    /// The pipeline of `entry` of `module`, whose bind group `g` holds `groups[g]`.
    pub(crate) fn new(
        gpu: &Gpu,
        label: &str,
        module: &wgpu::ShaderModule,
        entry: &str,
        groups: Vec<Vec<Binding>>,
    ) -> Compute {
        let groups: Vec<(wgpu::BindGroupLayout, Vec<Binding>)> = groups
            .into_iter()
            .enumerate()
            .map(|(g, b)| (gpu.bind_group_layout(&format!("{label} layout {g}"), wgpu::ShaderStages::COMPUTE, &b), b))
            .collect();
        let layouts: Vec<Option<&wgpu::BindGroupLayout>> = groups.iter().map(|(l, _)| Some(l)).collect();
        let pipeline_layout = gpu.device().create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(&format!("{label} pipeline layout")),
            bind_group_layouts: &layouts,
            immediate_size: 0,
        });
        let pipeline = gpu.device().create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(&pipeline_layout),
            module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        });
        Compute { label: label.to_string(), pipeline, groups }
    }

    /// The bind groups of this pipeline: each binding bound to the buffer of `buffers` named
    /// as its WGSL variable (`buffers` may name more: a submission hands all its stages one
    /// list).
    pub(crate) fn bind(&self, gpu: &Gpu, buffers: &[(&str, &wgpu::Buffer)]) -> Vec<wgpu::BindGroup> {
        self.groups.iter().map(|(layout, bindings)| gpu.bind_group(&self.label, layout, bindings, buffers)).collect()
    }

    /// Sets this pipeline and its bind groups (from [`Self::bind`]) on `pass`.
    pub(crate) fn set(&self, pass: &mut wgpu::ComputePass<'_>, groups: &[wgpu::BindGroup]) {
        pass.set_pipeline(&self.pipeline);
        for (g, group) in groups.iter().enumerate() {
            pass.set_bind_group(g as u32, group, &[]);
        }
    }
}

/// How a shader declares a buffer binding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Access {
    /// `var<uniform>`
    Uniform,
    /// `var<storage, read>`
    Read,
    /// `var<storage, read_write>`
    ReadWrite,
}

/// One buffer binding of a bind group, `@binding(slot) var<access> name: T`, as the WGSL
/// declares it (read by [`crate::reflect`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Binding {
    pub slot: u32,
    /// The WGSL variable's name; [`Gpu::bind_group`] takes buffers by it.
    pub name: String,
    pub access: Access,
    /// Bytes of `T`: the whole of `T` when it is sized (a uniform block, a fixed-size array),
    /// one element when `T` is a runtime-sized array.
    pub bytes: u64,
    /// The name of `T` (or of its element), for messages.
    pub ty: String,
}

/// What a caught GPU error says: its kind, and for a validation or internal error wgpu's
/// description on one line.
fn scope_error(e: &wgpu::Error) -> String {
    match e {
        wgpu::Error::Validation { description, .. } | wgpu::Error::Internal { description, .. } => {
            let said = e.to_string().lines().next().unwrap_or("").trim().to_string();
            let lines: Vec<&str> = description
                .lines()
                .map(str::trim)
                .filter(|l| !l.is_empty() && *l != said && *l != "Caused by:")
                .collect();
            format!("{said}: {}", lines.join(": "))
        }
        e => e.to_string(),
    }
}
