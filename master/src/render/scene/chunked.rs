//! A chunked `.bft` model: rank 0 sorts the chunks in view (verbatim chunks pass as they are,
//! straddling ones are cut), alone or sharing the sort with sorter ranks (`render --sorters
//! K`, each a contiguous share of the chunks), and mirrors every worker's chunk cache so that
//! a chunk a worker keeps is named, not sent again.

use anyhow::Result;
use codec::bft::chunked::sort::{share, PieceKind};
use codec::view::{Camera, TileGrid};
use protocol::{FrameJob, SortJob, StreamSource, TileJob, TileStream};
use worker::chunk_cache::ChunkCache;
use worker::node::kept_cost;

use super::contract::{empty_jobs, frame_messages, FrameContext, FrameJobs, Scene, ShareContext};
use crate::camera::CameraSpec;
use crate::model::{chunked_camera, open_chunked, Chunked};
use crate::render::plan::Plan;
use crate::render::stats::{ChunkStats, TileStats};

/// A chunked BFT model, memory-mapped, and rank 0's mirror of every worker's chunk cache
/// (`worker::chunk_cache`), from which it knows which verbatim chunks a worker holds.
pub(in crate::render) struct ChunkedScene {
    model: Chunked,
    coding: codec::bft::Coding,
    /// Indexed by worker rank - 1.
    mirrors: Vec<ChunkCache<()>>,
    /// Each worker's chunk cache bound in bytes.
    worker_cache: u64,
    /// Ranks sharing the sort (`--sorters`), and this frame's worker of every tile of the
    /// grid when there are several (rank 0 decides it and tells the others).
    sorters: usize,
    owners: Vec<usize>,
}

/// One sorter's share of a chunked frame: its jobs for every worker, their tile lines, and
/// what the share did with its chunks.
pub(in crate::render) struct Share {
    pub jobs: Vec<FrameJob>,
    pub tiles: Vec<TileStats>,
    pub chunks: ChunkStats,
}

impl ChunkedScene {
    /// The model at `path` if it is a chunked `.bft`, or `None` for any other kind of file.
    pub(in crate::render) fn open(plan: &Plan, path: &std::path::Path) -> Result<Option<ChunkedScene>> {
        let Some(model) = open_chunked(path, plan.cache_bytes)? else { return Ok(None) };
        Ok(Some(ChunkedScene {
            model,
            coding: plan.coding,
            mirrors: Vec::new(),
            worker_cache: plan.worker_cache_bytes,
            sorters: plan.sorters as usize,
            owners: Vec::new(),
        }))
    }

    /// Sorter `sorter`'s share of a frame: the chunked sort of its chunks, then each worker's
    /// tiles (the worker of each from `owner_of`), whose verbatim chunks go as bytes (with
    /// their border normals) unless the worker kept them, as this rank's mirror of the
    /// worker's cache for this sorter says.
    pub(in crate::render) fn share_jobs(
        &mut self,
        ctx: &ShareContext,
        sorter: usize,
        owner_of: impl FnOnce(&[usize]) -> Vec<usize>,
    ) -> Result<Share> {
        let (grid, vp) = (ctx.grid, ctx.view_proj);
        let range = share(self.model.chunks(), sorter, ctx.sorters);
        // Every sorter takes the cut at the frame's screen error (a live run may change it).
        self.model.error_px = Some(ctx.error_px);
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
            not_in_cut: counts.not_in_cut,
            culled: counts.culled,
            verbatim: counts.verbatim,
            straddling: counts.straddling,
            straddling_triangles: counts.straddling_triangles,
            reused_triangles: counts.reused_triangles,
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
                            mirror.insert(chunk, kept_cost(&bft, &normals), ());
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

impl Scene for ChunkedScene {
    fn camera(&self, args: &CameraSpec, grid: &TileGrid) -> Result<Camera> {
        chunked_camera(&self.model, args, grid)
    }

    /// With several sorters, the messages that set the others to work on this frame (sent
    /// before rank 0 sorts its own share): the view, and the worker of every tile, which rank
    /// 0 decides for all (round robin over the grid's tiles, or `--balance`).
    fn announce(&mut self, ctx: &FrameContext) -> Vec<(usize, Vec<u8>)> {
        if self.sorters == 1 {
            return Vec::new();
        }
        let all: Vec<usize> = (0..ctx.grid.tiles()).collect();
        self.owners = ctx.owners(&all);
        let job = SortJob {
            frame: ctx.frame,
            view_proj: ctx.camera.view_proj(ctx.grid.aspect()).to_cols_array(),
            error_px: ctx.error_px,
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
            error_px: ctx.error_px,
            workers: ctx.workers,
            sorters: self.sorters,
            decode_only: ctx.plan.decode_only,
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
}
