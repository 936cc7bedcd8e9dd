//! An `.nsp` model on a worker: the file's skeleton once, then per frame the cell streams it
//! lacks, refined to the frame's selection and drawn flat.

use std::collections::HashMap;
use std::time::Instant;

use glam::Mat4;
use protocol::{NspFrameJob, PixelCodec, PmMemory, TilePixels, TileTimes, ToWorker};

use super::model::{wrong_kind, Model, Rendered};
use super::tiles::{crop, tile_groups};
use super::{TileError, WorkerError};
use crate::render::Renderer;
use crate::RenderMesh;

impl Model for NspView {
    fn frame(&mut self, renderer: &mut Renderer, msg: ToWorker) -> Result<Option<Rendered>, WorkerError> {
        let ToWorker::NspFrame(job) = msg else { return Err(wrong_kind(&msg)) };
        let (frame, tiles) = self.render(renderer, job)?;
        Ok(Some(Rendered { frame, tiles, memory: PmMemory::default(), prepared_ms: None }))
    }
}

/// An `.nsp` model on a worker: the file's skeleton with the cell streams received so far,
/// and the cells decoded for the last frame (drawn ones and their ancestors).
pub(super) struct NspView {
    file: codec::nsp::NspFile,
    nav: codec::nsp::view::Navigator,
}

impl NspView {
    /// The model of an `NspModel` message: the file's skeleton, no cells yet.
    pub(super) fn new(skeleton: Vec<u8>) -> Result<NspView, WorkerError> {
        let file = codec::nsp::NspFile::from_skeleton(skeleton).map_err(WorkerError::Nsp)?;
        Ok(NspView { file, nav: Default::default() })
    }

    /// Refines the cells this worker draws to the frame's selection, draws them with the
    /// border rule against the whole selection, and renders every tile (flat shaded: a
    /// triangle's pixels depend on it alone, so any subset of the drawing renders the same
    /// pixels as the whole).
    fn render(&mut self, renderer: &mut Renderer, job: NspFrameJob) -> Result<(u32, Vec<TilePixels>), WorkerError> {
        for (c, from, bytes) in job.cells {
            self.file.receive(c, from, bytes).map_err(WorkerError::Nsp)?;
        }
        let bits: HashMap<u32, u8> = job.selection.iter().copied().collect();
        let mut want = Vec::with_capacity(job.draw.len());
        for c in &job.draw {
            want.push((*c, *bits.get(c).ok_or(WorkerError::NspFrame("draws a cell it does not select"))?));
        }
        let start = Instant::now();
        let states = self.nav.update(&self.file, &want).map_err(WorkerError::Nsp)?;
        let drawn = codec::nsp::view::draw_flat(&self.file, &job.selection, &states);
        let mesh = RenderMesh::flat(&drawn);
        let decode_ms = start.elapsed().as_secs_f64() * 1e3;
        let view_proj = Mat4::from_cols_array(&job.view_proj);
        for &(index, [x0, y0, x1, y1]) in &job.tiles {
            if !(x0 < x1 && x1 <= job.width && y0 < y1 && y1 <= job.height) {
                return Err(TileError::BadRect([x0, y0, x1, y1]).at(index));
            }
        }
        let groups = tile_groups(&job.tiles, job.width, job.height);
        let share = 1.0 / job.tiles.len().max(1) as f64;
        let mut out = Vec::with_capacity(job.tiles.len());
        for group in &groups {
            let first = group.tiles[0].0;
            let (rgba, times) = renderer
                .render(&mesh, view_proj, (job.width, job.height), group.rect)
                .map_err(|e| TileError::from(e).at(first))?;
            let part = 1.0 / group.tiles.len() as f64;
            for &(index, rect) in &group.tiles {
                out.push(TilePixels {
                    index,
                    rect,
                    times: TileTimes {
                        decode_ms: decode_ms * share,
                        adapt_ms: 0.0,
                        upload_ms: times.upload_ms * part,
                        render_ms: times.render_ms * part,
                        readback_ms: times.readback_ms * part,
                        encode_ms: 0.0,
                    },
                    triangles: drawn.len() as u32,
                    reused: 0,
                    codec: PixelCodec::Raw,
                    coded_bytes: 0,
                    pixels: crop(&rgba, group.rect, rect),
                });
            }
        }
        Ok((job.frame, out))
    }
}
