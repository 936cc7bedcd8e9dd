//! A BFT model rank 0 sorts every frame: a single-stream `.bft`, or a mesh file encoded on
//! load.

use std::path::Path;

use anyhow::Result;
use codec::bft::normals::BorderNormals;
use codec::bft::tile_sort::{self, Boxes, Sorter};
use codec::view::{Camera, TileGrid};
use protocol::{StreamSource, TileJob, TileStream};

use super::contract::{frame_messages, FrameContext, FrameJobs, Scene};
use crate::camera::CameraSpec;
use crate::model::{load_model, Model};
use crate::render::stats::TileStats;

/// A BFT model (or a mesh encoded on load), with what its per-frame sort reuses.
pub(super) struct BftScene {
    model: Box<Model>,
    /// The whole mesh's normals, for the tiles' border vertices.
    normals: BorderNormals,
    sorter: Sorter,
    boxes: Box<Boxes>,
}

impl BftScene {
    /// A mesh file or a single-stream `.bft` at `path` (a mesh is encoded on load).
    pub(super) fn open(path: &Path, coding: codec::bft::Coding) -> Result<BftScene> {
        let model = load_model(path, codec::bft::EncodeOptions::default())?;
        let normals = BorderNormals::of(&model.tiles.decoded);
        Ok(BftScene { model: Box::new(model), normals, sorter: Sorter::new(coding), boxes: Box::default() })
    }
}

impl Scene for BftScene {
    fn camera(&self, args: &CameraSpec, grid: &TileGrid) -> Result<Camera> {
        self.model.camera(args, grid)
    }

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
        // No chunks to keep; the bound is that of the meshes each worker keeps from the frame
        // before (a tile whose stream is the same is not decoded again).
        let mut jobs = ctx.frame_jobs(vp, ctx.plan.worker_cache_bytes);
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
