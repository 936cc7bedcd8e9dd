//! An `.nsp` model: rank 0 holds the header and cell tables, selects the view's cells and
//! precisions every frame, and sends each worker the cell streams it lacks, read from the
//! file and never decoded here.

use std::path::Path;

use anyhow::{Context, Result};
use codec::view::{Camera, TileGrid};
use protocol::{NspFrameJob, NspModel, ToWorker};

use super::contract::{FrameContext, FrameJobs, Scene};
use crate::camera::CameraSpec;
use crate::model::nsp_bbox;
use crate::render::stats::{NspStats, TileStats};

/// An `.nsp` model: its header and cell tables (the streams stay on disk until a worker
/// needs them), and the bytes of each cell's stream each worker holds (workers keep what
/// they are sent: the segments up to the highest precision they were asked for).
pub(super) struct NspScene {
    file: codec::nsp::NspFile,
    /// Indexed by worker rank - 1: cell -> bytes held.
    held: Vec<std::collections::HashMap<u32, u32>>,
}

impl NspScene {
    /// The `.nsp` file at `path`: its header and cell tables.
    pub(super) fn open(path: &Path) -> Result<NspScene> {
        let file = codec::nsp::NspFile::open(path).with_context(|| format!("{}", path.display()))?;
        Ok(NspScene { file, held: Vec::new() })
    }
}

impl Scene for NspScene {
    fn camera(&self, args: &CameraSpec, grid: &TileGrid) -> Result<Camera> {
        let (lo, hi) = nsp_bbox(&self.file);
        args.camera(lo, hi, grid.aspect())
    }

    fn model_message(&self) -> Option<Vec<u8>> {
        Some(ToWorker::NspModel(NspModel { skeleton: self.file.skeleton().to_vec() }).encode())
    }

    /// One frame of an `.nsp` model: the view's cells and precisions from the cell table
    /// alone; each worker draws the selected cells whose triangles can reach its tiles, and
    /// gets the streams of those cells and their ancestors that it does not hold yet. Rank 0
    /// reads those streams from the file and never decodes them.
    fn jobs(&mut self, ctx: &FrameContext) -> Result<FrameJobs> {
        use codec::nsp::view;
        let (grid, file) = (ctx.grid, &self.file);
        let vp = ctx.camera.view_proj(grid.aspect());
        let v = view::View { camera: ctx.camera, width: grid.width, height: grid.height, error_px: ctx.error_px };
        let selection = view::select(file, &v);
        let reach: Vec<Option<[u32; 4]>> = selection
            .iter()
            .map(|&(c, _)| {
                let (lo, hi) = view::reach_box(file, c);
                codec::view::box_screen_rect(lo, hi, vp, grid.width, grid.height)
            })
            .collect();
        let overlaps = |a: [u32; 4], b: [u32; 4]| a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3];
        let indices: Vec<usize> =
            (0..grid.tiles()).filter(|&i| reach.iter().flatten().any(|&r| overlaps(r, grid.tile_rect(i)))).collect();
        let owner = ctx.owners(&indices);
        if self.held.len() < ctx.workers {
            self.held.resize(ctx.workers, Default::default());
        }
        let mut stats = NspStats { selected: selection.len() as u32, ..NspStats::default() };
        let mut tile_stats = Vec::with_capacity(indices.len());
        let mut messages = Vec::new();
        for w in 1..=ctx.workers {
            let tiles: Vec<(u32, [u32; 4])> = indices
                .iter()
                .zip(&owner)
                .filter(|&(_, &o)| o == w)
                .map(|(&i, _)| (i as u32, grid.tile_rect(i)))
                .collect();
            if tiles.is_empty() {
                continue;
            }
            let drawn: Vec<(u32, u8)> = selection
                .iter()
                .zip(&reach)
                .filter(|(_, r)| r.is_some_and(|r| tiles.iter().any(|&(_, t)| overlaps(r, t))))
                .map(|(&cell, _)| cell)
                .collect();
            // The stream segments this worker lacks: of the drawn cells up to their
            // precisions, of their ancestors up to their maximal ones.
            let mut need: std::collections::BTreeMap<u32, u8> = std::collections::BTreeMap::new();
            for &(c, b) in &drawn {
                need.insert(c, b);
                let mut x = file.tree.nodes[c as usize].parent;
                while x != u32::MAX {
                    need.insert(x, file.tree.max_prec(x));
                    x = file.tree.nodes[x as usize].parent;
                }
            }
            let held = &mut self.held[w - 1];
            let mut cells = Vec::new();
            let mut bytes = 0;
            for (c, b) in need {
                let upto = file.needed(c, b);
                let have = held.entry(c).or_insert(0);
                if upto > *have {
                    let piece = file.cell_range(c, *have, upto)?;
                    bytes += piece.len();
                    cells.push((c, *have, piece));
                    *have = upto;
                }
            }
            stats.drawn += drawn.len() as u32;
            stats.sent += cells.len() as u32;
            stats.bytes_sent += bytes as u64;
            for (k, &(index, _)) in tiles.iter().enumerate() {
                // The worker's streams are counted on its first tile.
                tile_stats.push(TileStats {
                    index,
                    worker: w,
                    triangles: 0,
                    bytes: if k == 0 { bytes } else { 0 },
                    tri_bytes: 0,
                    normal_bytes: 0,
                });
            }
            let job = NspFrameJob {
                frame: ctx.frame,
                width: grid.width,
                height: grid.height,
                view_proj: vp.to_cols_array(),
                selection: selection.clone(),
                draw: drawn.iter().map(|&(c, _)| c).collect(),
                cells,
                tiles,
            };
            messages.push((w, ToWorker::NspFrame(job).encode()));
        }
        stats.bytes_read = file.bytes_read.load(std::sync::atomic::Ordering::Relaxed);
        tile_stats.sort_by_key(|t| t.index);
        Ok(FrameJobs { messages, tiles: tile_stats, chunks: None, nsp: Some(stats) })
    }
}
