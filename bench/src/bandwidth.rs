//! The bandwidth experiment (`cargo run --release -p tessera-bench --bin bandwidth`): Figure 8 of the paper (Mitra & Chiueh), bytes per frame against
//! tile size, for independent triangles ("Tri", "Tiled Tri"), the BFT model and the tile
//! sort's BFT submeshes ("BFT", "Tiled BFT"), with two baselines the paper did not have:
//! every tile's triangles compressed on their own by Draco and by meshopt.
//!
//! The baselines show what a sort-first renderer holding a conventionally compressed model
//! would send; `draco_retile_ms` is what it would pay per frame to get there (decode the
//! whole Draco model, bin its triangles, encode each tile), to set beside the BFT tile sort,
//! which produces its tiles straight from the compressed stream.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{ensure, Context, Result};
use codec::bft::tile_sort::{self, Boxes, Sorter};
use codec::bft::Coding;
use codec::bft::EncodeOptions;
use codec::view::{triangle_tile_boxes, TileBox, TileGrid};
use glam::Mat4;
use plotters::prelude::*;

use codec::bft::chunked::sort::{ChunkedModel, PieceKind};
use codec::bft::chunked::{encode_mesh_chunked, ChunkOptions, ChunkedFile};
use codec::view::Camera;
use master::camera::CameraSpec;
use master::commands::sort::{sort_frame, SortSummary};
use master::model::{load_model, Model};
use master::output::write_bytes;
use master::progress;
use master::render::orbit_by;

use crate::peers::{draco_decode, draco_encode, draco_to_mesh, Meshopt};
/// Runs of `sort_frame` per row, the two sorts alternating and the BFT sort keeping its
/// buffers as a frame loop does; the row keeps the median of each sort's time, so the
/// first, cold run (fresh pages, idle thread pool) does not count.
const SORT_RUNS: usize = 7;

const CSV_HEADER: &str = "model,triangles,width,height,cols,rows,tile_width,tile_height,tri_bytes,tiled_tri_bytes,\
bft_bytes,tiled_bft_bytes,draco_per_tile_bytes,meshopt_per_tile_bytes,bft_sort_ms,tri_sort_ms,draco_retile_ms,\
tiled_bft_prefix_bytes,bft_prefix_sort_ms,chunks,chunked_tiled_bft_bytes,chunked_sort_ms,chunked_orbit_bytes";

/// One model on one tile grid: a CSV row.
struct Row {
    model: String,
    triangles: usize,
    grid: TileGrid,
    tri_bytes: usize,
    tiled_tri_bytes: usize,
    bft_bytes: usize,
    tiled_bft_bytes: usize,
    draco_per_tile_bytes: usize,
    meshopt_per_tile_bytes: usize,
    bft_sort_ms: f64,
    tri_sort_ms: f64,
    draco_retile_ms: f64,
    /// The same tiles coded with `--tile-coding prefix`, and that sort's time.
    tiled_bft_prefix_bytes: usize,
    bft_prefix_sort_ms: f64,
    /// The model as a chunked file (`encode`'s default chunk size; 1 chunk is the single
    /// stream): its chunks, its first frame's tile bytes (range-coded, verbatim chunks whole)
    /// and sort time (median, tables cached), and the bytes per frame along a slow orbit (one
    /// degree a frame, frames 2 to 9) when the worker keeps the chunks it was sent.
    chunks: usize,
    chunked_tiled_bft_bytes: usize,
    chunked_sort_ms: f64,
    chunked_orbit_bytes: usize,
}

impl Row {
    /// Nominal tile size in pixels; tiles of a grid that does not divide the screen differ
    /// from it by at most one pixel.
    fn tile_size(&self) -> (f64, f64) {
        let g = &self.grid;
        (g.width as f64 / g.cols as f64, g.height as f64 / g.rows as f64)
    }

    fn csv(&self) -> String {
        let g = &self.grid;
        let (tw, th) = self.tile_size();
        format!(
            "{},{},{},{},{},{},{tw},{th},{},{},{},{},{},{},{:.3},{:.3},{:.3},{},{:.3},{},{},{:.3},{}",
            csv_field(&self.model),
            self.triangles,
            g.width,
            g.height,
            g.cols,
            g.rows,
            self.tri_bytes,
            self.tiled_tri_bytes,
            self.bft_bytes,
            self.tiled_bft_bytes,
            self.draco_per_tile_bytes,
            self.meshopt_per_tile_bytes,
            self.bft_sort_ms,
            self.tri_sort_ms,
            self.draco_retile_ms,
            self.tiled_bft_prefix_bytes,
            self.bft_prefix_sort_ms,
            self.chunks,
            self.chunked_tiled_bft_bytes,
            self.chunked_sort_ms,
            self.chunked_orbit_bytes
        )
    }

    const TABLE_HEADER: &str = "model               tiles    tile px         Tri   Tiled Tri         BFT   Tiled BFT  Draco/tile  meshopt/tile  TiledBFT/Draco  BFT sort ms  Tri sort ms  Draco retile ms  BFT/Tri sort  BFT/retile  Tiled BFT prefix  prefix sort ms  chunks  chunked Tiled BFT  chunked sort ms  orbit bytes/frame";

    fn table(&self) -> String {
        let (tw, th) = self.tile_size();
        format!(
            "{:<18} {:>6} {:>10} {:>11} {:>11} {:>11} {:>11} {:>11} {:>13} {:>15.3} {:>12.2} {:>12.2} {:>16.1} {:>13.2} {:>11.4} {:>17} {:>15.2} {:>7} {:>18} {:>16.2} {:>18}",
            self.model,
            format!("{}x{}", self.grid.cols, self.grid.rows),
            format!("{tw:.0}x{th:.0}"),
            self.tri_bytes,
            self.tiled_tri_bytes,
            self.bft_bytes,
            self.tiled_bft_bytes,
            self.draco_per_tile_bytes,
            self.meshopt_per_tile_bytes,
            self.tiled_bft_bytes as f64 / self.draco_per_tile_bytes as f64,
            self.bft_sort_ms,
            self.tri_sort_ms,
            self.draco_retile_ms,
            self.bft_sort_ms / self.tri_sort_ms,
            self.bft_sort_ms / self.draco_retile_ms,
            self.tiled_bft_prefix_bytes,
            self.bft_prefix_sort_ms,
            self.chunks,
            self.chunked_tiled_bft_bytes,
            self.chunked_sort_ms,
            self.chunked_orbit_bytes
        )
    }
}

/// Quotes a CSV field that holds a separator, a quote or a line break (RFC 4180).
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// A model loaded for the experiment, with what every grid's row needs from it.
struct Subject {
    name: String,
    model: Model,
    /// The model's triangles with every duplicate slot (one input vertex the encoder split
    /// into several slots) replaced by its source slot, as `Decoded::to_mesh` welds them: the
    /// baselines compress the input's connectivity, not the BFT encoder's split of it.
    welded: Vec<[u32; 3]>,
    /// The whole model as one Draco stream, what a Draco-based renderer would hold.
    draco: Vec<u8>,
    /// The model as a chunked file, if it makes more than one chunk.
    chunked: Option<ChunkedModel<Vec<u8>>>,
}

impl Subject {
    fn load(path: &Path, quant_bits: u8) -> Result<Subject> {
        // Positions only, as the peers and the paper's Figure 8 have them.
        let positions_only = EncodeOptions { quant_bits, colors: false, normals: false, ..Default::default() };
        let model = load_model(path, positions_only)?;
        let decoded = &model.tiles.decoded;
        let mut source: Vec<u32> = (0..decoded.positions.len() as u32).collect();
        for &(slot, from) in &decoded.duplicates {
            source[slot as usize] = source[from as usize];
        }
        let welded = decoded.triangles.iter().map(|t| t.map(|s| source[s as usize])).collect();
        let mesh = decoded.to_mesh();
        let draco = draco_encode(&mesh.positions, &mesh.triangles, decoded.header.quant_bits)
            .with_context(|| format!("Draco cannot encode {}", path.display()))?;
        let input = codec::load_path(path)?;
        let opts = ChunkOptions { quant_bits, stream: positions_only, ..Default::default() };
        let (bytes, _) =
            encode_mesh_chunked(&input, &opts).with_context(|| format!("cannot chunk {}", path.display()))?;
        let chunked = if codec::bft::chunked::is_chunked(&bytes) {
            // The sort column times the sort with its tables cached, not a still view's reuse.
            let mut model = ChunkedModel::new(ChunkedFile::open(bytes)?, 1 << 30);
            model.keep_sorts = false;
            Some(model)
        } else {
            None
        };
        Ok(Subject { name: model_name(path), model, welded, draco, chunked })
    }

    /// The chunked columns of a row: chunks, first-frame tile bytes, sort time, and bytes
    /// per frame along a slow orbit with the chunks a worker keeps not sent again.
    fn measure_chunked(
        &self,
        cam: &Camera,
        grid: &TileGrid,
        single: (usize, f64),
    ) -> Result<(usize, usize, f64, usize)> {
        let Some(model) = &self.chunked else {
            // One chunk: the single stream, which a worker cannot keep (it is a tile sort).
            return Ok((1, single.0, single.1, single.0));
        };
        let frame_bytes = |vp: Mat4, kept: &mut std::collections::HashSet<u32>| -> Result<usize> {
            let (tiles, _) = model.sort(vp, grid, Coding::Range)?;
            Ok(tiles
                .iter()
                .flat_map(|t| &t.pieces)
                .map(|p| match &p.kind {
                    PieceKind::Sorted { bytes, .. } => bytes.len(),
                    PieceKind::Verbatim if kept.insert(p.chunk) => {
                        model.file.entries[p.chunk as usize].bft_len as usize
                    }
                    PieceKind::Verbatim => 0,
                })
                .sum())
        };
        let vp = cam.view_proj(grid.aspect());
        let first = frame_bytes(vp, &mut Default::default())?;
        let mut times = Vec::new();
        for _ in 0..SORT_RUNS {
            let t = Instant::now();
            model.sort(vp, grid, Coding::Range)?;
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(f64::total_cmp);
        let mut kept = Default::default();
        let mut orbit = 0;
        for k in 0..9 {
            let bytes = frame_bytes(orbit_by(cam, k, 9, 9.0).view_proj(grid.aspect()), &mut kept)?;
            if k > 0 {
                orbit += bytes;
            }
        }
        Ok((model.chunks(), first, times[times.len() / 2], orbit / 8))
    }

    /// Measures one row.
    fn measure(&self, grid: &TileGrid) -> Result<Row> {
        let tiles = &self.model.tiles;
        let bits = tiles.decoded.header.quant_bits;
        let cam = self.model.camera(&CameraSpec::default(), grid)?;
        let (mut sorter, mut prefix_sorter) = (Sorter::new(Coding::Range), Sorter::new(Coding::Prefix));
        let (mut runs, mut prefix_runs) = (Vec::new(), Vec::new());
        let (mut boxes, mut prefix_boxes) = (Boxes::default(), Boxes::default());
        let (mut tri, mut prefix_tri) = Default::default();
        for _ in 0..SORT_RUNS {
            runs.push(sort_frame(&self.model, &self.name, &cam, grid, &mut sorter, &mut boxes, &mut tri)?.0);
            prefix_runs.push(
                sort_frame(
                    &self.model,
                    &self.name,
                    &cam,
                    grid,
                    &mut prefix_sorter,
                    &mut prefix_boxes,
                    &mut prefix_tri,
                )?
                .0,
            );
        }
        let median = |runs: &[SortSummary], time: fn(&SortSummary) -> f64| {
            let mut t: Vec<f64> = runs.iter().map(time).collect();
            t.sort_by(f64::total_cmp);
            t[t.len() / 2]
        };
        let totals = &runs[0].totals;
        ensure!(
            prefix_runs[0].totals.tiled_triangles == totals.tiled_triangles,
            "{}: the two tile codings hold different triangles",
            self.name
        );

        let view_proj = cam.view_proj(grid.aspect());
        let boxes = tile_sort::boxes(tiles, view_proj, grid);
        let sets = tile_sets(&self.welded, tiles.positions.len(), &boxes.triangles, grid);
        let tiled_triangles: usize = sets.iter().map(|s| s.triangles.len()).sum();
        ensure!(
            tiled_triangles == totals.tiled_triangles,
            "{}: the baselines' tiles hold {tiled_triangles} triangles, the BFT tiles {}",
            self.name,
            totals.tiled_triangles
        );
        let draco_per_tile_bytes = sets
            .iter()
            .map(|s| Ok(draco_encode(&s.gather(&tiles.positions), &s.triangles, bits)?.len()))
            .sum::<Result<usize>>()?;
        let meshopt_per_tile_bytes =
            sets.iter().map(|s| meshopt_bytes(s, &tiles.decoded.positions, bits)).sum::<Result<usize>>()?;

        let bft_sort_ms = median(&runs, |s| s.sort_ms);
        let (chunks, chunked_tiled_bft_bytes, chunked_sort_ms, chunked_orbit_bytes) =
            self.measure_chunked(&cam, grid, (totals.tiled_bft_bytes, bft_sort_ms))?;
        Ok(Row {
            model: self.name.clone(),
            triangles: totals.triangles,
            grid: *grid,
            tri_bytes: totals.tri_bytes,
            tiled_tri_bytes: totals.tiled_tri_bytes,
            bft_bytes: totals.bft_bytes,
            tiled_bft_bytes: totals.tiled_bft_bytes,
            draco_per_tile_bytes,
            meshopt_per_tile_bytes,
            bft_sort_ms,
            tri_sort_ms: median(&runs, |s| s.tri_sort_ms),
            draco_retile_ms: draco_retile_ms(&self.draco, view_proj, grid, bits)?,
            tiled_bft_prefix_bytes: prefix_runs[0].totals.tiled_bft_bytes,
            bft_prefix_sort_ms: median(&prefix_runs, |s| s.sort_ms),
            chunks,
            chunked_tiled_bft_bytes,
            chunked_sort_ms,
            chunked_orbit_bytes,
        })
    }
}

/// The file name up to its first dot: `bunny_zipper_c3d.obj.gz` is `bunny_zipper_c3d`.
fn model_name(path: &Path) -> String {
    let file = path.file_name().map_or_else(|| path.display().to_string(), |f| f.to_string_lossy().into_owned());
    file.split('.').next().unwrap_or_default().to_string()
}

/// One tile's triangles as a mesh of its own: `triangles` index `vertices`, which name the
/// model vertex of each tile vertex, in order of first use.
#[derive(Default)]
struct TileSet {
    vertices: Vec<u32>,
    triangles: Vec<[u32; 3]>,
}

impl TileSet {
    /// The tile's values of a per-vertex model attribute.
    fn gather<T: Copy>(&self, all: &[T]) -> Vec<T> {
        self.vertices.iter().map(|&v| all[v as usize]).collect()
    }
}

/// The triangle set of every non-empty tile: triangle `t` is in tile `(c, r)` iff
/// `boxes[t]` contains it, the rule the BFT and Tri sorts follow, so every tile holds the
/// triangles its Tiled BFT submesh decodes to.
fn tile_sets(triangles: &[[u32; 3]], vertex_count: usize, boxes: &[TileBox], grid: &TileGrid) -> Vec<TileSet> {
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); grid.tiles()];
    for (t, b) in boxes.iter().enumerate().filter(|(_, b)| !b.is_empty()) {
        for r in b.r0..=b.r1 {
            for c in b.c0..=b.c1 {
                members[r as usize * grid.cols as usize + c as usize].push(t as u32);
            }
        }
    }
    // Tile index of each model vertex while its tile is built; reset after each tile.
    let mut local = vec![u32::MAX; vertex_count];
    members
        .into_iter()
        .filter(|m| !m.is_empty())
        .map(|m| {
            let mut set = TileSet::default();
            for t in m {
                let tri = triangles[t as usize].map(|v| {
                    let l = &mut local[v as usize];
                    if *l == u32::MAX {
                        *l = set.vertices.len() as u32;
                        set.vertices.push(v);
                    }
                    *l
                });
                set.triangles.push(tri);
            }
            for &v in &set.vertices {
                local[v as usize] = u32::MAX;
            }
            set
        })
        .collect()
}

/// Milliseconds for Draco to turn the whole-model stream into per-tile Draco streams:
/// decode, bin the triangles into tiles, encode every tile. As in the BFT sort, which
/// projects with rayon, the machine's cores may help: draco-core splits large attribute
/// passes across threads; binning and the tile encodes run one after another.
fn draco_retile_ms(stream: &[u8], view_proj: Mat4, grid: &TileGrid, quant_bits: u8) -> Result<f64> {
    let start = Instant::now();
    let mesh = draco_to_mesh(&draco_decode(stream)?)?;
    let boxes = triangle_tile_boxes(&mesh.positions, &mesh.triangles, view_proj, grid);
    for set in tile_sets(&mesh.triangles, mesh.positions.len(), &boxes, grid) {
        draco_encode(&set.gather(&mesh.positions), &set.triangles, quant_bits)?;
    }
    Ok(start.elapsed().as_secs_f64() * 1e3)
}

/// meshopt's bytes for a tile, on the model's own quantized positions (see `peers`).
fn meshopt_bytes(set: &TileSet, quantized: &[[u32; 3]], quant_bits: u8) -> Result<usize> {
    Ok(Meshopt::encode_quantized(&set.triangles, &set.gather(quantized), quant_bits)?.bytes())
}

/// `bandwidth MODEL... [--tiles LIST] [--size WxH] [--quant-bits N] --out CSV --plot PNG`.
pub fn run(
    models: &[PathBuf],
    size: (u32, u32),
    tiles: &[(u32, u32)],
    quant_bits: u8,
    out: &Path,
    plot: &Path,
) -> Result<()> {
    // Everything that can be wrong with the request fails here, before minutes of work.
    let grids: Vec<TileGrid> = tiles
        .iter()
        .map(|&(c, r)| TileGrid::new(size.0, size.1, c, r).with_context(|| format!("bad --tiles entry {c}x{r}")))
        .collect::<Result<_>>()?;
    master::output::check_extension(out, &["csv"], "--out")?;
    master::output::check_extension(plot, &["png"], "--plot")?;
    for path in [out, plot] {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        }
    }
    let inputs: Vec<&Path> = models.iter().map(PathBuf::as_path).collect();
    master::output::check_distinct(&inputs, &[out, plot])?;
    let subjects: Vec<Subject> = models.iter().map(|p| Subject::load(p, quant_bits)).collect::<Result<_>>()?;

    println!("{}", Row::TABLE_HEADER);
    let pb = progress::bar((subjects.len() * grids.len()) as u64, "measuring");
    let mut rows = Vec::new();
    for subject in &subjects {
        for grid in &grids {
            let row = subject.measure(grid)?;
            pb.suspend(|| println!("{}", row.table()));
            pb.inc(1);
            rows.push(row);
        }
    }
    pb.finish_and_clear();

    let mut csv = format!("{CSV_HEADER}\n");
    for row in &rows {
        writeln!(csv, "{}", row.csv())?;
    }
    write_bytes(out, csv.as_bytes())?;
    let panels: Vec<&[Row]> = rows.chunks(grids.len()).collect();
    write_bytes(plot, &render_plot(&panels, size, quant_bits)?)?;
    println!("wrote {} and {}", out.display(), plot.display());
    Ok(())
}

/// A plotted quantity: one line in each model's panel.
struct Series {
    name: &'static str,
    bytes: fn(&Row) -> usize,
    color: RGBColor,
}

/// The paper's four series (the whole-model ones in a lighter shade of their tiled
/// counterpart), our faster tile coding, then the baselines.
const SERIES: [Series; 7] = [
    Series { name: "Tri", bytes: |r| r.tri_bytes, color: RGBColor(160, 160, 160) },
    Series { name: "Tiled Tri", bytes: |r| r.tiled_tri_bytes, color: RGBColor(0, 0, 0) },
    Series { name: "BFT", bytes: |r| r.bft_bytes, color: RGBColor(120, 170, 230) },
    Series { name: "Tiled BFT", bytes: |r| r.tiled_bft_bytes, color: RGBColor(20, 60, 200) },
    Series { name: "Tiled BFT, prefix-coded", bytes: |r| r.tiled_bft_prefix_bytes, color: RGBColor(140, 60, 200) },
    Series { name: "Draco per tile", bytes: |r| r.draco_per_tile_bytes, color: RGBColor(210, 40, 40) },
    Series { name: "meshopt per tile", bytes: |r| r.meshopt_per_tile_bytes, color: RGBColor(30, 150, 60) },
];

const PANEL_SIZE: (u32, u32) = (900, 650);

/// Renders the figure as PNG bytes: one panel per model, from that model's rows.
fn render_plot(panels: &[&[Row]], size: (u32, u32), quant_bits: u8) -> Result<Vec<u8>> {
    master::commands::plot::register_font()?;
    let cols = (panels.len() as f64).sqrt().ceil().max(1.0) as u32;
    let grid_rows = (panels.len() as u32).div_ceil(cols).max(1);
    let (w, h) = (PANEL_SIZE.0 * cols, PANEL_SIZE.1 * grid_rows + 50);
    let mut pixels = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, (w, h)).into_drawing_area();
        root.fill(&WHITE)?;
        let title = format!(
            "Bytes per frame against tile size ({}x{} screen, {quant_bits}-bit positions for mesh inputs)",
            size.0, size.1
        );
        let root = root.titled(&title, ("sans-serif", 30))?;
        for (area, rows) in root.split_evenly((grid_rows as usize, cols as usize)).iter().zip(panels) {
            draw_panel(area, rows)?;
        }
        root.present()?;
    }
    master::composite::encode_png(w, h, png::ColorType::Rgb, &pixels)
}

/// One model's panel: a line per series over tile width, both axes logarithmic, ticks at
/// the measured tile widths and at 1, 2 and 5 times powers of ten bytes.
fn draw_panel(area: &DrawingArea<BitMapBackend, plotters::coord::Shift>, rows: &[Row]) -> Result<()> {
    let mut rows: Vec<&Row> = rows.iter().collect();
    rows.sort_by(|a, b| a.tile_size().0.total_cmp(&b.tile_size().0));
    let mut widths: Vec<f64> = rows.iter().map(|r| r.tile_size().0).collect();
    widths.dedup();
    let (x_lo, x_hi) = (widths[0], widths[widths.len() - 1]);
    let ys = rows.iter().flat_map(|r| SERIES.iter().map(move |s| (s.bytes)(r) as f64)).filter(|&y| y > 0.0);
    let (y_lo, y_hi) = ys.fold((f64::INFINITY, 0.0f64), |(lo, hi), y| (lo.min(y), hi.max(y)));
    let (y_lo, y_hi) = if y_hi > 0.0 { (y_lo / 1.5, y_hi * 1.5) } else { (1.0, 10.0) };
    let y_ticks: Vec<f64> = (y_lo.log10().floor() as i32..=y_hi.log10().ceil() as i32)
        .flat_map(|e| [1.0, 2.0, 5.0].map(|m| m * 10f64.powi(e)))
        .filter(|y| (y_lo..=y_hi).contains(y))
        .collect();

    let mut chart = ChartBuilder::on(area)
        .caption(format!("{} ({} triangles)", rows[0].model, rows[0].triangles), ("sans-serif", 24))
        .margin(15)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (x_lo / 1.3..x_hi * 1.3).log_scale().with_key_points(widths),
            (y_lo..y_hi).log_scale().with_key_points(y_ticks),
        )?;
    chart
        .configure_mesh()
        .x_desc("tile width in pixels (log scale)")
        .y_desc("bytes per frame (log scale)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| human_bytes(*y))
        .label_style(("sans-serif", 16))
        .axis_desc_style(("sans-serif", 18))
        .draw()?;
    for Series { name, bytes, color } in SERIES {
        let points = rows.iter().map(|r| (r.tile_size().0, bytes(r) as f64)).filter(|&(_, y)| y > 0.0);
        chart
            .draw_series(LineSeries::new(points, color.stroke_width(2)).point_size(3))?
            .label(name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(3)));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::MiddleRight)
        .label_font(("sans-serif", 16))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

/// `1.5M`, `200k`, `900`: axis labels that fit.
fn human_bytes(v: f64) -> String {
    match v {
        v if v >= 1e6 => format!("{}M", trim(v / 1e6)),
        v if v >= 1e3 => format!("{}k", trim(v / 1e3)),
        v => trim(v),
    }
}

fn trim(v: f64) -> String {
    let s = format!("{v:.1}");
    s.strip_suffix(".0").unwrap_or(&s).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_sets_are_compact_and_follow_the_boxes() {
        let grid = TileGrid::new(4, 4, 2, 1).unwrap();
        let triangles = [[0, 1, 2], [2, 3, 4], [4, 5, 0]];
        let boxes = [TileBox { c0: 0, c1: 0, r0: 0, r1: 0 }, TileBox { c0: 0, c1: 1, r0: 0, r1: 0 }, TileBox::EMPTY];
        let sets = tile_sets(&triangles, 6, &boxes, &grid);
        assert_eq!(sets.len(), 2);
        assert_eq!(sets[0].vertices, [0, 1, 2, 3, 4]);
        assert_eq!(sets[0].triangles, [[0, 1, 2], [2, 3, 4]]);
        assert_eq!(sets[1].vertices, [2, 3, 4]);
        assert_eq!(sets[1].triangles, [[0, 1, 2]]);
        assert_eq!(sets[1].gather(&[10, 11, 12, 13, 14, 15]), [12, 13, 14]);
    }

    #[test]
    fn model_names_drop_every_extension() {
        assert_eq!(model_name(Path::new("../m/bunny_zipper_c3d.obj.gz")), "bunny_zipper_c3d");
        assert_eq!(csv_field("a,b"), "\"a,b\"");
    }
}
