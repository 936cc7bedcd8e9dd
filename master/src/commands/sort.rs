//! `tessera sort`: one frame of the compression-domain tile sort, with a per-tile report,
//! the Tiled Tri baseline beside it, and optionally every tile's decoded submesh on disk.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use codec::bft::tile_sort::{self, Boxes, Sorter, Tile};
use codec::bft::{self, EncodeOptions};
use codec::tri_sort;
use codec::view::{Camera, TileGrid};
use serde::Serialize;

use crate::cli::SortArgs;
use crate::model::{chunked_camera, load_model, open_chunked, Chunked, Model};
use crate::output::{write_atomic, write_bytes};

#[derive(Debug, Serialize)]
pub struct TileSummary {
    pub index: usize,
    pub col: u32,
    pub row: u32,
    pub triangles: u32,
    pub vertices: usize,
    pub bytes: usize,
    /// Bytes the same triangles need as independent triangles.
    pub tri_bytes: usize,
}

impl TileSummary {
    fn new(index: usize, grid: &TileGrid, triangles: u32, vertices: usize, bytes: usize, tri_bytes: usize) -> Self {
        let (col, row) = (index as u32 % grid.cols, index as u32 / grid.cols);
        TileSummary { index, col, row, triangles, vertices, bytes, tri_bytes }
    }
}

#[derive(Debug, Serialize)]
pub struct Totals {
    pub triangles: usize,
    /// Triangles with a non-empty clipped screen box.
    pub visible_triangles: usize,
    /// Triangles summed over tiles (a triangle counts once per tile it overlaps).
    pub tiled_triangles: usize,
    pub nonempty_tiles: usize,
    /// The whole model as one BFT stream (the paper's "BFT").
    pub bft_bytes: usize,
    /// The visible triangles as independent triangles, 36 bytes each ("Tri").
    pub tri_bytes: usize,
    pub tiled_bft_bytes: usize,
    pub tiled_tri_bytes: usize,
}

/// What a chunked model's frame did with its chunks.
#[derive(Debug, Serialize)]
pub struct ChunkSummary {
    pub chunks: usize,
    /// Chunks a level-of-detail file's cut leaves out.
    pub not_in_cut: u32,
    pub culled: u32,
    pub verbatim: u32,
    pub straddling: u32,
    pub straddling_triangles: u64,
}

#[derive(Debug, Serialize)]
pub struct SortSummary {
    pub model: String,
    pub size: [u32; 2],
    pub tiles: [u32; 2],
    pub eye: [f32; 3],
    pub target: [f32; 3],
    pub up: [f32; 3],
    pub fovy: f32,
    pub near: f32,
    pub far: f32,
    pub sort_ms: f64,
    pub tri_sort_ms: f64,
    pub totals: Totals,
    /// Chunked models (no Tri sort is run for them: `tri_sort_ms` is 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chunks: Option<ChunkSummary>,
    pub per_tile: Vec<TileSummary>,
    /// In a dump's `summary.json` only: the files the dump wrote (`dump_files`), the only
    /// ones a later dump into the folder removes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dump_files: Option<Vec<String>>,
}

impl SortSummary {
    /// The summary of a frame of `name` seen by `cam` on `grid`, its times at zero and no
    /// chunks, for the caller to fill in.
    fn of_view(name: &str, cam: &Camera, grid: &TileGrid, totals: Totals, per_tile: Vec<TileSummary>) -> Self {
        SortSummary {
            model: name.to_string(),
            size: [grid.width, grid.height],
            tiles: [grid.cols, grid.rows],
            eye: cam.eye.to_array(),
            target: cam.target.to_array(),
            up: cam.up.to_array(),
            fovy: cam.fovy,
            near: cam.near,
            far: cam.far,
            sort_ms: 0.0,
            tri_sort_ms: 0.0,
            totals,
            chunks: None,
            per_tile,
            dump_files: None,
        }
    }
}

/// Sorts one frame with both sorts and summarises it. `sorter` and `boxes` keep the BFT
/// sort's buffers between calls, and `tri` the Tri sort's, as a frame loop does.
pub fn sort_frame(
    model: &Model,
    name: &str,
    cam: &Camera,
    grid: &TileGrid,
    sorter: &mut Sorter,
    boxes: &mut Boxes,
    tri: &mut tri_sort::TriBuffers,
) -> Result<(SortSummary, Vec<Tile>)> {
    let vp = cam.view_proj(grid.aspect());
    let start = Instant::now();
    tile_sort::boxes_into(&model.tiles, vp, grid, boxes);
    let tiles = sorter.sort(&model.tiles, boxes, grid)?;
    let sort_ms = start.elapsed().as_secs_f64() * 1e3;
    let start = Instant::now();
    tri_sort::sort_into(&model.tiles.positions, model.tiles.triangles(), vp, grid, tri);
    let tri_sort_ms = start.elapsed().as_secs_f64() * 1e3;
    let tri = &tri.tiles;

    let per_tile: Vec<TileSummary> = tiles
        .iter()
        .map(|t| TileSummary::new(t.index, grid, t.triangles, t.slots.len(), t.bytes.len(), tri[t.index].len()))
        .collect();
    let visible = boxes.triangles.iter().filter(|b| !b.is_empty()).count();
    let totals = Totals {
        triangles: model.tiles.triangles().len(),
        visible_triangles: visible,
        tiled_triangles: per_tile.iter().map(|t| t.triangles as usize).sum(),
        nonempty_tiles: tiles.len(),
        bft_bytes: model.bytes.len(),
        tri_bytes: visible * tri_sort::TRIANGLE_BYTES,
        tiled_bft_bytes: tiles.iter().map(|t| t.bytes.len()).sum(),
        tiled_tri_bytes: tri.iter().map(Vec::len).sum(),
    };
    let summary = SortSummary { sort_ms, tri_sort_ms, ..SortSummary::of_view(name, cam, grid, totals, per_tile) };
    Ok((summary, tiles))
}

/// A tile's index and its `.bft` streams.
pub type TileStreams = (usize, Vec<Vec<u8>>);

/// One frame of a chunked model's sort, summarised; each tile's streams (verbatim chunks and
/// sorted pieces) as `.bft` bytes.
pub fn sort_chunked_frame(
    model: &Chunked,
    name: &str,
    cam: &Camera,
    grid: &TileGrid,
    coding: bft::Coding,
) -> Result<(SortSummary, Vec<TileStreams>)> {
    use codec::bft::chunked::sort::PieceKind;
    let vp = cam.view_proj(grid.aspect());
    let start = Instant::now();
    let (tiles, counts) = model.sort(vp, grid, coding)?;
    let sort_ms = start.elapsed().as_secs_f64() * 1e3;
    let file = &model.file;
    let tiles: Vec<(usize, Vec<Vec<u8>>, u64, usize)> = tiles
        .into_iter()
        .map(|t| {
            let triangles = t.triangles();
            let mut vertices = 0;
            let streams = t
                .pieces
                .into_iter()
                .map(|p| match p.kind {
                    PieceKind::Verbatim => {
                        vertices += file.entries[p.chunk as usize].slots as usize;
                        Ok(file.chunk_bft(p.chunk as usize)?.into_owned())
                    }
                    PieceKind::Sorted { bytes, slots, .. } => {
                        vertices += slots.len();
                        Ok(bytes)
                    }
                })
                .collect::<Result<_, codec::bft::BftError>>()?;
            Ok((t.index, streams, triangles, vertices))
        })
        .collect::<Result<_>>()?;
    let per_tile: Vec<TileSummary> = tiles
        .iter()
        .map(|(index, streams, triangles, vertices)| {
            let bytes = streams.iter().map(Vec::len).sum();
            let tri_bytes = *triangles as usize * tri_sort::TRIANGLE_BYTES;
            TileSummary::new(*index, grid, *triangles as u32, *vertices, bytes, tri_bytes)
        })
        .collect();
    let totals = Totals {
        triangles: file.header.triangles as usize,
        visible_triangles: counts.visible_triangles as usize,
        tiled_triangles: per_tile.iter().map(|t| t.triangles as usize).sum(),
        nonempty_tiles: tiles.len(),
        bft_bytes: file.file_len() as usize,
        tri_bytes: counts.visible_triangles as usize * tri_sort::TRIANGLE_BYTES,
        tiled_bft_bytes: per_tile.iter().map(|t| t.bytes).sum(),
        tiled_tri_bytes: per_tile.iter().map(|t| t.tri_bytes).sum(),
    };
    let chunks = ChunkSummary {
        chunks: model.chunks(),
        not_in_cut: counts.not_in_cut,
        culled: counts.culled,
        verbatim: counts.verbatim,
        straddling: counts.straddling,
        straddling_triangles: counts.straddling_triangles,
    };
    let summary =
        SortSummary { sort_ms, chunks: Some(chunks), ..SortSummary::of_view(name, cam, grid, totals, per_tile) };
    Ok((summary, tiles.into_iter().map(|(i, s, _, _)| (i, s)).collect()))
}

/// The key of a dump's `summary.json` that lists the files the dump wrote: the only files a
/// later dump into the same folder removes.
const DUMP_FILES: &str = "dump_files";

/// The files an earlier dump in `dir` recorded in its `summary.json` (the summary itself
/// included), or `None` when the folder holds no summary. A summary that is not a dump's, or
/// that names anything but a plain file name, is an error: nothing is removed on its word.
fn recorded_dump(dir: &Path) -> Result<Option<std::collections::HashSet<std::ffi::OsString>>> {
    let path = dir.join("summary.json");
    match std::fs::symlink_metadata(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Ok(m) if m.is_file() => {}
        _ => bail!("--dump {}: its summary.json is not a regular file; give an empty or new folder", dir.display()),
    }
    let not_ours = || {
        anyhow::anyhow!(
            "--dump {}: its summary.json was not written by tessera sort --dump; give an empty or new folder",
            dir.display()
        )
    };
    let text = crate::model::read_input(&path)?;
    let json: serde_json::Value = serde_json::from_slice(&text).map_err(|_| not_ours())?;
    let files = json.get(DUMP_FILES).and_then(|f| f.as_array()).ok_or_else(not_ours)?;
    let mut names = std::collections::HashSet::from([std::ffi::OsString::from("summary.json")]);
    for f in files {
        let name = f.as_str().ok_or_else(not_ours)?;
        if name.is_empty() || name.contains('/') || name == "." || name == ".." {
            return Err(not_ours());
        }
        names.insert(name.into());
    }
    Ok(Some(names))
}

/// Checks, before any work, that `--dump DIR` is new, empty, or holds only the files an
/// earlier dump recorded in its summary (which [`clear_dump`] then removes); anything else in
/// it is refused, never deleted, whatever its name.
fn prepare_dump(dir: &Path, model: &Path) -> Result<()> {
    match std::fs::symlink_metadata(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))
        }
        Err(e) => Err(e).with_context(|| format!("cannot use {}", dir.display())),
        Ok(m) if !m.is_dir() => bail!("--dump {}: not a folder", dir.display()),
        Ok(_) => {
            crate::output::probe_writable(&dir.join("summary.json"), dir)?;
            let recorded = recorded_dump(dir)?.unwrap_or_default();
            let model_id = crate::output::Identity::of(model).ok();
            for entry in std::fs::read_dir(dir).with_context(|| format!("cannot read {}", dir.display()))? {
                let entry = entry.with_context(|| format!("cannot read {}", dir.display()))?;
                let is_file = entry.file_type().is_ok_and(|t| t.is_file());
                if model_id.is_some() && crate::output::Identity::of(&entry.path()).ok() == model_id {
                    bail!(
                        "--dump {}: the model {} is in the folder the dump would clear",
                        dir.display(),
                        model.display()
                    );
                }
                if !is_file || !recorded.contains(&entry.file_name()) {
                    bail!(
                        "--dump {}: the folder holds {}, which no earlier dump recorded; give an empty or new folder",
                        dir.display(),
                        entry.file_name().to_string_lossy()
                    );
                }
            }
            Ok(())
        }
    }
}

/// Removes the files an earlier dump recorded in `dir` (checked by [`prepare_dump`]).
fn clear_dump(dir: &Path) -> Result<()> {
    for name in recorded_dump(dir)?.unwrap_or_default() {
        let path = dir.join(&name);
        match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).with_context(|| format!("cannot remove {}", path.display()))
            }
            _ => {}
        }
    }
    Ok(())
}

/// `tessera sort MODEL --size WxH --tiles CxR [camera] [--dump DIR] [--json]`.
pub fn run(args: &SortArgs) -> Result<()> {
    let (path, camera, dump, json) = (args.model.as_path(), &args.camera.spec(), args.dump.as_ref(), args.json);
    let coding: bft::Coding = args.tile_coding.into();
    let grid = args.grid.grid()?;
    if let Some(dir) = dump {
        prepare_dump(dir, path)?;
    }
    let name = path.display().to_string();
    let (mut summary, tiles) = if let Some(mut model) = open_chunked(path, 1 << 30)? {
        model.error_px = Some(args.error_px);
        let cam = chunked_camera(&model, camera, &grid)?;
        crate::camera::check_camera(&cam, grid.height)?;
        sort_chunked_frame(&model, &name, &cam, &grid, coding)?
    } else {
        let model = load_model(path, EncodeOptions::default())?;
        let cam = model.camera(camera, &grid)?;
        crate::camera::check_camera(&cam, grid.height)?;
        let (summary, tiles) = sort_frame(
            &model,
            &name,
            &cam,
            &grid,
            &mut Sorter::new(coding),
            &mut Boxes::default(),
            &mut Default::default(),
        )?;
        (summary, tiles.into_iter().map(|t| (t.index, vec![t.bytes])).collect())
    };
    if let Some(dir) = dump {
        clear_dump(dir)?;
        // The summary, written first, records the files the dump writes, so that a later dump
        // removes exactly those, even after this one was interrupted.
        // Written from the summary itself, so that its fields keep their order and its `f32`
        // values their shortest form.
        let files: Vec<String> = tiles.iter().map(|(index, _)| format!("tile-{index}.ply")).collect();
        summary.dump_files = Some(files);
        write_bytes(&dir.join("summary.json"), serde_json::to_string_pretty(&summary)?.as_bytes())?;
        summary.dump_files = None;
        for (index, streams) in &tiles {
            let mut mesh = codec::Mesh::default();
            for s in streams {
                let m = bft::decode(s).with_context(|| format!("tile {index} does not decode"))?.to_mesh();
                let base = mesh.positions.len() as u32;
                mesh.positions.extend(m.positions);
                mesh.triangles.extend(m.triangles.iter().map(|t| t.map(|v| v + base)));
            }
            write_atomic(&dir.join(format!("tile-{index}.ply")), |w| codec::save::write_ply(&mesh, w))?;
        }
    }
    if json {
        crate::outln!("{}", serde_json::to_string_pretty(&summary)?)?;
    } else {
        let t = &summary.totals;
        crate::outln!(
            "{}: {}x{} tiles on {}x{}, {} of {} triangles visible, {} non-empty tiles",
            summary.model,
            grid.cols,
            grid.rows,
            grid.width,
            grid.height,
            t.visible_triangles,
            t.triangles,
            t.nonempty_tiles
        )?;
        crate::outln!("  BFT        {:>12} bytes   (whole model)", t.bft_bytes)?;
        crate::outln!("  Tiled BFT  {:>12} bytes   sort {:.1} ms", t.tiled_bft_bytes, summary.sort_ms)?;
        crate::outln!("  Tri        {:>12} bytes", t.tri_bytes)?;
        match &summary.chunks {
            None => crate::outln!("  Tiled Tri  {:>12} bytes   sort {:.1} ms", t.tiled_tri_bytes, summary.tri_sort_ms)?,
            Some(c) => {
                crate::outln!("  Tiled Tri  {:>12} bytes", t.tiled_tri_bytes)?;
                crate::outln!(
                    "  chunks     {:>12}   {}{} culled, {} verbatim, {} straddling ({} triangles sorted)",
                    c.chunks,
                    if c.not_in_cut > 0 { format!("{} not in the cut, ", c.not_in_cut) } else { String::new() },
                    c.culled,
                    c.verbatim,
                    c.straddling,
                    c.straddling_triangles
                )?;
            }
        }
        if let Some(dir) = dump {
            crate::outln!("  wrote {} tiles and summary.json to {}", tiles.len(), dir.display())?;
        }
    }
    Ok(())
}
