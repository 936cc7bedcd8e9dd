//! `tessera render` in this process's role: under mpirun, rank 0 is the master, the last
//! `--display-ranks` ranks own the wall's displays, the `--sorters` ranks before them help
//! rank 0 sort, and the ranks between are workers; alone, the master drives one worker on a
//! thread of this process. The frame loop and the ranks' work live in [`crate::render`].

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
        return crate::render::run_alone(args, &plan);
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
    if mpi.rank() >= mpi.size() - displays {
        let index = mpi.rank() - (mpi.size() - displays);
        return crate::render::run_display(&mpi, args, &plan, index);
    }
    if mpi.rank() > workers {
        return crate::render::run_sorter(&mpi, args, &plan, mpi.rank() - workers);
    }
    if mpi.rank() > 0 {
        let direct = plan
            .wall
            .as_ref()
            .filter(|_| displays > 0)
            .map(|w| crate::render::DirectSend::new(w, mpi.size(), displays));
        let route = direct.map(|d| Box::new(move |rect: [u32; 4]| d.route(rect)) as Box<worker::node::Route>);
        return worker::node::run_routed(&mpi, route.as_deref()).map_err(anyhow::Error::msg);
    }
    crate::render::run_master(&mpi, args, &plan)
}
