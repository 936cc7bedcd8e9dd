//! `tessera render` in this process's role: under mpirun, rank 0 is the master, the last
//! `--display-ranks` ranks own the wall's displays, the `--sorters` ranks before them help
//! rank 0 sort, and the ranks between are workers; alone, the master drives one worker on a
//! thread of this process. The frame loop and the ranks' work live in [`crate::render`].

use std::time::Duration;

use anyhow::{Context, Result};
use worker::transport::{self, Mpi, Transport};

use crate::cli::RenderArgs;

/// `tessera render` in this process's role. Under mpirun, as in rsmpi's examples, rank 0 is
/// the master (`master::render`) and every rank above it a worker (`worker::node`); alone,
/// the master drives one worker on a thread of this process. Every rank checks the flags
/// first, so that bad arguments end the job before any MPI traffic.
pub fn run(args: &RenderArgs) -> Result<()> {
    let plan = crate::render::plan(args)?;
    if !transport::launched_by_mpirun() {
        return crate::render::run_alone(&plan);
    }
    let mpi = Mpi::init()
        .context("MPI is already initialized, or cannot serialize calls from two threads (MPI_THREAD_SERIALIZED)")?;
    let (sorters, displays) = (args.sorters as usize, args.display_ranks as usize);
    if mpi.size() < sorters + displays + 1 {
        match displays {
            0 => anyhow::bail!("--sorters {sorters} needs at least {} ranks (the sorters and a worker)", sorters + 1),
            _ => anyhow::bail!(
                "--display-ranks {displays} needs at least {} ranks (rank 0, a worker and the display ranks)",
                displays + 2
            ),
        }
    }
    // Ranks 1..=W are workers; then K-1 ranks help rank 0 sort (`--sorters K`), and the last
    // D ranks own the wall's displays (`--display-ranks D`).
    let workers = mpi.size() - sorters - displays;
    let result = if mpi.rank() >= mpi.size() - displays {
        let index = mpi.rank() - (mpi.size() - displays);
        crate::render::run_display(&mpi, &plan, index)
    } else if mpi.rank() > workers {
        crate::render::run_sorter(&mpi, &plan, mpi.rank() - workers)
    } else if mpi.rank() > 0 {
        share_cores(mpi.ranks_on_node());
        let direct = plan
            .wall
            .as_ref()
            .filter(|_| displays > 0)
            .map(|w| crate::render::DirectSend::new(w, mpi.size(), displays));
        let route = direct.map(|d| Box::new(move |rect: [u32; 4]| d.route(rect)) as Box<worker::node::Route>);
        worker::node::run_routed(&mpi, route.as_deref()).map_err(anyhow::Error::msg)
    } else {
        return crate::render::run_master(&mpi, &plan);
    };
    match result {
        Ok(()) => Ok(()),
        Err(e) => end_after_failure(&mpi, &e),
    }
}

/// A worker's rayon pool takes its share of the node's cores (at least one thread) instead of
/// all of them: with rank 0 and two workers on a 2-core machine, the single-stream dragon
/// orbited in 57.3-71.3 ms a frame against 59.2-79.0 with a pool per core, the workers
/// decoding in 30.8-37.3 ms against 44.8-48.4 (four alternated runs; docs/results.md,
/// "Frames at interactive rates"). Rank 0 and the sorters keep every core: their sort is the
/// frame's critical stage, and it runs while the workers wait for its tiles.
/// `RAYON_NUM_THREADS` overrides.
fn share_cores(ranks_on_node: usize) {
    if std::env::var_os("RAYON_NUM_THREADS").is_some() {
        return;
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    // Only fails when the pool was already built, by an earlier use of rayon in this
    // process; that pool is then kept as it is.
    let _ = rayon::ThreadPoolBuilder::new().num_threads((cores / ranks_on_node.max(1)).max(1)).build_global();
}

/// How long a failed rank waits for rank 0 to end the job before ending it itself.
const ABORT_GRACE: Duration = Duration::from_secs(10);

/// A rank above 0 that failed has told rank 0, which names the failure and ends every rank
/// with `MPI_Abort`. Meanwhile it must not finalize MPI: Open MPI 4.1's mpirun hangs or
/// crashes when one rank is in `MPI_Finalize` while another aborts (7 runs in 40 of a
/// three-rank C program doing just that; none in 40 when both abort). So it says its error,
/// waits to be ended, and aborts the job itself if rank 0 does not.
fn end_after_failure(mpi: &Mpi, e: &anyhow::Error) -> ! {
    eprintln!("error: {}", crate::output::one_line(e));
    std::thread::sleep(ABORT_GRACE);
    mpi.abort(1)
}
