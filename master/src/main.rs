//! `tessera`: one binary for every rank. This file parses the flags (`master::cli`), decides
//! the process's role, and dispatches; the work lives in the `master`, `worker` and `codec`
//! libraries.

use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::Parser;
use master::cli::{Cli, Command, Nsp, Pm, RenderArgs};
use master::commands;
use worker::transport::{self, Mpi, Transport};

/// Large blocks go to files once `pm build` turns spilling on (`master::spill`); until then
/// this is the system allocator.
#[global_allocator]
static ALLOC: master::spill::SpillAlloc = master::spill::SpillAlloc;

fn main() -> ExitCode {
    // Before anything else starts a thread: every thread inherits the blocked signals.
    master::output::install_signal_handler();
    let cli = Cli::parse();
    codec::input::set_max_decompressed_bytes(cli.max_decompressed);
    codec::input::set_allow_outside_uris(cli.allow_outside_uris);
    let result = match &cli.command {
        Command::Encode { input, output, options } => commands::encode(input, output, options),
        Command::Decode { input, output } => commands::decode(input, output),
        Command::Stats { input, json } => commands::stats(input, *json),
        Command::Render(args) => render(args),
        Command::Sort { model, grid, camera, dump, json, tile_coding } => {
            master::sort::run(model, grid, camera, dump.as_ref(), *json, (*tile_coding).into())
        }
        Command::Pm {
            pm:
                Pm::Build {
                    input,
                    output,
                    position_bits,
                    normal_bits,
                    node_kb,
                    chunk_faces,
                    no_memory_check,
                    spill_dir,
                    spill_min_mb,
                    assume_available_mb,
                },
        } => master::pm::build(
            input,
            output,
            codec::pm::DpmOptions {
                position_bits: *position_bits,
                normal_bits: *normal_bits,
                node_bytes: node_kb.map_or(0, |k| k * 1024),
            },
            codec::pm::BuildOptions { chunk_faces: *chunk_faces },
            master::pm::MemoryPolicy {
                check: !*no_memory_check,
                spill_dir: spill_dir.clone(),
                spill_threshold: spill_min_mb << 20,
                available: assume_available_mb.map(|mb| mb << 20),
            },
        ),
        Command::Pm { pm: Pm::Stats { input, json } } => master::pm::stats(input, *json),
        Command::Pm {
            pm:
                Pm::Adapt {
                    input,
                    view,
                    error_px,
                    output,
                    full,
                    normal_weight,
                    gpu,
                    gpu_budget_mb,
                    gpu_nodes_mb,
                    one_level,
                },
        } => {
            let mb = |mb: f32| (mb as f64 * (1u64 << 20) as f64) as u64;
            let opts = master::pm::AdaptOptions {
                size: view.size,
                error_px: *error_px,
                normal_weight: *normal_weight,
                full: *full,
                gpu: *gpu,
                gpu_budget: gpu_budget_mb.map(mb),
                gpu_nodes: gpu_nodes_mb.map(mb),
                levels: one_level.then_some(codec::pm::Levels::One),
            };
            master::pm::adapt(input, &view.camera, &opts, output)
        }
        Command::Nsp {
            nsp: Nsp::Build { input, output, bits, root_bits, splits, min_simplices, advance, temp_dir },
        } => {
            let params = codec::nsp::Params {
                bits: *bits,
                root_bits: *root_bits,
                splits: *splits,
                min_simplices: *min_simplices,
                advance: *advance,
            };
            master::nsp::build(input, output, params, temp_dir.as_deref())
        }
        Command::Nsp { nsp: Nsp::Stats { input, json } } => master::nsp::stats(input, *json),
        Command::Plot { input, output, frames, width } => master::plot::plot(input, output, *frames, *width),
        Command::Nsp { nsp: Nsp::Adapt { input, view, error_px, output, full } } => {
            master::nsp::adapt(input, &view.camera, view.size, *error_px, *full, output)
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        // The reader of our output went away: nothing to say to anyone, and 141 is what a
        // shell reports for a command ended by SIGPIPE.
        Err(e) if master::output::is_broken_pipe(&e) => ExitCode::from(141),
        Err(e) => {
            eprintln!("error: {}", master::output::one_line(&e));
            ExitCode::FAILURE
        }
    }
}

/// `tessera render` in this process's role. Under mpirun, as in rsmpi's examples, rank 0 is
/// the master (`master::render`) and every rank above it a worker (`worker::node`); alone,
/// the master drives one worker on a thread of this process. Every rank checks the flags
/// first, so that bad arguments end the job before any MPI traffic.
fn render(args: &RenderArgs) -> Result<()> {
    let plan = master::render::plan(args)?;
    if !transport::launched_by_mpirun() {
        return master::render::run_alone(args, &plan);
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
        return master::render::run_display(&mpi, args, &plan, index);
    }
    if mpi.rank() > workers {
        return master::render::run_sorter(&mpi, args, &plan, mpi.rank() - workers);
    }
    if mpi.rank() > 0 {
        let direct = plan
            .wall
            .as_ref()
            .filter(|_| displays > 0)
            .map(|w| master::render::DirectSend::new(w, mpi.size(), displays));
        let route = direct.map(|d| Box::new(move |rect: [u32; 4]| d.route(rect)) as Box<worker::node::Route>);
        return worker::node::run_routed(&mpi, route.as_deref()).map_err(anyhow::Error::msg);
    }
    master::render::run_master(&mpi, args, &plan)
}
