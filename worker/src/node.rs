//! A worker rank: start the renderer, report ready, then for every frame decode each tile
//! it was sent, render the tile's part of the frame, and send the pixels back to rank 0.
//! Any failure is reported to rank 0 with its reason before the worker exits.
//!
//! With a progressive mesh (a `Model` message, then `PmFrame`s) the worker uploads the mesh
//! once and keeps one GPU adaptation per tile it has rendered: every frame it adapts each of
//! its tiles to the tile's sub-frustum ([`codec::pm::View::for_tile`]), starting from the
//! tile's mesh of the frame before, and renders it from the GPU buffers.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use codec::pm::View;
use glam::{Mat4, Vec3};

use crate::pm_gpu::{GpuAdapter, DEFAULT_N_ALLOC};
use crate::protocol::{PmFrameJob, TileJob, TilePixels, TileTimes, ToMaster, ToWorker};
use crate::render::Renderer;
use crate::transport::{RecvError, Transport};
use crate::RenderMesh;

/// How long a worker waits for the master's next message. The master loads and sorts
/// between frames; when it dies, `mpirun` (or the closed channel) ends the worker sooner.
const MASTER_SILENCE: Duration = Duration::from_secs(3600);

/// Test hook for fault handling: `TESSERA_FAULT=die:R` makes rank R abort on its first
/// frame, `TESSERA_FAULT=fail:R` makes it report a failure instead. Unset in normal runs.
fn fault(rank: usize) -> Option<&'static str> {
    let v = std::env::var("TESSERA_FAULT").ok()?;
    let (kind, r) = v.split_once(':')?;
    (r.parse::<usize>().ok()? == rank).then_some(if kind == "die" { "die" } else { "fail" })
}

/// Runs the worker until the master says to stop. `Err` carries the reason, which has
/// already been sent to rank 0 when the transport allowed it.
pub fn run(t: &dyn Transport) -> Result<(), String> {
    let rank = t.rank();
    let fail = |reason: String| {
        t.send(0, &ToMaster::Failed { reason: reason.clone() }.encode());
        Err(format!("rank {rank}: {reason}"))
    };
    let mut renderer = match Renderer::new() {
        Ok(r) => r,
        Err(e) => return fail(e.to_string()),
    };
    t.send(0, &ToMaster::Ready { adapter: renderer.adapter_name().to_string() }.encode());
    let mut pm: Option<PmTiles> = None;
    loop {
        let bytes = match t.recv(MASTER_SILENCE) {
            Ok((0, bytes)) => bytes,
            Ok((from, _)) => return fail(format!("unexpected message from rank {from}")),
            Err(RecvError::Timeout) => return fail("no message from rank 0 for an hour".into()),
            Err(RecvError::Disconnected) => return Err(format!("rank {rank}: rank 0 is gone")),
        };
        let msg = match ToWorker::decode(&bytes) {
            Ok(ToWorker::Shutdown) => return Ok(()),
            Ok(ToWorker::Model(dpm)) => {
                match PmTiles::new(&renderer, &dpm) {
                    Ok(p) => pm = Some(p),
                    Err(e) => return fail(e),
                }
                continue;
            }
            Ok(msg) => msg,
            Err(e) => return fail(format!("bad message from rank 0: {e}")),
        };
        match fault(rank) {
            Some("die") => std::process::abort(),
            Some(_) => return fail("injected failure (TESSERA_FAULT)".into()),
            None => {}
        }
        let job = match msg {
            ToWorker::Frame(job) => job,
            ToWorker::PmFrame(job) => {
                let Some(pm) = pm.as_mut() else {
                    return fail("a progressive-mesh frame arrived before its model".into());
                };
                match pm.render(&mut renderer, &job) {
                    Ok(tiles) => t.send(0, &ToMaster::Pixels { frame: job.frame, tiles }.encode()),
                    Err(e) => return fail(e),
                }
                continue;
            }
            _ => unreachable!("handled above"),
        };
        let view_proj = Mat4::from_cols_array(&job.view_proj);
        let mut tiles = Vec::with_capacity(job.tiles.len());
        for tile in &job.tiles {
            match render_tile(&mut renderer, tile, view_proj, (job.width, job.height)) {
                Ok(p) => tiles.push(p),
                Err(e) => return fail(format!("tile {}: {e}", tile.index)),
            }
        }
        t.send(0, &ToMaster::Pixels { frame: job.frame, tiles }.encode());
    }
}

/// Decodes one tile, applies the border normals the master sent, and renders it.
fn render_tile(
    renderer: &mut Renderer,
    tile: &TileJob,
    view_proj: Mat4,
    frame: (u32, u32),
) -> Result<TilePixels, String> {
    let start = Instant::now();
    let decoded = codec::bft::decode(&tile.bft).map_err(|e| format!("cannot decode the submesh: {e}"))?;
    let mut mesh = RenderMesh::from_decoded(&decoded);
    for &(slot, n) in &tile.normals {
        let Some(dst) = mesh.normals.get_mut(slot as usize) else {
            return Err(format!("border normal for vertex {slot}, but the tile has {}", mesh.positions.len()));
        };
        *dst = n;
    }
    let decode_ms = start.elapsed().as_secs_f64() * 1e3;
    let (rgba, times) = renderer.render(&mesh, view_proj, frame, tile.rect).map_err(|e| e.to_string())?;
    Ok(TilePixels {
        index: tile.index,
        rect: tile.rect,
        times: TileTimes {
            decode_ms,
            adapt_ms: 0.0,
            upload_ms: times.upload_ms,
            render_ms: times.render_ms,
            readback_ms: times.readback_ms,
        },
        triangles: mesh.triangle_count() as u32,
        rgba,
    })
}

/// A progressive mesh on this worker's GPU, with one adaptation per tile.
struct PmTiles {
    /// At the base mesh; each tile's adapter starts as its sibling.
    template: GpuAdapter,
    tiles: HashMap<u32, GpuAdapter>,
}

impl PmTiles {
    fn new(renderer: &Renderer, dpm: &[u8]) -> Result<PmTiles, String> {
        let decoded = codec::pm::format::decode(dpm).map_err(|e| format!("cannot decode the progressive mesh: {e}"))?;
        let template = GpuAdapter::new(renderer, &decoded.pm, DEFAULT_N_ALLOC).map_err(|e| e.to_string())?;
        Ok(PmTiles { template, tiles: HashMap::new() })
    }

    /// Adapts every tile of `job` to its sub-frustum (until converged or `max_passes`) and
    /// renders it.
    fn render(&mut self, renderer: &mut Renderer, job: &PmFrameJob) -> Result<Vec<TilePixels>, String> {
        let view_proj = Mat4::from_cols_array(&job.view_proj);
        let view = View {
            view_proj,
            eye: Vec3::from(job.eye),
            width: job.width,
            height: job.height,
            error_px: job.error_px,
            pixels_per_unit: job.pixels_per_unit,
            c_lod: job.c_lod,
            attribute_scale: job.attribute_scale,
        };
        let mut out = Vec::with_capacity(job.tiles.len());
        for &(index, rect) in &job.tiles {
            let [x0, y0, x1, y1] = rect;
            if !(x0 < x1 && x1 <= job.width && y0 < y1 && y1 <= job.height) {
                return Err(format!("tile {index}: rect {rect:?} is not a non-empty part of the frame"));
            }
            let adapter = self.tiles.entry(index).or_insert_with(|| self.template.sibling());
            let tile_view = view.for_tile(rect);
            let start = Instant::now();
            for _ in 0..job.max_passes.max(1) {
                if adapter.adapt(&tile_view).map_err(|e| format!("tile {index}: {e}"))?.converged() {
                    break;
                }
            }
            let adapt_ms = start.elapsed().as_secs_f64() * 1e3;
            let (rgba, times) = renderer
                .render_pm(adapter, view_proj, (job.width, job.height), rect)
                .map_err(|e| format!("tile {index}: {e}"))?;
            out.push(TilePixels {
                index,
                rect,
                times: TileTimes {
                    decode_ms: 0.0,
                    adapt_ms,
                    upload_ms: times.upload_ms,
                    render_ms: times.render_ms,
                    readback_ms: times.readback_ms,
                },
                triangles: adapter.counts().1,
                rgba,
            });
        }
        Ok(out)
    }
}
