//! A rank that helps rank 0 sort a chunked model (`render --sorters K`): it maps the file
//! itself, and every frame, when rank 0 sends the view and the worker of every tile, sorts
//! its contiguous share of the chunks and sends each worker its pieces straight, with its
//! own mirror of its share of the worker's chunk cache. Rank 0 composites as before; no
//! rank reads the whole model or carries all the traffic, and the workers join the shares
//! in sorter order, which is the chunks' order, so frames are the same for every K.

use std::time::Duration;

use anyhow::{bail, Context, Result};
use glam::Mat4;
use protocol::{Ready, ToMaster, ToSorter};
use worker::transport::{RecvError, Transport};

use super::plan::Plan;
use super::scene::{frame_messages, ChunkedScene, Share, ShareContext};

/// How long a sorter waits for rank 0's next frame (rank 0 composites and writes between).
const MASTER_SILENCE: Duration = Duration::from_secs(3600);

/// Sorter `s` (of `--sorters K`, rank 0 being sorter 0) until rank 0 shuts the job down. A
/// failure is reported to rank 0, which ends the job with it.
pub fn run_sorter(t: &dyn Transport, plan: &Plan, s: usize) -> Result<()> {
    super::link::report_failure(t, "", sort_frames(t, plan, s))
}

fn sort_frames(t: &dyn Transport, plan: &Plan, s: usize) -> Result<()> {
    let Some(mut scene) = ChunkedScene::open(plan, &plan.model)? else {
        bail!("{}: --sorters shares the sort of a chunked .bft model", plan.model.display());
    };
    t.send(0, &ToMaster::Ready(Ready { adapter: format!("sorter {s}"), max_texture_side: u32::MAX }).encode());
    let workers = t.size() - plan.sorters as usize - plan.display_ranks as usize;
    loop {
        let (from, bytes) = match t.recv(MASTER_SILENCE) {
            Ok(m) => m,
            Err(RecvError::Timeout) => bail!("no message from rank 0 for an hour"),
            Err(RecvError::Disconnected) => return Ok(()),
        };
        if from != 0 {
            bail!("unexpected message from rank {from}");
        }
        match ToSorter::decode(&bytes).context("bad message from rank 0")? {
            ToSorter::Shutdown => return Ok(()),
            ToSorter::KeepAlive => continue,
            ToSorter::Sort(job) => {
                let ctx = ShareContext {
                    frame: job.frame,
                    grid: &plan.grid,
                    view_proj: Mat4::from_cols_array(&job.view_proj),
                    error_px: job.error_px,
                    workers,
                    sorters: plan.sorters as usize,
                    decode_only: plan.decode_only,
                };
                if !(job.error_px.is_finite() && job.error_px > 0.0) {
                    bail!("rank 0 sent a screen error of {} pixels", job.error_px);
                }
                if job.owners.len() != plan.grid.tiles() || job.owners.iter().any(|&w| w == 0 || w as usize > workers) {
                    bail!("rank 0 assigned tiles to ranks outside 1..={workers}");
                }
                let owners = &job.owners;
                let Share { jobs, .. } =
                    scene.share_jobs(&ctx, s, |tiles| tiles.iter().map(|&i| owners[i] as usize).collect())?;
                super::link::send_all(t, frame_messages(jobs), plan.timeout)?;
            }
        }
    }
}
