//! `tessera`: one binary for every rank. This file only parses arguments and dispatches;
//! the work lives in the `master`, `worker` and `codec` libraries.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use master::args::{CameraArgs, GridArgs};
use master::commands;

#[derive(Parser)]
#[command(name = "tessera", version, about = "Sort-first parallel rendering of compressed meshes")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Compress a mesh (OBJ, PLY or STL, optionally .gz) into a .bft file.
    Encode {
        input: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
        /// Bits per quantized coordinate (8 to 24).
        #[arg(long, default_value_t = codec::Quantization::DEFAULT_BITS, value_parser = clap::value_parser!(u8).range(8..=24))]
        quant_bits: u8,
    },
    /// Decompress a .bft file into PLY or OBJ (chosen by the output's extension).
    Decode {
        input: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Sort a model into one compressed BFT submesh per screen tile (one frame).
    Sort {
        /// A .bft file, or a mesh file (encoded on load at 16 bits).
        model: PathBuf,
        #[command(flatten)]
        grid: GridArgs,
        #[command(flatten)]
        camera: CameraArgs,
        /// Write DIR/tile-<index>.ply for every non-empty tile, and DIR/summary.json.
        #[arg(long)]
        dump: Option<PathBuf>,
        /// Print the summary as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Print sizes and rates of a .bft file.
    Stats {
        input: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Encode { input, output, quant_bits } => commands::encode(input, output, *quant_bits),
        Command::Decode { input, output } => commands::decode(input, output),
        Command::Stats { input, json } => commands::stats(input, *json),
        Command::Sort { model, grid, camera, dump, json } => master::sort::run(model, grid, camera, dump.as_ref(), *json),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
