//! A progressive mesh (`.dpm`): rank 0 sends the workers its file once (or, out of core, its
//! path) and per frame only the camera and each worker's tiles; the workers adapt it.

use std::path::Path;

use anyhow::{bail, Context, Result};
use codec::view::{Camera, TileGrid};
use protocol::{DpmFile, PmFrameJob, PmModel, ToWorker};

use super::contract::{FrameContext, FrameJobs, Scene};
use crate::camera::CameraSpec;
use crate::model::{dpm_file_bbox, pm_bbox, read_input};
use crate::render::plan::Plan;
use crate::render::stats::TileStats;

/// A progressive mesh: rank 0 keeps its file for the workers (or, out of core, its path:
/// each worker reads the nodes it needs itself) and its bounding box for the camera and for
/// the tiles it can reach.
pub(super) struct PmScene {
    source: PmSource,
    bbox: ([f32; 3], [f32; 3]),
}

enum PmSource {
    /// An in-core file's bytes, sent to every worker, and the bytes of graphics memory each
    /// worker's adaptation may take.
    Bytes { bytes: Vec<u8>, gpu_budget: u64 },
    /// An out-of-core file's absolute path, the bytes of graphics memory each worker's
    /// adaptation may take, those of them it keeps of the nodes, and the node slots they make
    /// (at most one per node).
    File { path: String, gpu_budget: u64, pool_bytes: u64, slots: u32 },
}

impl PmScene {
    /// A `.dpm` at `path`: out of core when its file says so (the workers read its nodes
    /// themselves), else its bytes, decoded here once so that a corrupt file fails before
    /// any worker sees it.
    pub(super) fn open(path: &Path, plan: &Plan) -> Result<PmScene> {
        let named = || format!("{}", path.display());
        let gpu_budget = plan.pm.gpu_budget;
        if let Some(file) = codec::pm::format::NodeFile::open_out_of_core(path).with_context(named)? {
            let nodes = plan.pm.gpu_nodes;
            return PmScene::out_of_core(path, &file, gpu_budget, nodes);
        }
        let bytes = read_input(path)?;
        // Decoded here once, so that a corrupt file fails before any worker sees it.
        let pm = codec::pm::format::decode(&bytes).with_context(|| format!("{}", path.display()))?.pm;
        let (lo, hi) = pm_bbox(&pm.positions);
        if !lo.iter().chain(&hi).all(|v| v.is_finite()) {
            bail!("{}: a bad model: its bounding box {lo:?} .. {hi:?} is not finite", path.display());
        }
        Ok(PmScene { source: PmSource::Bytes { bytes, gpu_budget }, bbox: (lo, hi) })
    }

    /// An out-of-core `.dpm`: its head is read and checked here (the nodes are checked by
    /// their checksums as workers read them); its box is [`dpm_file_bbox`].
    fn out_of_core(
        path: &Path,
        file: &codec::pm::format::NodeFile,
        gpu_budget: u64,
        nodes: Option<u64>,
    ) -> Result<PmScene> {
        let named = || format!("{}", path.display());
        let dpm = codec::pm::format::Dpm::parse_prefix(file.prefix()).with_context(named)?;
        let (lo, hi) = dpm_file_bbox(&dpm);
        if !lo.iter().chain(&hi).all(|v| v.is_finite()) || lo.iter().zip(&hi).any(|(a, b)| a > b) {
            bail!("{}: a bad model: its bounding box {lo:?} .. {hi:?} is not finite", path.display());
        }
        // Each worker's pool holds slots of the largest node's size: a pool below one slot
        // is refused here, before any worker starts on it.
        let pool_bytes = worker::pm_adapt::pool_bytes(Some(gpu_budget), nodes)?;
        let slot_bytes = worker::pm_adapt::decoder::slot_bytes(&dpm);
        if pool_bytes < slot_bytes as u64 {
            return Err(worker::pm_adapt::AdaptError::Budget { budget: pool_bytes, slot_bytes }.into());
        }
        let abs = std::fs::canonicalize(path).with_context(named)?;
        let path = abs.to_str().with_context(|| format!("{}: the path is not UTF-8", abs.display()))?.to_string();
        let slots = worker::pm_adapt::decoder::slots_within(&dpm, pool_bytes);
        Ok(PmScene { source: PmSource::File { path, gpu_budget, pool_bytes, slots }, bbox: (lo, hi) })
    }
}

impl Scene for PmScene {
    fn camera(&self, args: &CameraSpec, grid: &TileGrid) -> Result<Camera> {
        let (lo, hi) = self.bbox;
        args.camera(lo, hi, grid.aspect())
    }

    fn model_message(&self) -> Option<Vec<u8>> {
        Some(match &self.source {
            PmSource::Bytes { bytes, gpu_budget } => {
                ToWorker::Model(PmModel { dpm: bytes.clone(), gpu_budget: *gpu_budget }).encode()
            }
            PmSource::File { path, gpu_budget, pool_bytes, .. } => {
                ToWorker::DpmFile(DpmFile { path: path.clone(), gpu_budget: *gpu_budget, pool_bytes: *pool_bytes })
                    .encode()
            }
        })
    }

    fn budget_slots(&self) -> Option<u32> {
        match self.source {
            PmSource::File { slots, .. } => Some(slots),
            PmSource::Bytes { .. } => None,
        }
    }

    /// One frame of a progressive mesh: every tile the model can reach goes to a worker with
    /// the camera; nothing of the mesh is sent. The tiles' triangle counts come back with the
    /// pixels.
    fn jobs(&mut self, ctx: &FrameContext) -> Result<FrameJobs> {
        let (grid, plan, (lo, hi)) = (ctx.grid, ctx.plan, self.bbox);
        let view = codec::pm::Viewpoint::new(&ctx.camera, grid.width, grid.height, ctx.error_px);
        let diagonal = glam::Vec3::from(hi).distance(glam::Vec3::from(lo));
        // Only tiles the model's bounding box can reach: every vertex a progressive mesh can
        // activate lies in it, so the other tiles stay transparent and cost the workers nothing.
        let reach = codec::view::box_screen_rect(lo, hi, view.view_proj, grid.width, grid.height);
        let indices: Vec<usize> = (0..grid.tiles())
            .filter(|&i| {
                let [x0, y0, x1, y1] = grid.tile_rect(i);
                reach.is_some_and(|[rx0, ry0, rx1, ry1]| x0 < rx1 && rx0 < x1 && y0 < ry1 && ry0 < y1)
            })
            .collect();
        // Each worker adapts one mesh to its tiles' bounding rectangle: contiguous runs of
        // tiles keep it to the worker's share of the frame (with --balance, the balancer's
        // assignment, whose rectangles may be larger).
        let owner = if ctx.balance {
            ctx.owners(&indices)
        } else {
            crate::render::schedule::contiguous(indices.len(), ctx.workers)
        };
        let mut jobs: Vec<PmFrameJob> = (0..ctx.workers)
            .map(|_| PmFrameJob {
                frame: ctx.frame,
                width: grid.width,
                height: grid.height,
                view_proj: view.view_proj.to_cols_array(),
                eye: view.eye.to_array(),
                pixels_per_unit: view.pixels_per_unit,
                error_px: view.error_px,
                c_lod: plan.pm.c_lod,
                attribute_scale: plan.pm.normal_weight * diagonal,
                max_passes: plan.pm.max_passes,
                occlusion: plan.pm.occlusion,
                tiles: vec![],
            })
            .collect();
        let mut tile_stats = Vec::with_capacity(indices.len());
        for (&i, &w) in indices.iter().zip(&owner) {
            jobs[w - 1].tiles.push((i as u32, grid.tile_rect(i)));
            tile_stats.push(TileStats {
                index: i as u32,
                worker: w,
                triangles: 0,
                bytes: 0,
                tri_bytes: 0,
                normal_bytes: 0,
            });
        }
        // Workers without tiles this frame get no message and are not waited for.
        let messages = jobs
            .into_iter()
            .enumerate()
            .filter(|(_, j)| !j.tiles.is_empty())
            .map(|(i, j)| (i + 1, ToWorker::PmFrame(j).encode()))
            .collect();
        Ok(FrameJobs { messages, tiles: tile_stats, chunks: None, nsp: None })
    }
}
