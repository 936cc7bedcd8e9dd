//! Rank 0's entry points: under mpirun, or alone with one worker thread over channels.

use std::sync::mpsc::RecvTimeoutError;

use anyhow::Result;
use worker::transport::{self, Transport};

use super::control::{Client, Control, Request};
use super::{frame_loop, Plan};
use crate::window::{Behaviour, Input, WindowSpec, Windows};

/// Rank 0 of an mpirun job: the frame loop, shown in rank 0's windows with `--present` and
/// no display ranks. Any error ends every rank (`MPI_Abort`) rather than leave the workers
/// waiting.
pub fn run_master(mpi: &transport::Mpi, plan: &Plan) -> Result<()> {
    if mpi.size() < 2 {
        anyhow::bail!("run with at least 2 ranks: rank 0 sorts and composites, ranks 1.. render");
    }
    let result = if plan.present && plan.display_ranks == 0 {
        let (specs, behaviour) = rank0_windows(plan);
        run_windowed(plan, specs, behaviour, |plan, window| frame_loop::run_live(mpi, plan, window))
    } else {
        frame_loop::run(mpi, plan)
    };
    if let Err(e) = result {
        eprintln!("error: {}", crate::output::one_line(&e));
        mpi.abort(1);
    }
    Ok(())
}

/// How long a run alone that failed waits for its worker thread to stop.
const WORKER_GRACE: std::time::Duration = std::time::Duration::from_secs(5);

/// Without mpirun: the frame loop, and one worker on a thread of this process, over channels
/// (shown in windows with `--present`).
pub fn run_alone(plan: &Plan) -> Result<()> {
    if plan.present {
        let (specs, behaviour) = rank0_windows(plan);
        return run_windowed(plan, specs, behaviour, run_alone_live);
    }
    run_alone_live(plan, None)
}

/// Rank 0's windows with `--present`: one per display of the wall, each showing its part of
/// the frame where the wall file places it, or one for the frame; the first steers.
fn rank0_windows(plan: &Plan) -> (Vec<WindowSpec>, Behaviour) {
    let specs = match &plan.wall {
        Some(wall) => wall.displays.iter().map(|d| WindowSpec::display(plan, d, true)).collect(),
        None => vec![WindowSpec::frame(plan)],
    };
    (specs, Behaviour { resize: plan.wall.is_none(), ..Behaviour::of(plan) })
}

/// Runs `run` (a live frame loop) with its frames shown in windows opened from `specs`, whose
/// input goes onto the loop's control channel; closes them when it ends.
pub fn run_windowed(
    plan: &Plan,
    specs: Vec<WindowSpec>,
    behaviour: Behaviour,
    run: impl FnOnce(&Plan, Option<frame_loop::Window>) -> Result<()>,
) -> Result<()> {
    let control = Control::default();
    let sender = control.sender();
    let input: Input = Box::new(move |command| {
        let _ = sender.send(Request { client: Client::local(), command });
    });
    let windows = Windows::open(specs, behaviour, input, std::time::Duration::from_secs(3600), &mut || {})?;
    let result = run(plan, Some(frame_loop::Window { control, present: windows.presenter() }));
    let closed = windows.close();
    result.and(closed)
}

/// [`run_alone`], live in a window when `window` is given (`tessera view`).
pub fn run_alone_live(plan: &Plan, window: Option<frame_loop::Window>) -> Result<()> {
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
    if let Err(e) = frame_loop::run_live(&ranks[0] as &dyn Transport, plan, window) {
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
