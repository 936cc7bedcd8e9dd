//! One frame's messages to the workers, and the tile lines of its stats.

use anyhow::Result;
use codec::bft::chunked::sort::{share, PieceKind};
use codec::bft::tile_sort;
use codec::view::{Camera, TileGrid};
use protocol::{FrameJob, NspFrameJob, PmFrameJob, SortJob, StreamSource, TileJob, TileStream, ToWorker};
use worker::chunk_cache::ChunkCache;

use super::scene::{BftScene, ChunkedScene, NspScene, PmScene, Scene};
use super::schedule::assign;
use super::stats::{ChunkStats, NspStats, TileStats};
use crate::cli::RenderArgs;

/// What every frame's jobs are made from.
pub(super) struct FrameContext<'a> {
    /// The frame's number, from 0.
    pub frame: u32,
    pub camera: Camera,
    pub grid: &'a TileGrid,
    /// Workers are ranks `1..=workers`.
    pub workers: usize,
    pub args: &'a RenderArgs,
    /// Each tile's cost the frame before (ms), for `--balance`.
    pub costs: &'a [f64],
}

impl FrameContext<'_> {
    /// The worker of each of `tiles`.
    fn owners(&self, tiles: &[usize]) -> Vec<usize> {
        assign(tiles, self.workers, self.args.balance.then_some(self.costs))
    }
}

/// A frame's messages to the workers (by rank) and its tile lines for the stats.
pub(super) struct FrameJobs {
    pub messages: Vec<(usize, Vec<u8>)>,
    pub tiles: Vec<TileStats>,
    pub chunks: Option<ChunkStats>,
    pub nsp: Option<NspStats>,
}

impl Scene {
    /// The frame's jobs for either kind of model.
    pub fn jobs(&mut self, ctx: &FrameContext) -> Result<FrameJobs> {
        match self {
            Scene::Bft(s) => s.jobs(ctx),
            Scene::Chunked(s) => s.jobs(ctx),
            Scene::Pm(s) => Ok(s.jobs(ctx)),
            Scene::Nsp(s) => s.jobs(ctx),
        }
    }

    /// Messages that must leave before this rank sorts (other sorters' orders).
    pub fn announce(&mut self, ctx: &FrameContext) -> Vec<(usize, Vec<u8>)> {
        match self {
            Scene::Chunked(s) => s.announce(ctx),
            _ => Vec::new(),
        }
    }
}

impl BftScene {
    /// One frame of a BFT model: the tile sort, then each worker's tiles with their border
    /// normals, as messages.
    fn jobs(&mut self, ctx: &FrameContext) -> Result<FrameJobs> {
        let grid = ctx.grid;
        let vp = ctx.camera.view_proj(grid.aspect());
        let model = &self.model.tiles;
        tile_sort::boxes_into(model, vp, grid, &mut self.boxes);
        let tiles = self.sorter.sort(model, &self.boxes, grid)?;
        let borders = self.normals.for_tiles(model, &self.boxes, &tiles, grid);
        let indices: Vec<usize> = tiles.iter().map(|t| t.index).collect();
        let owner = ctx.owners(&indices);
        let mut jobs = ctx.frame_jobs(vp, 0);
        let mut tile_stats = Vec::with_capacity(tiles.len());
        for ((tile, normals), &w) in tiles.into_iter().zip(borders).zip(&owner) {
            tile_stats.push(TileStats {
                index: tile.index as u32,
                worker: w,
                triangles: tile.triangles,
                bytes: tile.bytes.len(),
                tri_bytes: tile.triangles as usize * codec::tri_sort::TRIANGLE_BYTES,
                normal_bytes: normals.len() * 16,
            });
            jobs[w - 1].tiles.push(TileJob {
                index: tile.index as u32,
                rect: grid.tile_rect(tile.index),
                streams: vec![TileStream { source: StreamSource::Bytes(tile.bytes), normals }],
            });
        }
        Ok(FrameJobs { messages: frame_messages(jobs), tiles: tile_stats, chunks: None, nsp: None })
    }
}

/// One empty frame job per worker: sorter `sorter`'s share of `sorters`.
fn empty_jobs(ctx: &ShareContext, sorter: usize, chunk_cache: u64) -> Vec<FrameJob> {
    (0..ctx.workers)
        .map(|_| FrameJob {
            frame: ctx.frame,
            width: ctx.grid.width,
            height: ctx.grid.height,
            view_proj: ctx.view_proj.to_cols_array(),
            decode_only: ctx.decode_only,
            sorter: sorter as u8,
            sorters: ctx.sorters as u8,
            chunk_cache,
            tiles: vec![],
        })
        .collect()
}

impl FrameContext<'_> {
    /// One empty frame job per worker, for a frame sorted by rank 0 alone.
    fn frame_jobs(&self, vp: glam::Mat4, chunk_cache: u64) -> Vec<FrameJob> {
        let share = ShareContext {
            frame: self.frame,
            grid: self.grid,
            view_proj: vp,
            workers: self.workers,
            sorters: 1,
            decode_only: self.args.decode_only,
        };
        empty_jobs(&share, 0, chunk_cache)
    }
}

/// Every worker's frame message, by rank.
pub(super) fn frame_messages(jobs: Vec<FrameJob>) -> Vec<(usize, Vec<u8>)> {
    jobs.into_iter().enumerate().map(|(i, j)| (i + 1, ToWorker::Frame(j).encode())).collect()
}

/// What one sorter's share of a chunked frame is made from.
pub(super) struct ShareContext<'a> {
    pub frame: u32,
    pub grid: &'a TileGrid,
    pub view_proj: glam::Mat4,
    /// Workers are ranks `1..=workers`.
    pub workers: usize,
    pub sorters: usize,
    pub decode_only: bool,
}

/// One sorter's share of a chunked frame: its jobs for every worker, their tile lines, and
/// what the share did with its chunks.
pub(super) struct Share {
    pub jobs: Vec<FrameJob>,
    pub tiles: Vec<TileStats>,
    pub chunks: ChunkStats,
}

impl ChunkedScene {
    /// With several sorters, the messages that set the others to work on this frame (sent
    /// before rank 0 sorts its own share): the view, and the worker of every tile, which rank
    /// 0 decides for all (round robin over the grid's tiles, or `--balance`).
    pub fn announce(&mut self, ctx: &FrameContext) -> Vec<(usize, Vec<u8>)> {
        if self.sorters == 1 {
            return Vec::new();
        }
        let all: Vec<usize> = (0..ctx.grid.tiles()).collect();
        self.owners = ctx.owners(&all);
        let job = SortJob {
            frame: ctx.frame,
            view_proj: ctx.camera.view_proj(ctx.grid.aspect()).to_cols_array(),
            owners: self.owners.iter().map(|&w| w as u32).collect(),
        };
        let msg = protocol::ToSorter::Sort(job).encode();
        (1..self.sorters).map(|s| (ctx.workers + s, msg.clone())).collect()
    }

    /// One frame of a chunked model on rank 0: its share of the sort (all of it with one
    /// sorter), as every worker's message.
    fn jobs(&mut self, ctx: &FrameContext) -> Result<FrameJobs> {
        let share = ShareContext {
            frame: ctx.frame,
            grid: ctx.grid,
            view_proj: ctx.camera.view_proj(ctx.grid.aspect()),
            workers: ctx.workers,
            sorters: self.sorters,
            decode_only: ctx.args.decode_only,
        };
        let owners = std::mem::take(&mut self.owners);
        let result = self.share_jobs(&share, 0, |tiles| {
            if owners.is_empty() {
                ctx.owners(tiles)
            } else {
                tiles.iter().map(|&t| owners[t]).collect()
            }
        });
        self.owners = owners;
        let Share { jobs, tiles, chunks } = result?;
        Ok(FrameJobs { messages: frame_messages(jobs), tiles, chunks: Some(chunks), nsp: None })
    }

    /// Sorter `sorter`'s share of a frame: the chunked sort of its chunks, then each worker's
    /// tiles (the worker of each from `owner_of`), whose verbatim chunks go as bytes (with
    /// their border normals) unless the worker kept them, as this rank's mirror of the
    /// worker's cache for this sorter says.
    pub fn share_jobs(
        &mut self,
        ctx: &ShareContext,
        sorter: usize,
        owner_of: impl FnOnce(&[usize]) -> Vec<usize>,
    ) -> Result<Share> {
        let (grid, vp) = (ctx.grid, ctx.view_proj);
        let range = share(self.model.chunks(), sorter, ctx.sorters);
        let (tiles, counts) = self.model.sort_chunks(vp, grid, self.coding, range)?;
        let indices: Vec<usize> = tiles.iter().map(|t| t.index).collect();
        let owner = owner_of(&indices);
        // Each sorter keeps its share of every worker's cache.
        let bound = self.worker_cache / ctx.sorters as u64;
        self.mirrors.resize_with(ctx.workers, ChunkCache::default);
        for m in &mut self.mirrors {
            m.set_limit(bound);
        }
        let mut jobs = empty_jobs(ctx, sorter, bound);
        let mut stats = ChunkStats {
            culled: counts.culled,
            verbatim: counts.verbatim,
            straddling: counts.straddling,
            straddling_triangles: counts.straddling_triangles,
            built: counts.built,
            cache_mb: self.model.cached_bytes() as f64 / (1 << 20) as f64,
            ..Default::default()
        };
        let file = &self.model.file;
        let mut tile_stats = Vec::with_capacity(tiles.len());
        for (tile, &w) in tiles.into_iter().zip(&owner) {
            let mirror = &mut self.mirrors[w - 1];
            let triangles = tile.triangles() as u32;
            let mut streams = Vec::with_capacity(tile.pieces.len());
            for piece in tile.pieces {
                streams.push(match piece.kind {
                    PieceKind::Sorted { bytes, normals, .. } => {
                        TileStream { source: StreamSource::Bytes(bytes), normals }
                    }
                    PieceKind::Verbatim => {
                        let chunk = piece.chunk;
                        if mirror.get(chunk).is_some() {
                            stats.kept += 1;
                            TileStream { source: StreamSource::Kept { chunk }, normals: vec![] }
                        } else {
                            stats.sent += 1;
                            let normals = file.border(chunk as usize)?.slot_normals();
                            let bft = file.chunk_bft(chunk as usize)?.into_owned();
                            mirror.insert(chunk, worker::node::kept_cost(&bft, &normals), ());
                            TileStream { source: StreamSource::Keep { chunk, bft }, normals }
                        }
                    }
                });
            }
            tile_stats.push(TileStats {
                index: tile.index as u32,
                worker: w,
                triangles,
                bytes: streams.iter().map(TileStream::bft_len).sum(),
                tri_bytes: triangles as usize * codec::tri_sort::TRIANGLE_BYTES,
                normal_bytes: streams.iter().map(|s| s.normals.len() * 16).sum(),
            });
            jobs[w - 1].tiles.push(TileJob { index: tile.index as u32, rect: grid.tile_rect(tile.index), streams });
        }
        Ok(Share { jobs, tiles: tile_stats, chunks: stats })
    }
}

impl PmScene {
    /// One frame of a progressive mesh: every tile the model can reach goes to a worker with
    /// the camera; nothing of the mesh is sent. The tiles' triangle counts come back with the
    /// pixels.
    fn jobs(&self, ctx: &FrameContext) -> FrameJobs {
        let (grid, args, (lo, hi)) = (ctx.grid, ctx.args, self.bbox);
        let view = codec::pm::Viewpoint::new(&ctx.camera, grid.width, grid.height, args.error_px);
        let diagonal = glam::Vec3::from(hi).distance(glam::Vec3::from(lo));
        // Only tiles the model's bounding box can reach: every vertex a progressive mesh can
        // activate lies in it, so the other tiles stay transparent and cost the workers nothing.
        let reach = codec::view::box_screen_rect(lo, hi, view.view_proj, grid.width, grid.height);
        let indices: Vec<usize> = (0..grid.tiles())
            .filter(|&i| {
                let [x0, y0, x1, y1] = grid.tile_rect(i);
                reach.is_some_and(|[rx0, ry0, rx1, ry1]| x0 < rx1 && rx0 < x1 && y0 < ry1 && ry0 < y1)
            })
            .collect();
        // Each worker adapts one mesh to its tiles' bounding rectangle: contiguous runs of
        // tiles keep it to the worker's share of the frame (with --balance, the balancer's
        // assignment, whose rectangles may be larger).
        let owner =
            if args.balance { ctx.owners(&indices) } else { super::schedule::contiguous(indices.len(), ctx.workers) };
        let mut jobs: Vec<PmFrameJob> = (0..ctx.workers)
            .map(|_| PmFrameJob {
                frame: ctx.frame,
                width: grid.width,
                height: grid.height,
                view_proj: view.view_proj.to_cols_array(),
                eye: view.eye.to_array(),
                pixels_per_unit: view.pixels_per_unit,
                error_px: view.error_px,
                c_lod: args.c_lod,
                attribute_scale: args.normal_weight * diagonal,
                max_passes: args.max_passes,
                occlusion: args.occlusion,
                tiles: vec![],
            })
            .collect();
        let mut tile_stats = Vec::with_capacity(indices.len());
        for (&i, &w) in indices.iter().zip(&owner) {
            jobs[w - 1].tiles.push((i as u32, grid.tile_rect(i)));
            tile_stats.push(TileStats {
                index: i as u32,
                worker: w,
                triangles: 0,
                bytes: 0,
                tri_bytes: 0,
                normal_bytes: 0,
            });
        }
        // Workers without tiles this frame get no message and are not waited for.
        let messages = jobs
            .into_iter()
            .enumerate()
            .filter(|(_, j)| !j.tiles.is_empty())
            .map(|(i, j)| (i + 1, ToWorker::PmFrame(j).encode()))
            .collect();
        FrameJobs { messages, tiles: tile_stats, chunks: None, nsp: None }
    }
}

impl NspScene {
    /// One frame of an `.nsp` model: the view's cells and precisions from the cell table
    /// alone; each worker draws the selected cells whose triangles can reach its tiles, and
    /// gets the streams of those cells and their ancestors that it does not hold yet. Rank 0
    /// reads those streams from the file and never decodes them.
    fn jobs(&mut self, ctx: &FrameContext) -> Result<FrameJobs> {
        use codec::nsp::view;
        let (grid, file) = (ctx.grid, &self.file);
        let vp = ctx.camera.view_proj(grid.aspect());
        let v = view::View { camera: ctx.camera, width: grid.width, height: grid.height, error_px: ctx.args.error_px };
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
