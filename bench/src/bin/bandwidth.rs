//! `bandwidth`: bytes per frame against tile size (Figure 8 of the BFT paper) for Tri, Tiled
//! Tri, BFT and Tiled BFT, and per-tile Draco and meshopt, with sort times; a CSV and a PNG.
//!
//! `cargo run --release -p tessera-bench --bin bandwidth -- MODEL... --out report.csv --plot report.png`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use master::cli::{parse_bytes, parse_pair, parse_size};

/// Bytes per frame against tile size (Figure 8): Tri, Tiled Tri, BFT, Tiled BFT, and per-tile
/// Draco and meshopt, with sort times; a CSV and a PNG plot.
#[derive(Parser)]
#[command(name = "bandwidth", version)]
struct Args {
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
    /// The most bytes a gzip-compressed input may expand to (K, M, G, T suffixes allowed).
    #[arg(long, value_parser = parse_bytes, default_value = "1G")]
    max_decompressed: u64,
}

fn main() -> ExitCode {
    let a = Args::parse();
    master::output::install_signal_handler();
    codec::input::set_max_decompressed_bytes(a.max_decompressed);
    match tessera_bench::bandwidth::run(&a.models, a.size, &a.tiles, a.quant_bits, &a.out, &a.plot) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
