//! `tessera nsp`: the nSP-tree store (`.nsp` files; `codec::nsp`): build, stats, adapt.

use std::path::Path;
use std::sync::atomic::Ordering;
use std::time::Instant;

use anyhow::{Context, Result};
use codec::nsp::{self, view, Canonical, NspFile, Params};
use serde::Serialize;

use crate::camera::CameraSpec;
use crate::cli::Nsp;
use crate::model::{expect_kind, load_mesh, nsp_bbox};
use crate::output::{
    check_distinct, check_extension, mesh_output, summary, temp_dir_in_flight, unregister_in_flight, write_atomic,
    write_bytes,
};
use crate::progress;
use codec::kind::ModelKind;

/// `tessera nsp build IN -o OUT.nsp`: PLY and OBJ out of core (`codec::nsp::ooc`, memory
/// that does not grow with the model), STL in core.
///
/// The out-of-core build's temporary folder is made here, in `temp_dir` (the system's
/// temporary folder by default), and registered with [`temp_dir_in_flight`], so that an
/// interrupted build removes it with everything in it; it is removed when the build ends.
pub fn build(input: &Path, output: &Path, params: Params, temp_dir: Option<&Path>) -> Result<()> {
    check_extension(output, &["nsp"], "the output of nsp build")?;
    check_distinct(&[input], &[output])?;
    params.validate()?;
    let start = Instant::now();
    let mut temp_mb = None;
    let (header, cells, bytes, cost_bits) = if codec::load::stream::can_stream(input) {
        let parent = temp_dir.map_or_else(std::env::temp_dir, Path::to_path_buf);
        let scratch = temp_dir_in_flight(&parent, "tessera-nsp")
            .with_context(|| format!("cannot make a temporary folder in {}", parent.display()))?;
        let built = build_out_of_core(input, output, params, &scratch, &parent);
        let _ = std::fs::remove_dir_all(&scratch);
        unregister_in_flight(&scratch);
        let b = built?;
        temp_mb = Some(b.temp_bytes as f64 / (1 << 20) as f64);
        (b.header, b.cells, b.bytes, b.cost_bits)
    } else {
        let mesh = load_mesh(input)?;
        let canon = Canonical::of_mesh(&mesh, params.bits).with_context(|| format!("{}", input.display()))?;
        drop(mesh);
        let pb = progress::bar(0, "encoding cells");
        let built = nsp::encode(&canon, params, &|done| {
            pb.set_position(done);
        })
        .with_context(|| format!("cannot build {}", input.display()))?;
        pb.finish_and_clear();
        write_bytes(output, &built.bytes)?;
        (built.header, built.tree.nodes.len(), built.bytes.len() as u64, built.cost_bits)
    };
    let secs = start.elapsed().as_secs_f64();
    let h = &header;
    let points = h.points.max(1) as f64;
    summary(
        output,
        format_args!(
            "{} -> {}: {} triangles ({} in the input), {} points, {} cells, {} bytes ({:.2} bits/point), \
             built in {:.2} s ({:.0} triangles/s)",
            input.display(),
            output.display(),
            h.triangles,
            h.input_triangles,
            h.points,
            cells,
            bytes,
            bytes as f64 * 8.0 / points,
            secs,
            h.input_triangles as f64 / secs.max(1e-9)
        ),
    )?;
    summary(
        output,
        format_args!(
            "  bits/point: geometry {:.2}, connectivity {:.2}, orientation {:.2} (at the static tables' entropy){}",
            cost_bits[0] / points,
            cost_bits[1] / points,
            cost_bits[2] / points,
            temp_mb.map_or(String::new(), |mb| format!("; out of core, temporary files up to {mb:.0} MB"))
        ),
    )?;
    Ok(())
}

/// What `tessera nsp stats --json` prints.
#[derive(Debug, Serialize)]
pub struct NspStatsReport {
    pub bytes: u64,
    pub bits: u8,
    pub root_bits: u8,
    pub splits: u32,
    pub min_simplices: u32,
    pub input_triangles: u64,
    pub input_vertices: u64,
    pub points: u64,
    pub triangles: u64,
    pub edges: u64,
    pub isolated_points: u64,
    pub cells: u32,
    pub split_cells: u32,
    pub empty_cells: u32,
    pub depth: u8,
    /// Top-simplices held by the leaves over top-simplices of the model.
    pub duplication: f64,
    pub header_and_table_bytes: u64,
    pub stream_bytes: u64,
    pub cell_table_bytes: u64,
    pub bits_per_point: f64,
}

impl NspStatsReport {
    pub fn of(file: &NspFile) -> NspStatsReport {
        let h = &file.header;
        let stream_bytes: u64 = file.entries.iter().map(|e| e.len as u64).sum();
        let cell_table_bytes = file.file_len - file.prefix_len - stream_bytes;
        let tops = h.triangles + h.edges + h.isolated;
        NspStatsReport {
            bytes: file.file_len,
            bits: h.params.bits,
            root_bits: h.params.root_bits,
            splits: h.params.splits,
            min_simplices: h.params.min_simplices,
            input_triangles: h.input_triangles,
            input_vertices: h.input_vertices,
            points: h.points,
            triangles: h.triangles,
            edges: h.edges,
            isolated_points: h.isolated,
            cells: h.cells,
            split_cells: file.entries.iter().filter(|e| e.split).count() as u32,
            empty_cells: file.entries.iter().filter(|e| e.len == 0).count() as u32,
            depth: file.tree.nodes.iter().map(|n| n.depth).max().unwrap_or(0),
            duplication: h.leaf_simplices as f64 / tops.max(1) as f64,
            header_and_table_bytes: file.prefix_len,
            stream_bytes,
            cell_table_bytes,
            bits_per_point: file.file_len as f64 * 8.0 / h.points.max(1) as f64,
        }
    }
}

/// The out-of-core build of `input` into `output`, its temporary files in `scratch` (a
/// folder in `shown`, which messages name).
fn build_out_of_core(
    input: &Path,
    output: &Path,
    params: Params,
    scratch: &Path,
    shown: &Path,
) -> Result<nsp::ooc::Built> {
    let pb = progress::bar(0, "reading");
    let pause = fault("slow-build:");
    let report = |stage: &str, done: u64, total: u64| {
        if pb.message() != stage {
            pb.set_message(stage.to_string());
            pb.set_length(total);
            // Test hook: a pause once the buckets are written, nothing else running.
            if let Some(ms) = pause.filter(|_| stage == "merging coincident vertices") {
                std::thread::sleep(std::time::Duration::from_millis(ms));
            }
        }
        pb.set_position(done);
    };
    let scratch = nsp::ooc::Scratch { dir: scratch, shown, full_after: fault("temp-full:") };
    let mut built = None;
    let mut failure = None;
    write_atomic(output, |w| {
        match nsp::ooc::build_in(input, params, scratch, w, &report, nsp::ooc::Limits::default()) {
            Ok(b) => {
                built = Some(b);
                Ok(())
            }
            // The output's own write error: `write_atomic` names the output.
            Err(nsp::NspError::Output(e)) => Err(std::io::Error::other(e)),
            Err(e) => {
                failure = Some(e);
                Err(std::io::Error::other("the build failed"))
            }
        }
    })
    .map_err(|e| match failure.take() {
        Some(f) => anyhow::Error::new(f).context(format!("cannot build {}", input.display())),
        None => e,
    })?;
    pb.finish_and_clear();
    Ok(built.expect("built when written"))
}

/// Test hooks: `TESSERA_FAULT=slow-build:MS` pauses the out-of-core build MS milliseconds
/// once its temporary folder holds the buckets (so a test can signal it then);
/// `TESSERA_FAULT=temp-full:BYTES` makes its temporary files fail as on a full disk once
/// BYTES bytes are written. Unset in normal runs.
fn fault(prefix: &str) -> Option<u64> {
    std::env::var("TESSERA_FAULT").ok().and_then(|v| v.strip_prefix(prefix)?.parse().ok())
}

fn open(input: &Path) -> Result<NspFile> {
    NspFile::open(input).with_context(|| format!("{}", input.display()))
}

/// `tessera nsp stats X.nsp [--json]` (reads the header and the cell table only).
pub fn stats(input: &Path, json: bool) -> Result<()> {
    expect_kind(input, ModelKind::Nsp, "nsp stats", "stats")?;
    let file = open(input)?;
    let r = NspStatsReport::of(&file);
    if json {
        crate::outln!("{}", serde_json::to_string_pretty(&r)?)?;
        return Ok(());
    }
    crate::outln!("{}", input.display())?;
    crate::outln!(
        "  parameters     p = {} bits, p_r = {}, n = {}, N_min = {}",
        r.bits,
        r.root_bits,
        r.splits,
        r.min_simplices
    )?;
    crate::outln!("  input          {:>12} triangles, {} vertices", r.input_triangles, r.input_vertices)?;
    crate::outln!(
        "  canonical      {:>12} triangles, {} edges, {} isolated points, {} points (coincident vertices merged)",
        r.triangles,
        r.edges,
        r.isolated_points,
        r.points
    )?;
    crate::outln!(
        "  cells          {:>12}   ({} split, {} empty, depth {}; duplication {:.3})",
        r.cells,
        r.split_cells,
        r.empty_cells,
        r.depth,
        r.duplication
    )?;
    crate::outln!("  bytes          {:>12}   ({:.2} bits/point)", r.bytes, r.bits_per_point)?;
    crate::outln!("    header+table {:>12}", r.header_and_table_bytes)?;
    crate::outln!("    cell streams {:>12}", r.stream_bytes)?;
    crate::outln!("    cell table   {:>12}", r.cell_table_bytes)?;
    Ok(())
}

/// `tessera nsp adapt X.nsp [camera] --size WxH --error-px E -o OUT.ply [--full]`.
pub fn adapt(
    input: &Path,
    camera: &CameraSpec,
    size: (u32, u32),
    error_px: f32,
    full: bool,
    output: &Path,
) -> Result<()> {
    let writer = mesh_output(input, output, "the output of nsp adapt")?;
    expect_kind(input, ModelKind::Nsp, "nsp adapt", "adapt")?;
    let file = open(input)?;
    let start = Instant::now();
    let (drawn, cells) = if full {
        let states = nsp::decode::decode_uniform_states(&file, file.header.params.bits)
            .with_context(|| format!("{}", input.display()))?;
        let selection: Vec<(u32, u8)> = states.iter().map(|s| (s.cell, s.precision())).collect();
        (view::draw(&file, &selection, &states.iter().collect::<Vec<_>>()), states.len())
    } else {
        let (lo, hi) = nsp_bbox(&file);
        let cam = camera.camera(lo, hi, size.0 as f32 / size.1 as f32)?;
        crate::camera::check_camera(&cam, size.1)?;
        let v = view::View { camera: cam, width: size.0, height: size.1, error_px };
        let selection = view::select(&file, &v);
        let mut nav = view::Navigator::default();
        let states = nav.update(&file, &selection).with_context(|| format!("{}", input.display()))?;
        (view::draw(&file, &selection, &states), selection.len())
    };
    let secs = start.elapsed().as_secs_f64();
    let mesh = drawn.to_mesh();
    write_atomic(output, |w| writer(&mesh, w))?;
    summary(
        output,
        format_args!(
            "{} -> {}: {} triangles from {} cells ({} edges and {} points not drawn), {} of {} bytes read, in {:.1} ms",
            input.display(),
            output.display(),
            mesh.triangles.len(),
            cells,
            drawn.edges,
            drawn.points,
            file.bytes_read.load(Ordering::Relaxed),
            file.file_len,
            secs * 1e3
        ),
    )?;
    Ok(())
}

/// `tessera nsp build|stats|adapt`.
pub fn run(nsp: &Nsp) -> Result<()> {
    match nsp {
        Nsp::Build { input, output, bits, root_bits, splits, min_simplices, advance, temp_dir } => {
            let params = codec::nsp::Params {
                bits: *bits,
                root_bits: *root_bits,
                splits: *splits,
                min_simplices: *min_simplices,
                advance: *advance,
            };
            build(input, output, params, temp_dir.as_deref())
        }
        Nsp::Stats { input, json } => stats(input, *json),
        Nsp::Adapt { input, view, error_px, output, full } => {
            adapt(input, &view.camera.spec(), view.size, *error_px, *full, output)
        }
    }
}
