//! What every model kind implements for the frame loop ([`Scene`]), and what its frames are
//! made from and into.

use anyhow::Result;
use codec::view::{Camera, TileGrid};
use protocol::{FrameJob, ToWorker};

use crate::camera::CameraSpec;
use crate::render::plan::Plan;
use crate::render::schedule::assign;
use crate::render::stats::{ChunkStats, NspStats, TileStats};

/// The model rank 0 renders, of one kind.
pub(crate) trait Scene {
    /// The camera of the first frame: the flags given, the rest framing the model.
    fn camera(&self, args: &CameraSpec, grid: &TileGrid) -> Result<Camera>;

    /// The message every worker gets once before the first frame: the model, for the kinds
    /// whose workers hold it whole.
    fn model_message(&self) -> Option<Vec<u8>> {
        None
    }

    /// The node slots a worker's graphics memory budget makes, for the kinds read out of
    /// core on the GPU (the stats report it).
    fn budget_slots(&self) -> Option<u32> {
        None
    }

    /// Messages that must leave before this rank sorts (other sorters' orders).
    fn announce(&mut self, _ctx: &FrameContext) -> Vec<(usize, Vec<u8>)> {
        Vec::new()
    }

    /// The frame's messages to the workers and its stats lines.
    fn jobs(&mut self, ctx: &FrameContext) -> Result<FrameJobs>;
}

/// What every frame's jobs are made from.
pub(crate) struct FrameContext<'a> {
    /// The frame's number, from 0.
    pub frame: u32,
    pub camera: Camera,
    pub grid: &'a TileGrid,
    /// Workers are ranks `1..=workers`.
    pub workers: usize,
    pub plan: &'a Plan,
    /// Each tile's cost the frame before (ms), for `--balance`.
    pub costs: &'a [f64],
    /// The screen error of `.dpm`, `.nsp` and level-of-detail `.bft` models (`--error-px`), and whether tiles go to
    /// workers by their costs (`--balance`): the plan's, or what a live run set since.
    pub error_px: f32,
    pub balance: bool,
}

impl FrameContext<'_> {
    /// The worker of each of `tiles`.
    pub(super) fn owners(&self, tiles: &[usize]) -> Vec<usize> {
        assign(tiles, self.workers, self.balance.then_some(self.costs))
    }
}

/// A frame's messages to the workers (by rank) and its tile lines for the stats.
pub(crate) struct FrameJobs {
    pub messages: Vec<(usize, Vec<u8>)>,
    pub tiles: Vec<TileStats>,
    pub chunks: Option<ChunkStats>,
    pub nsp: Option<NspStats>,
}

/// What one sorter's share of a chunked frame is made from.
pub(in crate::render) struct ShareContext<'a> {
    pub frame: u32,
    pub grid: &'a TileGrid,
    pub view_proj: glam::Mat4,
    /// A level-of-detail file's cut (`--error-px`, or what a live run set since).
    pub error_px: f32,
    /// Workers are ranks `1..=workers`.
    pub workers: usize,
    pub sorters: usize,
    pub decode_only: bool,
}

/// One empty frame job per worker: sorter `sorter`'s share of `sorters`.
pub(super) fn empty_jobs(ctx: &ShareContext, sorter: usize, chunk_cache: u64) -> Vec<FrameJob> {
    (0..ctx.workers)
        .map(|_| FrameJob {
            frame: ctx.frame,
            width: ctx.grid.width,
            height: ctx.grid.height,
            view_proj: ctx.view_proj.to_cols_array(),
            decode_only: ctx.decode_only,
            sorter: sorter as u8,
            sorters: ctx.sorters as u8,
            chunk_cache,
            tiles: vec![],
        })
        .collect()
}

impl FrameContext<'_> {
    /// One empty frame job per worker, for a frame sorted by rank 0 alone.
    pub(super) fn frame_jobs(&self, vp: glam::Mat4, chunk_cache: u64) -> Vec<FrameJob> {
        let share = ShareContext {
            frame: self.frame,
            grid: self.grid,
            view_proj: vp,
            error_px: self.error_px,
            workers: self.workers,
            sorters: 1,
            decode_only: self.plan.decode_only,
        };
        empty_jobs(&share, 0, chunk_cache)
    }
}

/// Every worker's frame message, by rank.
pub(crate) fn frame_messages(jobs: Vec<FrameJob>) -> Vec<(usize, Vec<u8>)> {
    jobs.into_iter().enumerate().map(|(i, j)| (i + 1, ToWorker::Frame(j).encode())).collect()
}
