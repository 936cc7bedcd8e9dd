//! `tessera`: one binary for every rank. This file parses the flags (`master::cli`), sets
//! what every command shares (signals, input limits), and calls the command
//! (`master::commands`, a file each); the work lives in the `master`, `worker` and `codec`
//! libraries.

use std::process::ExitCode;

use clap::Parser;
use master::cli::{Cli, Command};
use master::commands;

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
        Command::Encode { input, output, options } => commands::encode::run(input, output, options),
        Command::Decode { input, output } => commands::decode::run(input, output),
        Command::Stats { input, json } => commands::stats::run(input, *json),
        Command::Render(args) => commands::render::run(args),
        Command::View(args) => commands::view::run(args),
        Command::Sort(args) => commands::sort::run(args),
        Command::Pm { pm } => commands::pm::run(pm),
        Command::Nsp { nsp } => commands::nsp::run(nsp),
        Command::Plot { input, output, frames, width } => commands::plot::run(input, output, *frames, *width),
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
