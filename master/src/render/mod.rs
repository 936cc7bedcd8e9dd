//! `tessera render`, rank 0's side: the sort-first frame loop.
//!
//! Per frame: place the camera, sort the model into compressed tile submeshes, assign the
//! tiles to workers, send each worker its tiles (non-blocking, all at once), receive the
//! tile pixels, stitch them, write the PNG (or one per display of a tile wall) and a stats
//! line per rank. Without `mpirun` the same loop drives one worker thread over channels.
//!
//! A progressive mesh (`.dpm`) takes another path through the same loop: rank 0 sends the
//! file to every worker once, then per frame only the camera and each worker's tiles; each
//! worker adapts the mesh on its GPU to each tile's sub-frustum and renders it.
//!
//! `main` decides the role of the process (rank 0 this module, ranks above it
//! `worker::node`); the files here are one concern each:
//!
//! | file | what |
//! |---|---|
//! | `plan.rs` | what is checked before any rank talks to another, and the output files' names |
//! | `scene/` | the model rank 0 holds, a file per kind (`.bft`, chunked `.bft`, `.dpm`, `.nsp`), and each frame's messages to the workers |
//! | `frame_loop.rs` | the frame loop |
//! | `schedule.rs` | which worker renders which tile (round robin, or balanced by cost) |
//! | `sorter.rs` | a rank that helps rank 0 sort a chunked model (`--sorters K`) |
//! | `link.rs` | the handshake, heartbeats and silence, receiving the tiles' pixels |
//! | `display.rs` | direct send: display ranks that assemble and write a wall's displays at a swap barrier |
//! | `stats.rs` | the `--stats` JSON lines of rank 0 and of the workers |

mod display;
mod eye;
mod frame_loop;
mod link;
mod plan;
mod scene;
mod schedule;
mod sorter;
pub mod stats;

use std::sync::mpsc::RecvTimeoutError;

use anyhow::Result;
use worker::transport::{self, Transport};

pub use display::{run_display, DirectSend};
pub use frame_loop::{orbit, orbit_by};
pub use plan::{frame_path, plan, Plan};
pub use schedule::assign;
pub use sorter::run_sorter;

/// Rank 0 of an mpirun job: the frame loop. Any error ends every rank (`MPI_Abort`) rather
/// than leave the workers waiting.
pub fn run_master(mpi: &transport::Mpi, plan: &Plan) -> Result<()> {
    if mpi.size() < 2 {
        anyhow::bail!("run with at least 2 ranks: rank 0 sorts and composites, ranks 1.. render");
    }
    if let Err(e) = frame_loop::run(mpi, plan) {
        eprintln!("error: {}", crate::output::one_line(&e));
        mpi.abort(1);
    }
    Ok(())
}

/// How long a run alone that failed waits for its worker thread to stop.
const WORKER_GRACE: std::time::Duration = std::time::Duration::from_secs(5);

/// Without mpirun: the frame loop, and one worker on a thread of this process, over channels.
pub fn run_alone(plan: &Plan) -> Result<()> {
    if plan.display_ranks > 0 {
        anyhow::bail!("--display-ranks {} needs mpirun: the display ranks are ranks of their own", plan.display_ranks);
    }
    if plan.sorters > 1 {
        anyhow::bail!("--sorters {} needs mpirun: the sorters are ranks of their own", plan.sorters);
    }
    let mut ranks = transport::local_ranks(2);
    let worker_end = ranks.pop().expect("two ranks");
    let (finished, worker_done) = std::sync::mpsc::channel::<()>();
    let handle = std::thread::spawn(move || {
        let result = worker::node::run(&worker_end);
        drop(finished);
        result
    });
    if let Err(e) = frame_loop::run(&ranks[0] as &dyn Transport, plan) {
        // The worker leaves the GPU before the process exits: exiting while it draws runs the
        // driver's exit-time destructors under it (SIGSEGV or "corrupted double-linked list"
        // in 2 of 100 loaded runs of a chunked model cut while in use). Closing its channel
        // ends it at its next receive.
        drop(ranks);
        if worker_done.recv_timeout(WORKER_GRACE.min(plan.timeout)) == Err(RecvTimeoutError::Timeout) {
            // Stuck (that may be the error): end without the exit-time destructors, so that
            // --timeout bounds the run.
            eprintln!("error: {}", crate::output::one_line(&e));
            let _ = std::io::Write::flush(&mut std::io::stdout());
            // Safety: ends the process; nothing after it runs.
            unsafe { libc::_exit(1) }
        }
        let _ = handle.join();
        return Err(e);
    }
    drop(ranks);
    let worker_result = handle.join().map_err(|_| anyhow::anyhow!("the worker thread panicked"))?;
    worker_result.map_err(anyhow::Error::msg)
}
