//! A progressive mesh (`.dpm`) on a worker, in core or read out of core from its file,
//! adapted on the GPU once per frame for all of the worker's tiles.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use codec::pm::Viewpoint;
use glam::{Mat4, Vec3};
use protocol::{PixelCodec, PmFrameJob, PmMemory, TilePixels, TileTimes, ToWorker};

use super::model::{wrong_kind, Model, Rendered};
use super::tiles::{crop, tile_groups, TileGroup};
use super::{TileError, WorkerError};
use crate::gpu::Gpu;
use crate::pm_adapt::occlusion::Occluder;
use crate::pm_adapt::{AdaptError, GpuAdapter, OutOfCore, DEFAULT_N_ALLOC};
use crate::render::Renderer;

impl Model for PmTiles {
    fn frame(&mut self, renderer: &mut Renderer, msg: ToWorker) -> Result<Option<Rendered>, WorkerError> {
        let ToWorker::PmFrame(job) = msg else { return Err(wrong_kind(&msg)) };
        let (tiles, memory) = self.render(renderer, &job)?;
        Ok(Some(Rendered { frame: job.frame, tiles, memory, prepared_ms: None }))
    }
}

/// A progressive mesh on this worker's GPU, adapted once per frame for all of the worker's
/// tiles: to the sub-frustum of their bounding rectangle (refined inside it, coarsened
/// outside with the c_LOD falloff), then drawn once under that rectangle and cut into tiles. The adaptation's cost follows the worker's screen
/// region and the change of view, not its tile count (issue 16: per-tile adaptations cost
/// 2.5x one adaptation of the same screen in 8x8 tiles, each tile converging separately).
/// Rank 0 deals a progressive mesh's tiles to workers in contiguous runs, so a worker's
/// rectangle is its share of the frame. It also keeps the mesh coherent from frame to frame:
/// one adaptation state, whatever tiles come.
///
/// An out-of-core file ([`PmTiles::open`]) is read by each worker from its path, node by node
/// on a loader thread, the nodes kept within the GPU budget by the paper's priority for the
/// worker's region of the frame. A frame schedules the nodes its view wants, adapts, and when
/// the mesh has converged while nodes are still on their way, waits for them and goes on (an
/// offline frame is drawn from the nodes its view needs; the paper's interactive renderer
/// would draw at once and refine over the next frames).
pub(super) struct PmTiles {
    adapter: GpuAdapter,
    /// Node bytes uploaded up to the end of the last frame (out of core).
    uploaded: u64,
}

impl PmTiles {
    /// An in-core `.dpm`, its adaptation within `gpu_budget` bytes of graphics memory.
    pub(super) fn new(gpu: &Gpu, dpm: &[u8], gpu_budget: u64) -> Result<PmTiles, WorkerError> {
        let dpm = codec::pm::format::Dpm::parse(dpm).map_err(WorkerError::Model)?;
        let mut adapter = GpuAdapter::new(gpu, &dpm, DEFAULT_N_ALLOC).map_err(WorkerError::Upload)?;
        adapter.set_budget(Some(gpu_budget)).map_err(WorkerError::Upload)?;
        Ok(PmTiles { adapter, uploaded: 0 })
    }

    /// An out-of-core `.dpm` at `path`, its adaptation within `gpu_budget` bytes of graphics
    /// memory, `pool_bytes` of them for nodes.
    pub(super) fn open(gpu: &Gpu, path: &Path, gpu_budget: u64, pool_bytes: u64) -> Result<PmTiles, WorkerError> {
        let named = |error| WorkerError::ModelFile { path: path.display().to_string(), error };
        let file = Arc::new(codec::pm::format::NodeFile::open(path).map_err(named)?);
        let dpm = codec::pm::format::Dpm::parse_prefix(file.prefix()).map_err(named)?;
        let ooc = OutOfCore { file: file.clone(), pool_bytes, background: true };
        let mut adapter = GpuAdapter::out_of_core(gpu, &dpm, ooc, DEFAULT_N_ALLOC).map_err(WorkerError::Upload)?;
        adapter.set_budget(Some(gpu_budget)).map_err(WorkerError::Upload)?;
        Ok(PmTiles { adapter, uploaded: 0 })
    }

    /// Adapts the mesh to the sub-frustum of `job`'s tiles' bounding rectangle (until
    /// converged or `max_passes`) and renders every tile from it.
    fn render(
        &mut self,
        renderer: &mut Renderer,
        job: &PmFrameJob,
    ) -> Result<(Vec<TilePixels>, PmMemory), WorkerError> {
        let view_proj = Mat4::from_cols_array(&job.view_proj);
        let view = Viewpoint {
            view_proj,
            eye: Vec3::from(job.eye),
            width: job.width,
            height: job.height,
            error_px: job.error_px,
            pixels_per_unit: job.pixels_per_unit,
            c_lod: job.c_lod,
            attribute_scale: job.attribute_scale,
        };
        let Some(&(first, _)) = job.tiles.first() else {
            return Ok((Vec::new(), PmMemory::default()));
        };
        let mut region = [u32::MAX, u32::MAX, 0, 0];
        for &(index, [x0, y0, x1, y1]) in &job.tiles {
            if !(x0 < x1 && x1 <= job.width && y0 < y1 && y1 <= job.height) {
                return Err(TileError::BadRect([x0, y0, x1, y1]).at(index));
            }
            region = [region[0].min(x0), region[1].min(y0), region[2].max(x1), region[3].max(y1)];
        }
        let region_view = view.for_tile(region);
        let start = Instant::now();
        let at = |e: AdaptError| TileError::from(e).at(first);
        if !job.occlusion {
            self.adapter.set_occluder(None);
        }
        let cache = self.adapter.schedule(&region_view).map_err(at)?;
        for _ in 0..job.max_passes.max(1) {
            if self.adapter.adapt(&region_view).map_err(at)?.converged() {
                if self.adapter.nodes_in_flight() == 0 {
                    break;
                }
                self.adapter.wait_for_nodes().map_err(at)?;
            }
        }
        // A pass checks the operations the one before decoded; the last one is checked here.
        self.adapter.check().map_err(|e| TileError::from(e).at(first))?;
        // The one adaptation, shared out among the tiles for the load balancer.
        let adapt_ms = start.elapsed().as_secs_f64() * 1e3 / job.tiles.len() as f64;
        let triangles = self.adapter.counts().1;
        // The region is drawn once and the tiles are cut out of it (a tile is an exact crop
        // of the frame however large the scissor, `worker::render`): every draw processes the
        // whole adapted mesh, so one draw costs what one tile's would (measured on the dragon
        // in 8x8 tiles: 105-192 ms a frame against 390-811 ms in 4x4-block groups). A region
        // larger than a texture falls back to groups.
        let groups = if region[2] - region[0] <= renderer.max_side() && region[3] - region[1] <= renderer.max_side() {
            vec![TileGroup { key: 0, rect: region, tiles: job.tiles.clone() }]
        } else {
            tile_groups(&job.tiles, job.width, job.height)
        };
        let uploaded = self.adapter.uploaded_bytes();
        let memory = PmMemory {
            gpu_bytes: self.adapter.gpu_bytes(),
            loaded_bytes: uploaded - self.uploaded,
            resident_nodes: self.adapter.nodes_resident() as u32,
            required_nodes: cache.map_or(0, |c| c.required as u32),
            slots: self.adapter.node_slots().unwrap_or(0),
            error_scale: self.adapter.error_scale(),
        };
        self.uploaded = uploaded;
        let mut out = Vec::with_capacity(job.tiles.len());
        for group in &groups {
            let first = group.tiles[0].0;
            let (group_rgba, group_times) = renderer
                .render_pm(self.adapter.mesh(), view_proj, (job.width, job.height), group.rect)
                .map_err(|e| TileError::from(e).at(first))?;
            let share = 1.0 / group.tiles.len() as f64;
            for &(index, rect) in &group.tiles {
                out.push(TilePixels {
                    index,
                    rect,
                    times: TileTimes {
                        decode_ms: 0.0,
                        adapt_ms,
                        upload_ms: group_times.upload_ms * share,
                        render_ms: group_times.render_ms * share,
                        readback_ms: group_times.readback_ms * share,
                        encode_ms: 0.0,
                    },
                    triangles,
                    reused: 0,
                    codec: PixelCodec::Raw,
                    coded_bytes: 0,
                    pixels: crop(&group_rgba, group.rect, rect),
                });
            }
        }
        // Occlusion culling one frame late: the region's depth, drawn whole above, hides
        // what the next frame need not refine.
        if job.occlusion && groups.len() == 1 {
            let depth = renderer.read_depth(region).map_err(|e| TileError::from(e).at(first))?;
            self.adapter.set_occluder(Some(Occluder::new(view_proj, (job.width, job.height), region, &depth)));
        }
        Ok((out, memory))
    }
}
