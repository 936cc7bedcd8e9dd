//! `tessera`: one binary for every rank. This file only parses arguments and dispatches;
//! the work lives in the `master`, `worker` and `codec` libraries.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use master::args::{parse_bytes, parse_non_negative, parse_pair, parse_positive, parse_size, CameraArgs, GridArgs};
use master::commands;

#[derive(Parser)]
#[command(name = "tessera", version, about = "Sort-first parallel rendering of compressed meshes")]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// The most bytes a gzip-compressed input may expand to (K, M, G, T suffixes allowed).
    #[arg(long, global = true, value_parser = parse_bytes, default_value = "1G")]
    max_decompressed: u64,
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
        /// Write `DIR/tile-<index>.ply` for every non-empty tile, and `DIR/summary.json`.
        #[arg(long)]
        dump: Option<PathBuf>,
        /// Print the summary as JSON.
        #[arg(long)]
        json: bool,
        /// How the tiles are entropy-coded: `range` (the adaptive range coder of `.bft`
        /// files, the smallest tiles) or `prefix` (static Huffman codes per tile, several times
        /// faster to sort and decode, about 5% larger).
        #[arg(long, value_enum, default_value_t = master::args::TileCoding::Range)]
        tile_coding: master::args::TileCoding,
    },
    /// Render a model sort-first: rank 0 sorts it into compressed tiles, ranks 1.. render them.
    /// Run under mpirun for a cluster; alone, it runs the master and one worker in-process.
    Render(master::render::RenderArgs),
    /// Print sizes and rates of a .bft file.
    Stats {
        input: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Dependency-free progressive meshes (.dpm files).
    Pm {
        #[command(subcommand)]
        pm: Pm,
    },
    /// Experiments from the paper.
    Bench {
        #[command(subcommand)]
        bench: Bench,
    },
}

#[derive(Subcommand)]
enum Pm {
    /// Build a progressive mesh from a mesh file and compress it into a .dpm file.
    Build {
        input: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
        /// Bits per quantized position coordinate (8 to 24).
        #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u8).range(8..=24))]
        position_bits: u8,
        /// Bits per octahedral normal coordinate (4 to 16).
        #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u8).range(4..=16))]
        normal_bits: u8,
    },
    /// Print the size of a .dpm file per vertex, with the breakdown.
    Stats {
        input: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Adapt a .dpm file to a view (or refine it fully) and write the mesh as PLY.
    Adapt {
        input: PathBuf,
        #[command(flatten)]
        camera: CameraArgs,
        /// Frame size in pixels, WIDTHxHEIGHT.
        #[arg(long, value_parser = parse_size, default_value = "1920x1080")]
        size: (u32, u32),
        /// Screen-space error threshold in pixels.
        #[arg(long, default_value_t = 0.5, value_parser = parse_positive)]
        error_px: f32,
        #[arg(short, long)]
        output: PathBuf,
        /// Apply every split (ignores the view).
        #[arg(long)]
        full: bool,
        /// The normal error's weight, as a fraction of the model's bounding box diagonal per
        /// unit of normal chord (0 ignores normals).
        #[arg(long, default_value_t = 0.0, value_parser = parse_non_negative)]
        normal_weight: f32,
        /// Adapt on the GPU (WGSL compute shaders through wgpu; lavapipe without a GPU). The
        /// mesh written is the same as the CPU reference's.
        #[arg(long)]
        gpu: bool,
    },
}

#[derive(Subcommand)]
enum Bench {
    /// Bytes per frame against tile size (Figure 8): Tri, Tiled Tri, BFT, Tiled BFT, and
    /// per-tile Draco and meshopt, with sort times; a CSV and a PNG plot.
    Bandwidth {
        /// .bft files, or mesh files (encoded on load at --quant-bits).
        #[arg(required = true)]
        models: Vec<PathBuf>,
        /// Tile grids, COLSxROWS, comma-separated.
        #[arg(long, value_parser = parse_pair, value_delimiter = ',', default_value = "1x1,2x2,4x4,8x8,16x16,32x32")]
        tiles: Vec<(u32, u32)>,
        /// Frame size in pixels, WIDTHxHEIGHT.
        #[arg(long, value_parser = parse_size, default_value = "1920x1080")]
        size: (u32, u32),
        /// Bits per quantized coordinate for mesh inputs (8 to 24).
        #[arg(long, default_value_t = 14, value_parser = clap::value_parser!(u8).range(8..=24))]
        quant_bits: u8,
        /// The CSV report.
        #[arg(long)]
        out: PathBuf,
        /// The PNG plot.
        #[arg(long)]
        plot: PathBuf,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    master::output::install_signal_handler();
    codec::input::set_max_decompressed_bytes(cli.max_decompressed);
    let result = match &cli.command {
        Command::Encode { input, output, quant_bits } => commands::encode(input, output, *quant_bits),
        Command::Decode { input, output } => commands::decode(input, output),
        Command::Stats { input, json } => commands::stats(input, *json),
        Command::Render(args) => master::render::run(args),
        Command::Sort { model, grid, camera, dump, json, tile_coding } => {
            master::sort::run(model, grid, camera, dump.as_ref(), *json, (*tile_coding).into())
        }
        Command::Pm { pm: Pm::Build { input, output, position_bits, normal_bits } } => master::pm::build(
            input,
            output,
            codec::pm::DpmOptions { position_bits: *position_bits, normal_bits: *normal_bits },
        ),
        Command::Pm { pm: Pm::Stats { input, json } } => master::pm::stats(input, *json),
        Command::Pm { pm: Pm::Adapt { input, camera, size, error_px, output, full, normal_weight, gpu } } => {
            let opts = master::pm::AdaptOptions {
                size: *size,
                error_px: *error_px,
                normal_weight: *normal_weight,
                full: *full,
                gpu: *gpu,
            };
            master::pm::adapt(input, camera, &opts, output)
        }
        Command::Bench { bench: Bench::Bandwidth { models, tiles, size, quant_bits, out, plot } } => {
            master::bandwidth::run(models, *size, tiles, *quant_bits, out, plot)
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
