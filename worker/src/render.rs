//! Headless wgpu tile renderer: draws a [`RenderMesh`] into one rectangle of a frame and
//! reads the pixels back as tightly packed RGBA8 rows.
//!
//! Tiles are pixel-exact crops of the full frame because a tile is the full frame's draw,
//! limited by a scissor rect: the render target has the frame's size, and the pipeline state,
//! viewport and `view_proj` are the full frame's, so every pixel inside the tile is computed
//! by the same arithmetic. A first draw under the scissor clears the tile (a load-op clear
//! would clear the whole frame); the copy to the readback buffer takes only the tile. This
//! costs a frame-sized color and depth buffer per renderer (8 bytes a pixel, zero-filled once
//! by wgpu), but neither a per-call whole-frame clear nor rasterization outside the tile.
//!
//! The cheaper-looking alternatives, a tile-sized target with the viewport moved to
//! `(-x0, -y0, W, H)` (which wgpu 30 accepts) or a sub-frustum projection, are not exact on
//! lavapipe: moving the origin changes the magnitude, hence the rounding, of the window
//! coordinates and of the interpolation set up from them. Measured on the bunny at 1920x1080
//! in 3x2 tiles, the moved viewport gave the same coverage but 32 of 266,459 covered pixels
//! one level off in color; the sub-frustum also flipped the coverage of some pixels.
//!
//! The shading is `worker/src/render.wgsl`: a light grey, two-sided Lambert plus ambient under a
//! headlight, on a transparent background; there is no culling, as meshes may be
//! inconsistently oriented.

use std::sync::OnceLock;
use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec4};
use thiserror::Error;

use crate::gpu::{Binding, Gpu, GpuError};
use crate::reflect::Reflected;
use crate::RenderMesh;

/// A mesh that is already on the device, in the layout of the GPU progressive-mesh
/// adaptation (`crate::pm_adapt`), drawn by vertex pulling (`vs_pulled` in
/// `worker/src/render.wgsl`): the index buffer holds active-vertex indices, and each vertex reads
/// its position and normal.
#[derive(Clone, Copy)]
pub struct AdaptedMesh<'a> {
    /// Position and normal per active vertex ([`PmPoint`], `STORAGE`).
    pub points: &'a wgpu::Buffer,
    /// Active-vertex indices, 3 per triangle (`u32`, `INDEX`).
    pub indices: &'a wgpu::Buffer,
    /// How many of `indices` to draw.
    pub index_count: u32,
}

/// One active vertex's position and unit normal, `w` unused: `PmPoint` of `render.wgsl`,
/// `Point` of `pm/common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PmPoint {
    pub pos: [f32; 4],
    pub nrm: [f32; 4],
}

/// What a tile draws: an uploaded mesh, or a mesh adapted on the GPU, drawn from its own
/// buffers.
#[derive(Clone, Copy)]
enum Source<'a> {
    /// A mesh uploaded for this frame and meshes already on the device, drawn in order.
    Parts(&'a RenderMesh, &'a [Draw<'a>]),
    Pm(AdaptedMesh<'a>),
}

/// One draw of [`Renderer::render_parts`].
#[derive(Clone, Debug)]
pub enum Draw<'a> {
    /// These indices of the mesh uploaded for the frame.
    Joined(std::ops::Range<u32>),
    /// A mesh kept on the device.
    Resident(&'a GpuMesh),
}

/// A decoded mesh's buffers on the device ([`Renderer::upload`]): a worker that keeps a mesh
/// from frame to frame keeps these too, and a later frame draws it without uploading it
/// again ([`Renderer::render_parts`]).
#[derive(Debug)]
pub struct GpuMesh {
    positions: wgpu::Buffer,
    normals: wgpu::Buffer,
    colors: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
}

/// The renderer's shaders (`render.wgsl`, beside this file): two pipelines drawn under the
/// tile's scissor rect into a frame-sized target, `clear_vs`/`clear_fs` (resets the tile to
/// transparent black and the far depth) and `vs_main`/`fs_main` (the mesh), with the uniform
/// block `Frame { view_proj, eye }` at group 0, binding 0, and positions and normals at vertex
/// locations 0 and 1; `vs_pulled` draws a progressive mesh adapted on the GPU straight from
/// its buffers (the vertex's FVID at group 1, binding 0; that FVID's position and normal at
/// binding 1).
pub(crate) const SHADER: &str = include_str!("render.wgsl");

/// Bind group 0 of the mesh pipelines: the frame uniform, read by both shader stages.
pub(crate) const FRAME_GROUP: u32 = 0;
/// Bind group 1 of the pulled pipeline: the adapted mesh's buffers, read by `vs_pulled`.
pub(crate) const PULLED_GROUP: u32 = 1;

/// The bindings of [`FRAME_GROUP`], then of [`PULLED_GROUP`].
type GroupBindings = (Vec<Binding>, Vec<Binding>);

/// The bindings of [`FRAME_GROUP`] and [`PULLED_GROUP`], as [`SHADER`] declares them, read
/// once per process.
fn shader_bindings() -> Result<&'static GroupBindings, GpuError> {
    static BINDINGS: OnceLock<Result<GroupBindings, String>> = OnceLock::new();
    let read = || {
        let shader = Reflected::parse("render.wgsl", SHADER)?;
        Ok((
            shader.bindings(&["vs_main", "vs_pulled", "fs_main"], FRAME_GROUP)?,
            shader.bindings(&["vs_pulled"], PULLED_GROUP)?,
        ))
    };
    BINDINGS.get_or_init(read).as_ref().map_err(|e| GpuError::Shader(e.clone()))
}

const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
const BYTES_PER_PIXEL: u32 = 4;
/// Byte size of one position or normal.
const VEC3_BYTES: u64 = std::mem::size_of::<[f32; 3]>() as u64;
const POSITION_ATTRIBUTE: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![0 => Float32x3];
const NORMAL_ATTRIBUTE: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![1 => Float32x3];
/// Vertex colours, RGBA8 read as 0..1; alpha 0 marks a mesh without colours (see
/// `worker/src/render.wgsl`).
const COLOR_ATTRIBUTE: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![2 => Unorm8x4];

/// Why the renderer could not start or render.
#[derive(Debug, Error)]
pub enum RenderError {
    #[error("rect {rect:?} is not a non-empty part of the {width}x{height} frame")]
    BadRect { rect: [u32; 4], width: u32, height: u32 },
    #[error("frame {width}x{height} exceeds the adapter's largest texture side, {max}")]
    FrameTooLarge { width: u32, height: u32, max: u32 },
    #[error("mesh has {positions} positions but {normals} normals")]
    NormalCount { positions: usize, normals: usize },
    #[error("mesh has {positions} positions but {colors} colours")]
    ColorCount { positions: usize, colors: usize },
    #[error("a draw of indices {start}..{end} of a mesh of {indices}")]
    BadDraw { start: u32, end: u32, indices: u32 },
    #[error("the mesh's {what} buffer needs {bytes} bytes; the adapter allows {max}")]
    MeshTooLarge { what: &'static str, bytes: u64, max: u64 },
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// Wall-clock milliseconds of the three stages of [`Renderer::render`], each waited for
/// on the device before the next starts so that they can be told apart.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderTimes {
    /// Mesh and uniform writes until the device has them.
    pub upload_ms: f64,
    /// Clear, draw, and wait for the draw to finish.
    pub render_ms: f64,
    /// Texture-to-buffer copy, map, and removal of the row padding.
    pub readback_ms: f64,
}

/// The uniform block of `render.wgsl`, `Frame`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct FrameUniform {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
}

/// A GPU buffer that is replaced by a larger one only when the data outgrows it.
struct GrowBuffer {
    label: &'static str,
    usage: wgpu::BufferUsages,
    buffer: Option<wgpu::Buffer>,
}

impl GrowBuffer {
    fn new(label: &'static str, usage: wgpu::BufferUsages) -> GrowBuffer {
        GrowBuffer { label, usage: usage | wgpu::BufferUsages::COPY_DST, buffer: None }
    }

    /// Queues `data` for upload (nothing for empty data). Capacity grows to the next power of
    /// two, capped at `max`, so a worker whose tile mesh grows slowly reallocates rarely.
    fn write(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, data: &[u8], max: u64) -> Result<(), RenderError> {
        let len = data.len() as u64;
        if len == 0 {
            return Ok(());
        }
        if len > max {
            return Err(RenderError::MeshTooLarge { what: self.label, bytes: len, max });
        }
        if self.buffer.as_ref().is_none_or(|b| b.size() < len) {
            self.buffer = Some(device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(self.label),
                size: len.next_power_of_two().min(max),
                usage: self.usage,
                mapped_at_creation: false,
            }));
        }
        queue.write_buffer(self.buffer.as_ref().expect("allocated above"), 0, data);
        Ok(())
    }

    /// The first `len` bytes (`len > 0`, and written by [`GrowBuffer::write`]).
    fn slice(&self, len: u64) -> wgpu::BufferSlice<'_> {
        self.buffer.as_ref().expect("written before drawing").slice(..len)
    }
}

/// Frame-sized color and depth attachments, kept while the frame size stays the same.
struct FrameTarget {
    size: (u32, u32),
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth: wgpu::Texture,
    depth_view: wgpu::TextureView,
}

impl FrameTarget {
    fn new(device: &wgpu::Device, (width, height): (u32, u32)) -> FrameTarget {
        let texture = |label, format, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let color = texture(
            "render: color target",
            COLOR_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        // Copied out for occlusion culling ([`Renderer::read_depth`]).
        let depth = texture(
            "render: depth buffer",
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let color_view = color.create_view(&wgpu::TextureViewDescriptor {
            label: Some("render: color target view"),
            ..Default::default()
        });
        let depth_view = depth.create_view(&wgpu::TextureViewDescriptor {
            label: Some("render: depth buffer view"),
            ..Default::default()
        });
        FrameTarget { size: (width, height), color, color_view, depth, depth_view }
    }
}

/// The tile pipelines on a [`Gpu`], and the buffers and targets they reuse across calls: a
/// worker renders the same tiles of the same frame size every frame, so after the first
/// frame a call allocates only when its mesh or tile outgrows the previous ones.
pub struct Renderer {
    gpu: Gpu,
    clear_pipeline: wgpu::RenderPipeline,
    mesh_pipeline: wgpu::RenderPipeline,
    /// The mesh pipeline with vertices pulled from an [`AdaptedMesh`]'s buffers (`vs_pulled`).
    pulled_pipeline: wgpu::RenderPipeline,
    pulled_layout: wgpu::BindGroupLayout,
    /// `pulled_layout`'s bindings.
    pulled_bindings: &'static [Binding],
    uniform: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    positions: GrowBuffer,
    normals: GrowBuffer,
    colors: GrowBuffer,
    /// Alpha-0 colours (the mark of a mesh without colours), kept for such meshes.
    no_colors: Vec<[u8; 4]>,
    indices: GrowBuffer,
    frame_target: Option<FrameTarget>,
    /// The mappable buffer tiles are copied into, rows padded to `COPY_BYTES_PER_ROW_ALIGNMENT`.
    readback: Option<wgpu::Buffer>,
}

impl Renderer {
    /// Creates the tile pipelines on `gpu`'s device.
    pub fn new(gpu: &Gpu) -> Result<Renderer, GpuError> {
        let (frame_bindings, pulled_bindings) = shader_bindings()?;
        let device = gpu.device();
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("render: shader"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let bind_group_layout =
            gpu.bind_group_layout("render: frame uniform layout", wgpu::ShaderStages::VERTEX_FRAGMENT, frame_bindings);
        let depth_stencil = |depth_compare| wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(depth_compare),
            stencil: Default::default(),
            bias: Default::default(),
        };
        let color_targets = [Some(COLOR_FORMAT.into())];
        let clear_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("render: clear pipeline layout"),
            bind_group_layouts: &[],
            immediate_size: 0,
        });
        let clear_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("render: clear pipeline"),
            layout: Some(&clear_layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("clear_vs"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: Some(depth_stencil(wgpu::CompareFunction::Always)),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &shader,
                entry_point: Some("clear_fs"),
                compilation_options: Default::default(),
                targets: &color_targets,
            }),
            multiview_mask: None,
            cache: None,
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("render: mesh pipeline layout"),
            bind_group_layouts: &[Some(&bind_group_layout)],
            immediate_size: 0,
        });
        let vec3_layout = |attributes| wgpu::VertexBufferLayout {
            array_stride: VEC3_BYTES,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes,
        };
        // The shaded pipelines differ in their vertex input only: vertex buffers or pulling.
        let shaded_pipeline = |label: &str,
                               layout: &wgpu::PipelineLayout,
                               entry_point: &str,
                               buffers: &[Option<wgpu::VertexBufferLayout>]| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(layout),
                vertex: wgpu::VertexState {
                    module: &shader,
                    entry_point: Some(entry_point),
                    compilation_options: Default::default(),
                    buffers,
                },
                primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
                depth_stencil: Some(depth_stencil(wgpu::CompareFunction::Less)),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &shader,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &color_targets,
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        // Positions and normals stay in separate buffers, uploaded straight from the
        // RenderMesh vectors without interleaving.
        let mesh_pipeline = shaded_pipeline(
            "render: mesh pipeline",
            &layout,
            "vs_main",
            &[
                Some(vec3_layout(&POSITION_ATTRIBUTE)),
                Some(vec3_layout(&NORMAL_ATTRIBUTE)),
                Some(wgpu::VertexBufferLayout {
                    array_stride: 4,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &COLOR_ATTRIBUTE,
                }),
            ],
        );
        let pulled_layout =
            gpu.bind_group_layout("render: pulled vertices layout", wgpu::ShaderStages::VERTEX, pulled_bindings);
        // Indexed by group: FRAME_GROUP, PULLED_GROUP.
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("render: pulled pipeline layout"),
            bind_group_layouts: &[Some(&bind_group_layout), Some(&pulled_layout)],
            immediate_size: 0,
        });
        let pulled_pipeline = shaded_pipeline("render: pulled pipeline", &layout, "vs_pulled", &[]);
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("upload: frame uniform"),
            size: std::mem::size_of::<FrameUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group =
            gpu.bind_group("render: frame uniform", &bind_group_layout, frame_bindings, &[("frame", &uniform)]);
        Ok(Renderer {
            gpu: gpu.clone(),
            clear_pipeline,
            mesh_pipeline,
            pulled_pipeline,
            pulled_layout,
            pulled_bindings,
            uniform,
            bind_group,
            positions: GrowBuffer::new("upload: positions", wgpu::BufferUsages::VERTEX),
            normals: GrowBuffer::new("upload: normals", wgpu::BufferUsages::VERTEX),
            colors: GrowBuffer::new("upload: colours", wgpu::BufferUsages::VERTEX),
            no_colors: Vec::new(),
            indices: GrowBuffer::new("upload: indices", wgpu::BufferUsages::INDEX),
            frame_target: None,
            readback: None,
        })
    }

    /// The GPU this renderer draws on.
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// Renders the part `rect = [x0, y0, x1, y1]` (pixels, half-open, origin top-left) of a
    /// `frame.0 x frame.1` frame seen through `view_proj`, and returns its RGBA8 pixels, rows
    /// top first, `(x1 - x0) * 4` bytes each. `rect = [0, 0, W, H]` is the whole frame; any
    /// other rect gives exactly the same bytes as cropping the whole frame. Uncovered pixels
    /// are `(0, 0, 0, 0)`, covered ones opaque.
    ///
    /// Indices are not checked against the vertex count: out-of-range ones read defined but
    /// unspecified values (wgpu's robust buffer access), not other memory.
    pub fn render(
        &mut self,
        mesh: &RenderMesh,
        view_proj: Mat4,
        frame: (u32, u32),
        rect: [u32; 4],
    ) -> Result<(Vec<u8>, RenderTimes), RenderError> {
        self.render_parts(mesh, &[Draw::Joined(0..mesh.indices.len() as u32)], view_proj, frame, rect)
    }

    /// Uploads `mesh` into buffers of its own, to be drawn by [`Renderer::render_parts`] in
    /// this and later frames; `None` for a mesh without triangles. Returns the milliseconds
    /// until the device has them.
    pub fn upload(&mut self, mesh: &RenderMesh) -> Result<(Option<GpuMesh>, f64), RenderError> {
        use wgpu::util::DeviceExt;
        check_counts(mesh)?;
        if mesh.indices.is_empty() {
            return Ok((None, 0.0));
        }
        let start = Instant::now();
        let max = self.gpu.limits().max_buffer_size;
        let gpu = self.gpu.clone();
        let device = gpu.device();
        let fits = |what: &'static str, bytes: u64| -> Result<(), RenderError> {
            match bytes > max {
                true => Err(RenderError::MeshTooLarge { what, bytes, max }),
                false => Ok(()),
            }
        };
        let buffer = |label: &'static str, contents: &[u8], usage| -> Result<wgpu::Buffer, RenderError> {
            fits(label, contents.len() as u64)?;
            Ok(device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage }))
        };
        let mesh = gpu.scoped(|| -> Result<GpuMesh, RenderError> {
            let colors = match mesh.colors.is_empty() {
                // Zero-filled by wgpu: alpha 0, the renderer's grey (as `render` draws it).
                true => {
                    let size = mesh.positions.len() as u64 * 4;
                    fits("resident: colours", size)?;
                    device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some("resident: colours"),
                        size,
                        usage: wgpu::BufferUsages::VERTEX,
                        mapped_at_creation: false,
                    })
                }
                false => buffer("resident: colours", bytemuck::cast_slice(&mesh.colors), wgpu::BufferUsages::VERTEX)?,
            };
            Ok(GpuMesh {
                positions: buffer(
                    "resident: positions",
                    bytemuck::cast_slice(&mesh.positions),
                    wgpu::BufferUsages::VERTEX,
                )?,
                normals: buffer("resident: normals", bytemuck::cast_slice(&mesh.normals), wgpu::BufferUsages::VERTEX)?,
                colors,
                indices: buffer("resident: indices", bytemuck::cast_slice(&mesh.indices), wgpu::BufferUsages::INDEX)?,
                index_count: mesh.indices.len() as u32,
            })
        })?;
        Ok((Some(mesh), ms_since(start)))
    }

    /// Renders `draws` in order: ranges of `joined`'s indices (`joined` uploaded into the
    /// renderer's own buffers, which grow as meshes do) and meshes already on the device. The
    /// pixels are [`Renderer::render`]'s of all of them joined into one mesh in that order:
    /// the same triangles reach the rasterizer in the same order.
    pub fn render_parts(
        &mut self,
        joined: &RenderMesh,
        draws: &[Draw<'_>],
        view_proj: Mat4,
        frame: (u32, u32),
        rect: [u32; 4],
    ) -> Result<(Vec<u8>, RenderTimes), RenderError> {
        check_counts(joined)?;
        let n = joined.indices.len() as u32;
        if let Some(Draw::Joined(r)) =
            draws.iter().find(|d| matches!(d, Draw::Joined(r) if r.start > r.end || r.end > n))
        {
            return Err(RenderError::BadDraw { start: r.start, end: r.end, indices: n });
        }
        self.render_source(Source::Parts(joined, draws), view_proj, frame, rect)
    }

    /// The largest rectangle side one render can have (the device's texture limit).
    pub fn max_side(&self) -> u32 {
        self.gpu.limits().max_texture_dimension_2d
    }

    /// Renders an adapted mesh (`GpuAdapter::mesh`) as [`Renderer::render`] renders a
    /// [`RenderMesh`], but straight from its GPU buffers: nothing is uploaded or read back but
    /// the pixels (its upload time is the frame uniform's). `pm` must live on this renderer's
    /// device.
    pub fn render_pm(
        &mut self,
        pm: AdaptedMesh<'_>,
        view_proj: Mat4,
        frame: (u32, u32),
        rect: [u32; 4],
    ) -> Result<(Vec<u8>, RenderTimes), RenderError> {
        self.render_source(Source::Pm(pm), view_proj, frame, rect)
    }

    fn render_source(
        &mut self,
        source: Source<'_>,
        view_proj: Mat4,
        frame: (u32, u32),
        rect: [u32; 4],
    ) -> Result<(Vec<u8>, RenderTimes), RenderError> {
        let (width, height) = frame;
        let [x0, y0, x1, y1] = rect;
        if !(x0 < x1 && x1 <= width && y0 < y1 && y1 <= height) {
            return Err(RenderError::BadRect { rect, width, height });
        }
        // The frame is a texture.
        let max = self.gpu.limits().max_texture_dimension_2d;
        if width > max || height > max {
            return Err(RenderError::FrameTooLarge { width, height, max });
        }
        let gpu = self.gpu.clone();
        gpu.scoped(|| self.render_unscoped(source, view_proj, frame, rect))
    }

    fn render_unscoped(
        &mut self,
        source: Source<'_>,
        view_proj: Mat4,
        (width, height): (u32, u32),
        [x0, y0, x1, y1]: [u32; 4],
    ) -> Result<(Vec<u8>, RenderTimes), RenderError> {
        let size = (x1 - x0, y1 - y0);
        let start = Instant::now();
        let max = self.gpu.limits().max_buffer_size;
        let (device, queue) = (self.gpu.device(), self.gpu.queue());
        let pulled = match source {
            Source::Parts(mesh, _) => {
                self.positions.write(device, queue, bytemuck::cast_slice(&mesh.positions), max)?;
                self.normals.write(device, queue, bytemuck::cast_slice(&mesh.normals), max)?;
                let colors = if mesh.colors.is_empty() {
                    self.no_colors.resize(mesh.positions.len(), [0; 4]);
                    &self.no_colors[..mesh.positions.len()]
                } else {
                    &mesh.colors[..]
                };
                self.colors.write(device, queue, bytemuck::cast_slice(colors), max)?;
                self.indices.write(device, queue, bytemuck::cast_slice(&mesh.indices), max)?;
                None
            }
            Source::Pm(pm) => Some(self.gpu.bind_group(
                "render: pulled vertices",
                &self.pulled_layout,
                self.pulled_bindings,
                &[("pm_points", pm.points)],
            )),
        };
        // The eye is the point the projection sends to infinity: clip (0, 0, 1, 0) back in
        // world space, up to a scale (see `Frame::eye` in render.wgsl).
        let eye = view_proj.inverse() * Vec4::Z;
        let uniform = FrameUniform { view_proj: view_proj.to_cols_array_2d(), eye: eye.to_array() };
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&uniform));
        // An empty submission flushes the queued writes.
        self.gpu.wait_for(queue.submit([]))?;
        let upload_ms = ms_since(start);

        let start = Instant::now();
        if self.frame_target.as_ref().is_none_or(|t| t.size != (width, height)) {
            self.frame_target = Some(FrameTarget::new(device, (width, height)));
        }
        let target = self.frame_target.as_ref().expect("created above");
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("render: draw") });
        {
            // Load, not clear: a load-op clear would clear the whole frame, and only the
            // tile is drawn (and cleared, by the first draw) under the scissor.
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("render: pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &target.color_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Store },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &target.depth_view,
                    // Stored: a discarded depth buffer would be zero-filled, whole, by wgpu
                    // before the next load.
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_scissor_rect(x0, y0, size.0, size.1);
            pass.set_pipeline(&self.clear_pipeline);
            pass.draw(0..3, 0..1);
            match (source, &pulled) {
                (Source::Parts(joined, draws), _) => {
                    pass.set_pipeline(&self.mesh_pipeline);
                    pass.set_bind_group(FRAME_GROUP, &self.bind_group, &[]);
                    let vertex_bytes = joined.positions.len() as u64 * VEC3_BYTES;
                    let index_bytes = joined.indices.len() as u64 * 4;
                    for draw in draws {
                        match draw {
                            Draw::Joined(range) if !range.is_empty() => {
                                pass.set_vertex_buffer(0, self.positions.slice(vertex_bytes));
                                pass.set_vertex_buffer(1, self.normals.slice(vertex_bytes));
                                pass.set_vertex_buffer(2, self.colors.slice(joined.positions.len() as u64 * 4));
                                pass.set_index_buffer(self.indices.slice(index_bytes), wgpu::IndexFormat::Uint32);
                                pass.draw_indexed(range.clone(), 0, 0..1);
                            }
                            Draw::Joined(_) => {}
                            Draw::Resident(part) => {
                                pass.set_vertex_buffer(0, part.positions.slice(..));
                                pass.set_vertex_buffer(1, part.normals.slice(..));
                                pass.set_vertex_buffer(2, part.colors.slice(..));
                                pass.set_index_buffer(part.indices.slice(..), wgpu::IndexFormat::Uint32);
                                pass.draw_indexed(0..part.index_count, 0, 0..1);
                            }
                        }
                    }
                }
                (Source::Pm(pm), Some(bind_group)) => {
                    if pm.index_count > 0 {
                        pass.set_pipeline(&self.pulled_pipeline);
                        pass.set_bind_group(FRAME_GROUP, &self.bind_group, &[]);
                        pass.set_bind_group(PULLED_GROUP, bind_group, &[]);
                        pass.set_index_buffer(pm.indices.slice(..pm.index_count as u64 * 4), wgpu::IndexFormat::Uint32);
                        pass.draw_indexed(0..pm.index_count, 0, 0..1);
                    }
                }
                (Source::Pm(_), None) => unreachable!("the pulled bind group is made for every PM source"),
            }
        }
        self.gpu.wait_for(queue.submit([encoder.finish()]))?;
        let render_ms = ms_since(start);

        let start = Instant::now();
        let color = wgpu::TexelCopyTextureInfo {
            texture: &target.color,
            mip_level: 0,
            origin: wgpu::Origin3d { x: x0, y: y0, z: 0 },
            aspect: wgpu::TextureAspect::All,
        };
        let pixels = read_back(&self.gpu, &mut self.readback, color, size, BYTES_PER_PIXEL)?;
        let readback_ms = ms_since(start);
        Ok((pixels, RenderTimes { upload_ms, render_ms, readback_ms }))
    }
}

impl Renderer {
    /// The depth buffer over `rect` of the last frame drawn, row by row (1 where nothing was
    /// drawn): what occlusion culling one frame late builds its pyramid from
    /// ([`crate::pm_adapt::occlusion::Occluder`]).
    pub fn read_depth(&mut self, rect: [u32; 4]) -> Result<Vec<f32>, RenderError> {
        let gpu = self.gpu.clone();
        gpu.scoped(|| self.read_depth_unscoped(rect))
    }

    fn read_depth_unscoped(&mut self, [x0, y0, x1, y1]: [u32; 4]) -> Result<Vec<f32>, RenderError> {
        let Some(target) = self.frame_target.as_ref() else {
            return Ok(Vec::new());
        };
        let (width, height) = target.size;
        if !(x0 < x1 && x1 <= width && y0 < y1 && y1 <= height) {
            return Err(RenderError::BadRect { rect: [x0, y0, x1, y1], width, height });
        }
        // A depth texture is copied whole (wgpu allows no partial copy of one), then the
        // rectangle is cut out.
        let depth = wgpu::TexelCopyTextureInfo {
            texture: &target.depth,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::DepthOnly,
        };
        let bytes = read_back(&self.gpu, &mut self.readback, depth, (width, height), 4)?;
        let row = width as usize * 4;
        Ok(bytes
            .chunks_exact(row)
            .skip(y0 as usize)
            .take((y1 - y0) as usize)
            .flat_map(|r| r[x0 as usize * 4..x1 as usize * 4].chunks_exact(4))
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect())
    }
}

/// Copies `size` texels of `copy` (`texel_bytes` each) into `kept`, the renderer's readback
/// buffer (grown when too small, then kept: a worker's tiles of an uneven grid differ by a
/// pixel or so), and returns them row by row, the copy's row padding dropped.
fn read_back(
    gpu: &Gpu,
    kept: &mut Option<wgpu::Buffer>,
    copy: wgpu::TexelCopyTextureInfo<'_>,
    size: (u32, u32),
    texel_bytes: u32,
) -> Result<Vec<u8>, GpuError> {
    let padded_row = (size.0 * texel_bytes).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let bytes = padded_row as u64 * size.1 as u64;
    if kept.as_ref().is_none_or(|b| b.size() < bytes) {
        *kept = Some(gpu.device().create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        }));
    }
    let buffer = kept.as_ref().expect("created above");
    let mut encoder = gpu.device().create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
    encoder.copy_texture_to_buffer(
        copy,
        wgpu::TexelCopyBufferInfo {
            buffer,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(padded_row), rows_per_image: None },
        },
        wgpu::Extent3d { width: size.0, height: size.1, depth_or_array_layers: 1 },
    );
    gpu.queue().submit([encoder.finish()]);
    let row = (size.0 * texel_bytes) as usize;
    gpu.map_read(buffer, bytes, |mapped| {
        let mut out = Vec::with_capacity(row * size.1 as usize);
        for padded in mapped.chunks_exact(padded_row as usize) {
            out.extend_from_slice(&padded[..row]);
        }
        out
    })
}

/// A mesh's per-vertex arrays are as long as its positions.
fn check_counts(mesh: &RenderMesh) -> Result<(), RenderError> {
    if mesh.normals.len() != mesh.positions.len() {
        return Err(RenderError::NormalCount { positions: mesh.positions.len(), normals: mesh.normals.len() });
    }
    if !mesh.colors.is_empty() && mesh.colors.len() != mesh.positions.len() {
        return Err(RenderError::ColorCount { positions: mesh.positions.len(), colors: mesh.colors.len() });
    }
    Ok(())
}

fn ms_since(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}
