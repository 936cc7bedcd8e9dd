//! A worker rank: start the renderer, report ready, then for every frame decode each tile
//! it was sent, render the tile's part of the frame, and send the pixels back to rank 0.
//! Any failure is reported to rank 0 with its reason before the worker exits.
//!
//! With a progressive mesh (a `Model` message, then `PmFrame`s) the worker uploads the mesh
//! once and keeps one GPU adaptation per tile it has rendered: every frame it adapts each of
//! its tiles to the tile's sub-frustum ([`codec::pm::Viewpoint::for_tile`]), starting from the
//! tile's mesh of the frame before, and renders it from the GPU buffers.
//!
//! Everything that stops a worker is a [`WorkerError`]; its display is the reason rank 0
//! receives and prints as `rank R failed: <reason>`.

use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use codec::bft::BftError;
use codec::pm::{DpmError, Viewpoint};
use glam::{Mat4, Vec3};
use rayon::prelude::*;
use thiserror::Error;

use crate::chunk_cache::ChunkCache;
use crate::gpu::{Gpu, GpuError};
use crate::pm_adapt::occlusion::Occluder;
use crate::pm_adapt::{AdaptError, GpuAdapter, OutOfCore, DEFAULT_N_ALLOC};
use crate::render::{RenderError, Renderer};
use crate::transport::{RecvError, Transport};
use crate::RenderMesh;
use protocol::{
    unix_ms, DpmFile, Failed, FrameJob, FrameSpan, NspFrameJob, NspModel, Pixels, PmFrameJob, PmMemory, PmModel,
    ProtocolError, Ready, StreamSource, TilePixels, TileTimes, ToMaster, ToWorker,
};

/// How long a worker waits for the master's next message. The master loads and sorts
/// between frames; when it dies, `mpirun` (or the closed channel) ends the worker sooner.
const MASTER_SILENCE: Duration = Duration::from_secs(3600);

/// How often a worker tells rank 0 that it is alive while it starts or renders a frame, so
/// that rank 0's `--timeout` measures silence, not the length of a frame.
pub const HEARTBEAT: Duration = Duration::from_millis(250);

/// Why a worker stopped: the reason it sends rank 0 in [`ToMaster::Failed`].
#[derive(Debug, Error)]
pub enum WorkerError {
    /// The GPU could not be opened.
    #[error(transparent)]
    Gpu(#[from] GpuError),
    /// Transport: a message from a rank other than 0.
    #[error("unexpected message from rank {0}")]
    UnexpectedSender(usize),
    /// Transport: nothing from rank 0 for `MASTER_SILENCE`.
    #[error("no message from rank 0 for an hour")]
    MasterSilent,
    /// Transport: rank 0's end is closed (reported to no one: there is no one to tell).
    #[error("rank 0 is gone")]
    MasterGone,
    /// Protocol: bytes from rank 0 that are no message.
    #[error("bad message from rank 0: {0}")]
    BadMessage(ProtocolError),
    /// Protocol: a `PmFrame` before any `Model`.
    #[error("a progressive-mesh frame arrived before its model")]
    FrameBeforeModel,
    /// Decode: the `Model` message's `.dpm` bytes, or the head of a `DpmFile`'s file.
    #[error("cannot decode the progressive mesh: {0}")]
    Model(DpmError),
    /// The `DpmFile` message's file could not be opened or read.
    #[error("{path}: {error}")]
    ModelFile { path: String, error: DpmError },
    /// GPU: the progressive mesh could not be uploaded.
    #[error(transparent)]
    Upload(AdaptError),
    /// The `.nsp` model or one of its cells.
    #[error("the .nsp model: {0}")]
    Nsp(codec::nsp::NspError),
    /// Protocol: an `NspFrame` before any `NspModel`, or naming a cell it does not select.
    #[error("an .nsp frame {0}")]
    NspFrame(&'static str),
    /// The `fail` hook of `TESSERA_FAULT`.
    #[error("injected failure (TESSERA_FAULT)")]
    Injected,
    /// One tile of a frame.
    #[error("tile {index}: {error}")]
    Tile { index: u32, error: TileError },
}

/// Why a tile could not be rendered.
#[derive(Debug, Error)]
pub enum TileError {
    #[error("cannot decode the submesh: {0}")]
    Decode(BftError),
    #[error("border normal for vertex {slot}, but the stream has {vertices}")]
    BorderNormal { slot: u32, vertices: usize },
    #[error("cannot decode chunk {0} of the model: {1}")]
    ChunkDecode(u32, BftError),
    #[error("the master named chunk {0}, which this worker does not hold")]
    MissingChunk(u32),
    #[error("rect {0:?} is not a non-empty part of the frame")]
    BadRect([u32; 4]),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Adapt(#[from] AdaptError),
}

impl TileError {
    fn at(self, index: u32) -> WorkerError {
        WorkerError::Tile { index, error: self }
    }
}

/// What [`run`] returns when a worker stops on an error: its rank and the reason, displayed
/// `rank R: <reason>`.
#[derive(Debug, Error)]
#[error("rank {rank}: {reason}")]
pub struct RankError {
    pub rank: usize,
    pub reason: WorkerError,
}

/// Test hooks for fault handling, unset in normal runs. `TESSERA_FAULT=KIND:R[:MS]` makes rank
/// R, on its first frame: `die`, abort; `fail`, report a failure; `slow:R:MS`, work MS
/// milliseconds longer (heartbeats go on); `hang`, stop its heartbeat and never answer;
/// `texture:R:N`, report N as its largest texture side in the handshake.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Fault {
    Die,
    Fail,
    Slow(Duration),
    Hang,
    /// Report this largest texture side in the handshake instead of the adapter's.
    Texture(u32),
}

fn fault(rank: usize) -> Option<Fault> {
    let v = std::env::var("TESSERA_FAULT").ok()?;
    let mut parts = v.split(':');
    let kind = parts.next()?;
    if parts.next()?.parse::<usize>().ok()? != rank {
        return None;
    }
    Some(match kind {
        "die" => Fault::Die,
        "slow" => Fault::Slow(Duration::from_millis(parts.next().and_then(|m| m.parse().ok()).unwrap_or(1000))),
        "hang" => Fault::Hang,
        "texture" => Fault::Texture(parts.next()?.parse().ok()?),
        _ => Fault::Fail,
    })
}

/// A thread that sends [`ToMaster::Heartbeat`] every [`HEARTBEAT`] while the worker is busy.
struct Heartbeat {
    busy: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Heartbeat {
    fn start(send: crate::transport::SendFn) -> Heartbeat {
        let busy = Arc::new(AtomicBool::new(true));
        let stop = Arc::new(AtomicBool::new(false));
        let (b, s) = (busy.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("heartbeat".into())
            .spawn(move || {
                let beat = ToMaster::Heartbeat.encode();
                while !s.load(Ordering::Relaxed) {
                    std::thread::park_timeout(HEARTBEAT);
                    if b.load(Ordering::Relaxed) && !s.load(Ordering::Relaxed) {
                        send(&beat);
                    }
                }
            })
            .ok();
        Heartbeat { busy, stop, thread }
    }

    fn busy(&self, busy: bool) {
        self.busy.store(busy, Ordering::Relaxed);
    }
}

impl Drop for Heartbeat {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

/// Runs the worker until the master says to stop. `Err` carries the reason, which has
/// already been sent to rank 0 when the transport allowed it.
pub fn run(t: &dyn Transport) -> Result<(), RankError> {
    run_routed(t, None)
}

/// Direct send (`render --display-ranks D`): the display ranks that take the pixels of a
/// tile, by its rectangle in the frame.
pub type Route = dyn Fn([u32; 4]) -> Vec<usize> + Send + Sync;

/// [`run`], sending each tile's pixels to the display ranks `route` names and to rank 0
/// only the tiles' times (their pixels stripped), when `route` is given.
pub fn run_routed(t: &dyn Transport, route: Option<&Route>) -> Result<(), RankError> {
    let rank = t.rank();
    let heartbeat = Heartbeat::start(t.sender(0));
    let fail = |reason: WorkerError| {
        heartbeat.busy(false);
        t.send(0, &ToMaster::Failed(Failed { reason: reason.to_string() }).encode());
        Err(RankError { rank, reason })
    };
    let gpu = match Gpu::new() {
        Ok(g) => g,
        Err(e) => return fail(e.into()),
    };
    let mut renderer = Renderer::new(&gpu);
    let max_texture_side = match fault(rank) {
        Some(Fault::Texture(n)) => n,
        _ => gpu.limits().max_texture_dimension_2d,
    };
    heartbeat.busy(false);
    t.send(0, &ToMaster::Ready(Ready { adapter: gpu.adapter_name().to_string(), max_texture_side }).encode());
    let mut pm: Option<PmTiles> = None;
    let mut nsp: Option<NspView> = None;
    // One chunk cache per sorter (`render --sorters K`), each mirrored by its sorter.
    let mut chunks: Vec<ChunkCache<KeptChunk>> = Vec::new();
    // The shares of the frame received so far, by sorter.
    let mut shares: Vec<Option<FrameJob>> = Vec::new();
    let mut first_frame = true;
    loop {
        heartbeat.busy(false);
        let (from, bytes) = match t.recv(MASTER_SILENCE) {
            Ok(m) => m,
            Err(RecvError::Timeout) => return fail(WorkerError::MasterSilent),
            Err(RecvError::Disconnected) => return Err(RankError { rank, reason: WorkerError::MasterGone }),
        };
        heartbeat.busy(true);
        let start_ms = unix_ms();
        let msg = ToWorker::decode(&bytes);
        // Sorter ranks (`render --sorters K`) send frame shares; everything else comes from
        // rank 0.
        if from != 0 && !matches!(msg, Ok(ToWorker::Frame(_))) {
            return fail(WorkerError::UnexpectedSender(from));
        }
        let msg = match msg {
            Ok(ToWorker::Shutdown) => return Ok(()),
            Ok(ToWorker::Model(PmModel { dpm, gpu_budget })) => {
                match PmTiles::new(&gpu, &dpm, gpu_budget) {
                    Ok(p) => pm = Some(p),
                    Err(e) => return fail(e),
                }
                continue;
            }
            Ok(ToWorker::DpmFile(DpmFile { path, gpu_budget, pool_bytes })) => {
                match PmTiles::open(&gpu, Path::new(&path), gpu_budget, pool_bytes) {
                    Ok(p) => pm = Some(p),
                    Err(e) => return fail(e),
                }
                continue;
            }
            Ok(ToWorker::NspModel(NspModel { skeleton })) => {
                match codec::nsp::NspFile::from_skeleton(skeleton) {
                    Ok(file) => nsp = Some(NspView { file, nav: Default::default() }),
                    Err(e) => return fail(WorkerError::Nsp(e)),
                }
                continue;
            }
            Ok(msg) => msg,
            Err(e) => return fail(WorkerError::BadMessage(e)),
        };
        match fault(rank).filter(|_| std::mem::take(&mut first_frame)) {
            Some(Fault::Die) => std::process::abort(),
            Some(Fault::Fail) => return fail(WorkerError::Injected),
            Some(Fault::Slow(d)) => std::thread::sleep(d),
            Some(Fault::Texture(_)) => {}
            Some(Fault::Hang) => {
                heartbeat.busy(false);
                loop {
                    std::thread::park();
                }
            }
            None => {}
        }
        let job = match msg {
            ToWorker::Frame(job) => job,
            ToWorker::NspFrame(job) => {
                let Some(view) = nsp.as_mut() else {
                    return fail(WorkerError::NspFrame("arrived before its model"));
                };
                match view.render(&mut renderer, job) {
                    Ok((frame, tiles)) => {
                        let span = phased_span(start_ms, &tiles);
                        answer(t, route, frame, tiles, span, PmMemory::default())
                    }
                    Err(e) => return fail(e),
                }
                continue;
            }
            ToWorker::PmFrame(job) => {
                let Some(pm) = pm.as_mut() else {
                    return fail(WorkerError::FrameBeforeModel);
                };
                match pm.render(&mut renderer, &job) {
                    Ok((tiles, memory)) => {
                        let span = phased_span(start_ms, &tiles);
                        answer(t, route, job.frame, tiles, span, memory)
                    }
                    Err(e) => return fail(e),
                }
                continue;
            }
            _ => unreachable!("handled above"),
        };
        // A frame comes in `sorters` shares (one unless `render --sorters K`); it renders
        // once every share is here.
        let n = job.sorters as usize;
        if shares.len() != n {
            shares = (0..n).map(|_| None).collect();
        }
        if let Some(other) = shares.iter().flatten().find(|s| s.frame != job.frame) {
            let why = format!("shares of frames {} and {} at once", other.frame, job.frame);
            return fail(WorkerError::BadMessage(ProtocolError::Unexpected(why)));
        }
        let sorter = job.sorter as usize;
        if shares[sorter].replace(job).is_some() {
            return fail(WorkerError::BadMessage(ProtocolError::Unexpected(format!("sorter {sorter}'s share twice"))));
        }
        if shares.iter().any(Option::is_none) {
            continue;
        }
        let jobs: Vec<FrameJob> = shares.iter_mut().map(|s| s.take().expect("every share")).collect();
        chunks.resize_with(n, ChunkCache::default);
        // The streams decode in parallel (they are independent), then the tiles render one
        // after the other on the one device; the first tile in order that fails is the one
        // reported.
        let meshes = match tile_meshes(&jobs, &mut chunks) {
            Ok(m) => m,
            Err((index, e)) => return fail(e.at(index)),
        };
        let prepared_ms = unix_ms();
        let mut tiles = Vec::with_capacity(meshes.len());
        for mesh in meshes {
            match render_tile(&mut renderer, &jobs[0], &mesh) {
                Ok(p) => tiles.push(p),
                Err(e) => return fail(e.at(mesh.index)),
            }
        }
        let span = FrameSpan { start_ms, prepared_ms, end_ms: unix_ms() };
        answer(t, route, jobs[0].frame, tiles, span, PmMemory::default());
    }
}

/// Sends a frame's pixels to rank 0, or with a `route` to the display ranks (each the tiles
/// that reach its displays) and rank 0 the tiles with their pixels stripped (an empty
/// rectangle at the tile's corner), all at once.
fn answer(t: &dyn Transport, route: Option<&Route>, frame: u32, tiles: Vec<TilePixels>, span: FrameSpan, pm: PmMemory) {
    let Some(route) = route else {
        t.send(0, &ToMaster::Pixels(Pixels { frame, tiles, span, pm }).encode());
        return;
    };
    let mut to: std::collections::BTreeMap<usize, Vec<TilePixels>> = Default::default();
    for tile in &tiles {
        for r in route(tile.rect) {
            to.entry(r).or_default().push(tile.clone());
        }
    }
    let mut msgs: Vec<(usize, Vec<u8>)> =
        to.into_iter().map(|(r, tiles)| (r, ToMaster::Pixels(Pixels { frame, tiles, span, pm }).encode())).collect();
    let stripped = tiles
        .into_iter()
        .map(|p| TilePixels { rect: [p.rect[0], p.rect[1], p.rect[0], p.rect[1]], rgba: Vec::new(), ..p })
        .collect();
    msgs.push((0, ToMaster::Pixels(Pixels { frame, tiles: stripped, span, pm }).encode()));
    // Rank 0 and the display ranks wait for these; a rank that died ends the job from there.
    let _ = t.send_many(msgs, crate::transport::NO_TIMEOUT);
}

/// The span of a frame whose first phase (an adaptation or an `.nsp` refinement, done once
/// for all tiles) is timed in the tiles' shares of it.
fn phased_span(start_ms: f64, tiles: &[TilePixels]) -> FrameSpan {
    let first: f64 = tiles.iter().map(|t| t.times.decode_ms + t.times.adapt_ms).sum();
    let end_ms = unix_ms();
    FrameSpan { start_ms, prepared_ms: (start_ms + first).min(end_ms), end_ms }
}

/// A verbatim chunk a worker keeps: its stream and its border normals, compressed as it
/// came, so that a worker holds many more chunks than it could decoded (about 1.5 bytes a
/// triangle against 36); it decodes them every frame, as it does every tile's stream.
pub type KeptChunk = Arc<(Vec<u8>, Vec<(u32, [f32; 3])>)>;

/// The cost of a kept chunk in a [`ChunkCache`]: its stream's bytes and 16 per normal, as
/// the master counts it from the message it sends.
pub fn kept_cost(bft: &[u8], normals: &[(u32, [f32; 3])]) -> u64 {
    bft.len() as u64 + 16 * normals.len() as u64
}

/// Every tile's mesh for a frame, with the milliseconds its streams took to decode, from the
/// frame's shares in sorter order (a tile's streams from several sorters follow each other in
/// that order, which is the chunks' order). First, in message order (the order each sorter's
/// mirror of its cache in `chunks` follows), chunks to keep go into the cache and chunks kept
/// before come out of it; then every stream decodes in parallel, and each tile's streams are
/// joined in order.
fn tile_meshes(jobs: &[FrameJob], chunks: &mut [ChunkCache<KeptChunk>]) -> Result<Vec<TileMesh>, (u32, TileError)> {
    let mut tiles: Vec<(u32, [u32; 4])> = Vec::new();
    let mut slot_of: HashMap<u32, usize> = HashMap::new();
    // (tile slot, chunk, stream), tile by tile in the order of first appearance.
    // A stream is read from the message where it came in it, else from the cache.
    enum Source<'a> {
        Sent(&'a [u8], &'a [(u32, [f32; 3])]),
        Kept(KeptChunk),
    }
    let mut streams: Vec<(usize, Option<u32>, Source)> = Vec::new();
    for (job, cache) in jobs.iter().zip(chunks.iter_mut()) {
        cache.set_limit(job.chunk_cache);
        for tile in &job.tiles {
            let slot = *slot_of.entry(tile.index).or_insert_with(|| {
                tiles.push((tile.index, tile.rect));
                tiles.len() - 1
            });
            for s in &tile.streams {
                let (chunk, source) = match &s.source {
                    StreamSource::Bytes(b) => (None, Source::Sent(b, &s.normals)),
                    StreamSource::Keep { chunk, bft } => {
                        let kept = Arc::new((bft.clone(), s.normals.clone()));
                        cache.insert(*chunk, kept_cost(bft, &s.normals), kept);
                        (Some(*chunk), Source::Sent(bft, &s.normals))
                    }
                    StreamSource::Kept { chunk } => match cache.get(*chunk) {
                        Some(k) => (Some(*chunk), Source::Kept(k.clone())),
                        None => return Err((tile.index, TileError::MissingChunk(*chunk))),
                    },
                };
                streams.push((slot, chunk, source));
            }
        }
    }
    let decode_only = jobs[0].decode_only;
    // With --decode-only a stream's mesh is dropped as soon as it is counted: nothing is
    // drawn, and a whole large model's meshes need not be held at once.
    type Decoded = Result<(RenderMesh, usize, f64), (u32, TileError)>;
    let decoded: Vec<Decoded> = streams
        .par_iter()
        .map(|(slot, chunk, source)| {
            let index = tiles[*slot].0;
            let (bft, normals) = match source {
                Source::Sent(b, n) => (*b, *n),
                Source::Kept(k) => (&k.0[..], &k.1[..]),
            };
            let (mesh, ms) = decode_stream(bft, normals).map_err(|e| match (e, chunk) {
                (TileError::Decode(e), Some(c)) => (index, TileError::ChunkDecode(*c, e)),
                (e, _) => (index, e),
            })?;
            let triangles = mesh.triangle_count();
            Ok((if decode_only { RenderMesh::default() } else { mesh }, triangles, ms))
        })
        .collect();
    let mut parts: Vec<Vec<RenderMesh>> = (0..tiles.len()).map(|_| Vec::new()).collect();
    let mut out: Vec<TileMesh> = tiles
        .iter()
        .map(|&(index, rect)| TileMesh { index, rect, mesh: RenderMesh::default(), triangles: 0, decode_ms: 0.0 })
        .collect();
    for ((slot, _, _), d) in streams.iter().zip(decoded) {
        let (mesh, n, ms) = d?;
        out[*slot].decode_ms += ms;
        out[*slot].triangles += n as u32;
        parts[*slot].push(mesh);
    }
    for (t, mut p) in out.iter_mut().zip(parts) {
        t.mesh = if p.len() == 1 { p.pop().expect("one part") } else { RenderMesh::concat(&p) };
    }
    Ok(out)
}

/// A tile's streams decoded and joined (empty with `--decode-only`), its triangles, and the
/// milliseconds its streams took to decode.
struct TileMesh {
    index: u32,
    rect: [u32; 4],
    mesh: RenderMesh,
    triangles: u32,
    decode_ms: f64,
}

/// Decodes one stream and applies the border normals the master sent; returns the mesh and
/// the milliseconds it took.
fn decode_stream(bft: &[u8], normals: &[(u32, [f32; 3])]) -> Result<(RenderMesh, f64), TileError> {
    let start = Instant::now();
    let decoded = codec::bft::decode(bft).map_err(TileError::Decode)?;
    let mut mesh = RenderMesh::from_decoded(&decoded);
    // A stream with the file's normals shades with them; border normals are for computed ones.
    let file_normals = RenderMesh::has_file_normals(&decoded);
    for &(slot, n) in normals {
        let Some(dst) = mesh.normals.get_mut(slot as usize) else {
            return Err(TileError::BorderNormal { slot, vertices: mesh.positions.len() });
        };
        if !file_normals {
            *dst = n;
        }
    }
    Ok((mesh, start.elapsed().as_secs_f64() * 1e3))
}

/// Renders one decoded tile of `job`; with `job.decode_only`, answers transparent pixels.
fn render_tile(renderer: &mut Renderer, job: &FrameJob, tile_mesh: &TileMesh) -> Result<TilePixels, TileError> {
    let TileMesh { index, rect, mesh, triangles, decode_ms } = tile_mesh;
    let (index, rect, decode_ms) = (*index, *rect, *decode_ms);
    let (rgba, times) = if job.decode_only {
        let [x0, y0, x1, y1] = rect.map(|v| v as usize);
        (vec![0; (x1.saturating_sub(x0)) * (y1.saturating_sub(y0)) * 4], Default::default())
    } else {
        renderer.render(mesh, Mat4::from_cols_array(&job.view_proj), (job.width, job.height), rect)?
    };
    Ok(TilePixels {
        index,
        rect,
        times: TileTimes {
            decode_ms,
            adapt_ms: 0.0,
            upload_ms: times.upload_ms,
            render_ms: times.render_ms,
            readback_ms: times.readback_ms,
        },
        triangles: *triangles,
        rgba,
    })
}

/// The most draws a worker makes of its adapted mesh per frame: up to this many tiles, each
/// tile is drawn under its own rectangle; beyond it, a worker's tiles are grouped by the 4x4
/// block of the frame they lie in, each group drawn once under its tiles' bounding rectangle
/// and cut into tiles (a 64x64 grid would otherwise cost 4,096 draws).
pub const MAX_DRAWS: usize = 16;

/// An `.nsp` model on a worker: the file's skeleton with the cell streams received so far,
/// and the cells decoded for the last frame (drawn ones and their ancestors).
struct NspView {
    file: codec::nsp::NspFile,
    nav: codec::nsp::view::Navigator,
}

impl NspView {
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
                    },
                    triangles: drawn.len() as u32,
                    rgba: crop(&rgba, group.rect, rect),
                });
            }
        }
        Ok((job.frame, out))
    }
}

/// Tiles drawn together (see [`MAX_DRAWS`]).
struct TileGroup {
    /// The group's key: the tile index for a tile alone, `1 << 31 | block` for a block.
    key: u32,
    /// The bounding rectangle of the group's tiles.
    rect: [u32; 4],
    tiles: Vec<(u32, [u32; 4])>,
}

/// The pixels of `rect` out of an image of the pixels of `outer` (rows top first, RGBA8).
fn crop(pixels: &[u8], outer: [u32; 4], rect: [u32; 4]) -> Vec<u8> {
    let outer_row = (outer[2] - outer[0]) as usize * 4;
    let row = (rect[2] - rect[0]) as usize * 4;
    let x = (rect[0] - outer[0]) as usize * 4;
    (rect[1]..rect[3])
        .flat_map(|y| {
            let at = (y - outer[1]) as usize * outer_row + x;
            &pixels[at..at + row]
        })
        .copied()
        .collect()
}

/// Groups a worker's tiles for drawing: one group per tile up to [`MAX_DRAWS`] tiles, else one
/// per 4x4 block of the frame (by each tile's top-left corner), in the job's order.
fn tile_groups(tiles: &[(u32, [u32; 4])], width: u32, height: u32) -> Vec<TileGroup> {
    if tiles.len() <= MAX_DRAWS {
        return tiles.iter().map(|&(index, rect)| TileGroup { key: index, rect, tiles: vec![(index, rect)] }).collect();
    }
    let mut groups: Vec<TileGroup> = Vec::new();
    for &(index, rect) in tiles {
        let block = (rect[1] as u64 * 4 / height as u64 * 4 + rect[0] as u64 * 4 / width as u64) as u32;
        let key = 1 << 31 | block;
        match groups.iter_mut().find(|g| g.key == key) {
            Some(g) => {
                g.rect =
                    [g.rect[0].min(rect[0]), g.rect[1].min(rect[1]), g.rect[2].max(rect[2]), g.rect[3].max(rect[3])];
                g.tiles.push((index, rect));
            }
            None => groups.push(TileGroup { key, rect, tiles: vec![(index, rect)] }),
        }
    }
    groups
}

/// A progressive mesh on this worker's GPU, adapted once per frame for all of the worker's
/// tiles: to the sub-frustum of their bounding rectangle (refined inside it, coarsened
/// outside with the c_LOD falloff), then drawn once under that rectangle and cut into tiles. The adaptation's cost follows the worker's screen
/// region and the change of view, not its tile count (issue 16: per-tile adaptations cost
/// 2.5x one adaptation of the same screen in 8x8 tiles, each tile converging separately).
/// Rank 0 deals a progressive mesh's tiles to workers in contiguous runs, so a worker's
/// rectangle is its share of the frame. It also keeps the mesh coherent from frame to frame:
/// one adaptation state, whatever tiles come.
///
/// An out-of-core file ([`PmTiles::open`]) is read by each worker from its path, node by node
/// on a loader thread, the nodes kept within the GPU budget by the paper's priority for the
/// worker's region of the frame. A frame schedules the nodes its view wants, adapts, and when
/// the mesh has converged while nodes are still on their way, waits for them and goes on (an
/// offline frame is drawn from the nodes its view needs; the paper's interactive renderer
/// would draw at once and refine over the next frames).
struct PmTiles {
    adapter: GpuAdapter,
    /// Node bytes uploaded up to the end of the last frame (out of core).
    uploaded: u64,
}

impl PmTiles {
    /// An in-core `.dpm`, its adaptation within `gpu_budget` bytes of graphics memory.
    fn new(gpu: &Gpu, dpm: &[u8], gpu_budget: u64) -> Result<PmTiles, WorkerError> {
        let dpm = codec::pm::format::Dpm::parse(dpm).map_err(WorkerError::Model)?;
        let mut adapter = GpuAdapter::new(gpu, &dpm, DEFAULT_N_ALLOC).map_err(WorkerError::Upload)?;
        adapter.set_budget(Some(gpu_budget)).map_err(WorkerError::Upload)?;
        Ok(PmTiles { adapter, uploaded: 0 })
    }

    /// An out-of-core `.dpm` at `path`, its adaptation within `gpu_budget` bytes of graphics
    /// memory, `pool_bytes` of them for nodes.
    fn open(gpu: &Gpu, path: &Path, gpu_budget: u64, pool_bytes: u64) -> Result<PmTiles, WorkerError> {
        let named = |error| WorkerError::ModelFile { path: path.display().to_string(), error };
        let file = Arc::new(codec::pm::format::NodeFile::open(path).map_err(named)?);
        let dpm = codec::pm::format::Dpm::parse_prefix(file.prefix()).map_err(named)?;
        let ooc = OutOfCore { file: file.clone(), pool_bytes, background: true };
        let mut adapter = GpuAdapter::out_of_core(gpu, &dpm, ooc, DEFAULT_N_ALLOC).map_err(WorkerError::Upload)?;
        adapter.set_budget(Some(gpu_budget)).map_err(WorkerError::Upload)?;
        Ok(PmTiles { adapter, uploaded: 0 })
    }

    /// Adapts the mesh to the sub-frustum of `job`'s tiles' bounding rectangle (until
    /// converged or `max_passes`) and renders every tile from it.
    fn render(
        &mut self,
        renderer: &mut Renderer,
        job: &PmFrameJob,
    ) -> Result<(Vec<TilePixels>, PmMemory), WorkerError> {
        let view_proj = Mat4::from_cols_array(&job.view_proj);
        let view = Viewpoint {
            view_proj,
            eye: Vec3::from(job.eye),
            width: job.width,
            height: job.height,
            error_px: job.error_px,
            pixels_per_unit: job.pixels_per_unit,
            c_lod: job.c_lod,
            attribute_scale: job.attribute_scale,
        };
        let Some(&(first, _)) = job.tiles.first() else {
            return Ok((Vec::new(), PmMemory::default()));
        };
        let mut region = [u32::MAX, u32::MAX, 0, 0];
        for &(index, [x0, y0, x1, y1]) in &job.tiles {
            if !(x0 < x1 && x1 <= job.width && y0 < y1 && y1 <= job.height) {
                return Err(TileError::BadRect([x0, y0, x1, y1]).at(index));
            }
            region = [region[0].min(x0), region[1].min(y0), region[2].max(x1), region[3].max(y1)];
        }
        let region_view = view.for_tile(region);
        let start = Instant::now();
        let at = |e: AdaptError| TileError::from(e).at(first);
        if !job.occlusion {
            self.adapter.set_occluder(None);
        }
        let cache = self.adapter.schedule(&region_view).map_err(at)?;
        for _ in 0..job.max_passes.max(1) {
            if self.adapter.adapt(&region_view).map_err(at)?.converged() {
                if self.adapter.nodes_in_flight() == 0 {
                    break;
                }
                self.adapter.wait_for_nodes().map_err(at)?;
            }
        }
        // A pass checks the operations the one before decoded; the last one is checked here.
        self.adapter.check().map_err(|e| TileError::from(e).at(first))?;
        // The one adaptation, shared out among the tiles for the load balancer.
        let adapt_ms = start.elapsed().as_secs_f64() * 1e3 / job.tiles.len() as f64;
        let triangles = self.adapter.counts().1;
        // The region is drawn once and the tiles are cut out of it (a tile is an exact crop
        // of the frame however large the scissor, `worker::render`): every draw processes the
        // whole adapted mesh, so one draw costs what one tile's would (measured on the dragon
        // in 8x8 tiles: 105-192 ms a frame against 390-811 ms in 4x4-block groups). A region
        // larger than a texture falls back to groups.
        let groups = if region[2] - region[0] <= renderer.max_side() && region[3] - region[1] <= renderer.max_side() {
            vec![TileGroup { key: 0, rect: region, tiles: job.tiles.clone() }]
        } else {
            tile_groups(&job.tiles, job.width, job.height)
        };
        let uploaded = self.adapter.uploaded_bytes();
        let memory = PmMemory {
            gpu_bytes: self.adapter.gpu_bytes(),
            loaded_bytes: uploaded - self.uploaded,
            resident_nodes: self.adapter.nodes_resident() as u32,
            required_nodes: cache.map_or(0, |c| c.required as u32),
            slots: self.adapter.node_slots().unwrap_or(0),
            error_scale: self.adapter.error_scale(),
        };
        self.uploaded = uploaded;
        let mut out = Vec::with_capacity(job.tiles.len());
        for group in &groups {
            let first = group.tiles[0].0;
            let (group_rgba, group_times) = renderer
                .render_pm(self.adapter.mesh(), view_proj, (job.width, job.height), group.rect)
                .map_err(|e| TileError::from(e).at(first))?;
            let share = 1.0 / group.tiles.len() as f64;
            for &(index, rect) in &group.tiles {
                out.push(TilePixels {
                    index,
                    rect,
                    times: TileTimes {
                        decode_ms: 0.0,
                        adapt_ms,
                        upload_ms: group_times.upload_ms * share,
                        render_ms: group_times.render_ms * share,
                        readback_ms: group_times.readback_ms * share,
                    },
                    triangles,
                    rgba: crop(&group_rgba, group.rect, rect),
                });
            }
        }
        // Occlusion culling one frame late: the region's depth, drawn whole above, hides
        // what the next frame need not refine.
        if job.occlusion && groups.len() == 1 {
            let depth = renderer.read_depth(region).map_err(|e| TileError::from(e).at(first))?;
            self.adapter.set_occluder(Some(Occluder::new(view_proj, (job.width, job.height), region, &depth)));
        }
        Ok((out, memory))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reasons rank 0 prints (`rank R failed: <reason>`), which scripts and
    /// `tests/cluster_faults.rs` match, word for word.
    #[test]
    fn failure_reasons_keep_their_wording() {
        let cases = [
            (WorkerError::UnexpectedSender(3), "unexpected message from rank 3"),
            (WorkerError::MasterSilent, "no message from rank 0 for an hour"),
            (WorkerError::MasterGone, "rank 0 is gone"),
            (
                WorkerError::BadMessage(ProtocolError::Truncated("header")),
                "bad message from rank 0: message is truncated (while reading header)",
            ),
            (WorkerError::FrameBeforeModel, "a progressive-mesh frame arrived before its model"),
            (WorkerError::Injected, "injected failure (TESSERA_FAULT)"),
            (TileError::BadRect([4, 0, 2, 9]).at(7), "tile 7: rect [4, 0, 2, 9] is not a non-empty part of the frame"),
            (
                TileError::BorderNormal { slot: 12, vertices: 10 }.at(2),
                "tile 2: border normal for vertex 12, but the stream has 10",
            ),
            (
                TileError::Render(RenderError::NormalCount { positions: 3, normals: 0 }).at(0),
                "tile 0: mesh has 3 positions but 0 normals",
            ),
            (
                TileError::Adapt(AdaptError::FaceIndex { index: 9, vertices: 4 }).at(5),
                "tile 5: GPU error: face index 9 out of 4 vertices",
            ),
            (
                TileError::Adapt(AdaptError::corrupt(10, 3 * 65536 + 17, true)).at(1),
                "tile 1: corrupt .dpm data: node 3: operation at byte 17: bad operation pointer",
            ),
            (
                TileError::Adapt(AdaptError::TooLarge { elements: 9, what: "vertices", bytes: 1152, limit: 1024 }).at(0),
                "tile 0: the adapted mesh needs 9 vertices, 1152 bytes in one buffer, and this GPU binds at most 1024: \
                 raise --error-px",
            ),
        ];
        for (error, reason) in cases {
            assert_eq!(error.to_string(), reason);
        }
        let stopped = RankError { rank: 2, reason: WorkerError::MasterGone };
        assert_eq!(stopped.to_string(), "rank 2: rank 0 is gone");
    }
}
