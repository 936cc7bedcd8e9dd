//! `subdivide`: a large test model from a mesh, by repeated midpoint subdivision with a small
//! deterministic displacement, written as binary PLY in memory that follows the input (see
//! `tessera_bench::subdivide`). For scale benchmarks; write into a temporary folder.
//!
//! `cargo run --release -p tessera-bench --bin subdivide -- ../shared/meshes/stanford/dragon_vrip.ply.gz --min-triangles 200M -o /tmp/dragon-223m.ply`

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Parser;
use master::cli::parse_bytes;
use tessera_bench::subdivide::{levels_for, Subdivision};

#[derive(Parser)]
#[command(name = "subdivide", version)]
struct Args {
    /// A mesh file (OBJ, PLY, STL, optionally .gz).
    input: PathBuf,
    /// The binary PLY to write.
    #[arg(short, long)]
    output: PathBuf,
    /// Levels of subdivision (each multiplies the triangles by 4).
    #[arg(long, conflicts_with = "min_triangles")]
    levels: Option<u32>,
    /// The fewest levels that give at least this many triangles (K, M, G suffixes: powers of 1024).
    #[arg(long, value_parser = parse_bytes)]
    min_triangles: Option<u64>,
    /// The new points' offset, as a fraction of the input's mean edge length over 2^levels.
    #[arg(long, default_value_t = 0.05, value_parser = master::cli::parse_non_negative)]
    displace: f32,
}

fn run(a: &Args) -> Result<()> {
    master::output::check_extension(&a.output, &["ply"], "--output")?;
    master::output::check_distinct(&[&a.input], &[&a.output])?;
    let mesh = master::model::load_mesh(&a.input)?;
    let levels = match (a.levels, a.min_triangles) {
        (Some(l), _) => l,
        (None, Some(t)) => levels_for(mesh.triangles.len() as u64, t),
        (None, None) => anyhow::bail!("give --levels L or --min-triangles N"),
    };
    let start = Instant::now();
    let s = Subdivision::new(&mesh, levels, a.displace)?;
    let c = s.counts();
    let pb = master::progress::bar(c.triangles, "writing triangles");
    master::output::write_atomic(&a.output, |w| s.write_ply(w, &|done| pb.set_position(done)))
        .with_context(|| format!("{}", a.output.display()))?;
    pb.finish_and_clear();
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{} -> {}: {levels} levels, {} triangles, {} vertices in {:.1} s ({:.1}M triangles/s)",
        a.input.display(),
        a.output.display(),
        c.triangles,
        c.vertices,
        secs,
        c.triangles as f64 / secs / 1e6
    );
    Ok(())
}

fn main() -> ExitCode {
    let a = Args::parse();
    master::output::install_signal_handler();
    match run(&a) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
