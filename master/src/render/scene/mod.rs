//! The model rank 0 holds for `tessera render`, one file per kind behind [`Scene`]: a BFT
//! model it sorts every frame (`bft.rs`), a chunked one whose sort it may share with sorter
//! ranks (`chunked.rs`), a progressive mesh that the workers adapt themselves (`pm.rs`), and
//! an `.nsp` model whose cells it sends as the view selects them (`nsp.rs`). Each kind opens
//! its file, frames its camera, says what the workers get once, and makes every frame's
//! messages; the frame loop sees only [`Scene`]. A new kind is a file here, a line in
//! [`load`], and its messages.

mod bft;
mod chunked;
mod nsp;
mod pm;

use anyhow::{bail, Result};
use codec::kind::ModelKind;
use codec::view::{Camera, TileGrid};
use protocol::{FrameJob, ToWorker};

use super::plan::Plan;
use super::schedule::assign;
use super::stats::{ChunkStats, NspStats, TileStats};
use crate::cli::CameraArgs;

pub(super) use chunked::{ChunkedScene, Share, ShareContext};

/// The model rank 0 renders, of one kind.
pub(super) trait Scene {
    /// The camera of the first frame: the flags given, the rest framing the model.
    fn camera(&self, args: &CameraArgs, grid: &TileGrid) -> Result<Camera>;

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

/// Loads the plan's model, of the kind its magic bytes say (BFT tiles coded as the plan says).
pub(super) fn load(plan: &Plan) -> Result<Box<dyn Scene>> {
    let (path, coding) = (plan.model.as_path(), plan.coding);
    if let Some(scene) = ChunkedScene::open(plan)? {
        return Ok(Box::new(scene));
    }
    if plan.sorters > 1 {
        bail!(
            "{}: --sorters shares the sort of a chunked .bft model (tessera encode writes one above --chunk-triangles)",
            path.display()
        );
    }
    Ok(match ModelKind::of(path) {
        ModelKind::Nsp => Box::new(nsp::NspScene::open(path)?),
        ModelKind::Dpm => Box::new(pm::PmScene::open(path, plan)?),
        _ => Box::new(bft::BftScene::open(path, coding)?),
    })
}

/// What every frame's jobs are made from.
pub(super) struct FrameContext<'a> {
    /// The frame's number, from 0.
    pub frame: u32,
    pub camera: Camera,
    pub grid: &'a TileGrid,
    /// Workers are ranks `1..=workers`.
    pub workers: usize,
    pub plan: &'a Plan,
    /// Each tile's cost the frame before (ms), for `--balance`.
    pub costs: &'a [f64],
}

impl FrameContext<'_> {
    /// The worker of each of `tiles`.
    fn owners(&self, tiles: &[usize]) -> Vec<usize> {
        assign(tiles, self.workers, self.plan.balance.then_some(self.costs))
    }
}

/// A frame's messages to the workers (by rank) and its tile lines for the stats.
pub(super) struct FrameJobs {
    pub messages: Vec<(usize, Vec<u8>)>,
    pub tiles: Vec<TileStats>,
    pub chunks: Option<ChunkStats>,
    pub nsp: Option<NspStats>,
}

/// One empty frame job per worker: sorter `sorter`'s share of `sorters`.
fn empty_jobs(ctx: &ShareContext, sorter: usize, chunk_cache: u64) -> Vec<FrameJob> {
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
    fn frame_jobs(&self, vp: glam::Mat4, chunk_cache: u64) -> Vec<FrameJob> {
        let share = ShareContext {
            frame: self.frame,
            grid: self.grid,
            view_proj: vp,
            workers: self.workers,
            sorters: 1,
            decode_only: self.plan.decode_only,
        };
        empty_jobs(&share, 0, chunk_cache)
    }
}

/// Every worker's frame message, by rank.
pub(super) fn frame_messages(jobs: Vec<FrameJob>) -> Vec<(usize, Vec<u8>)> {
    jobs.into_iter().enumerate().map(|(i, j)| (i + 1, ToWorker::Frame(j).encode())).collect()
}
