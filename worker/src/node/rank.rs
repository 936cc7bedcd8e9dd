//! The worker's loop: start the renderer, report ready, then for every message set up the
//! model it names or render the frame it carries through the model's kind ([`Model`]), and
//! send the pixels back to rank 0 (or, with direct send, to the display ranks). Any failure is
//! reported to rank 0 with its reason before the worker stops. Heartbeats tell rank 0 the
//! worker is alive while it works, and `TESSERA_FAULT` injects the faults the tests need.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use protocol::{unix_ms, Failed, FrameSpan, PixelCodec, Pixels, PmMemory, Ready, TilePixels, ToMaster, ToWorker};

use super::kinds::{self, Loaded};
use super::model::{Model, Rendered};
use super::{RankError, WorkerError};
use crate::gpu::Gpu;
use crate::render::Renderer;
use crate::transport::{RecvError, Transport};

/// How long a worker waits for the master's next message. The master loads and sorts
/// between frames; when it dies, `mpirun` (or the closed channel) ends the worker sooner.
const MASTER_SILENCE: Duration = Duration::from_secs(3600);

/// How often a worker tells rank 0 that it is alive while it starts or renders a frame, so
/// that rank 0's `--timeout` measures silence, not the length of a frame.
pub const HEARTBEAT: Duration = Duration::from_millis(250);

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
    let mut renderer = match Renderer::new(&gpu) {
        Ok(r) => r,
        Err(e) => return fail(e.into()),
    };
    let max_texture_side = match fault(rank) {
        Some(Fault::Texture(n)) => n,
        _ => gpu.limits().max_texture_dimension_2d,
    };
    heartbeat.busy(false);
    t.send(0, &ToMaster::Ready(Ready { adapter: gpu.adapter_name().to_string(), max_texture_side }).encode());
    // The model rank 0 renders: set up by its model message (a `.dpm`'s or an `.nsp`'s), or
    // by the first frame of a `.bft` model, which needs none.
    let mut model: Option<Box<dyn Model>> = None;
    let mut first_frame = true;
    // How the pixels go on the wire, as rank 0 says (raw until it does).
    let mut codec = PixelCodec::Raw;
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
            Ok(ToWorker::KeepAlive) => continue,
            Ok(ToWorker::PixelCodec(c)) => {
                codec = c;
                continue;
            }
            // Another model follows: this one, its GPU buffers and its caches are freed now.
            Ok(ToWorker::Unload) => {
                model = None;
                continue;
            }
            Ok(msg) => msg,
            Err(e) => return fail(WorkerError::BadMessage(e)),
        };
        let frame = match kinds::load(&gpu, msg) {
            Ok(Loaded::Model(m)) => {
                model = Some(m);
                continue;
            }
            Ok(Loaded::Frame(frame)) => frame,
            Err(e) => return fail(e),
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
        let model = match &mut model {
            Some(m) => m,
            None => match kinds::for_first_frame(&frame) {
                Ok(m) => model.insert(m),
                Err(e) => return fail(e),
            },
        };
        match model.frame(&mut renderer, frame) {
            Ok(Some(Rendered { frame, tiles, memory, prepared_ms })) => {
                let span = match prepared_ms {
                    Some(prepared_ms) => FrameSpan { start_ms, prepared_ms, end_ms: unix_ms() },
                    None => phased_span(start_ms, &tiles),
                };
                answer(t, route, frame, coded(codec, tiles), span, memory);
            }
            Ok(None) => {}
            Err(e) => return fail(e),
        }
    }
}

/// `tiles` with their pixels coded by `codec` (in parallel; each tile's time in its
/// `encode_ms`), and each one's coded size.
fn coded(codec: PixelCodec, tiles: Vec<TilePixels>) -> Vec<TilePixels> {
    use rayon::prelude::*;
    tiles
        .into_par_iter()
        .map(|mut tile| {
            let start = std::time::Instant::now();
            let [x0, y0, x1, y1] = tile.rect;
            let (used, pixels) = if codec == PixelCodec::Raw {
                (codec, std::mem::take(&mut tile.pixels))
            } else {
                crate::pixels::encode(codec, &tile.pixels, x1 - x0, y1 - y0)
            };
            tile.times.encode_ms = start.elapsed().as_secs_f64() * 1e3;
            TilePixels { codec: used, coded_bytes: pixels.len() as u32, pixels, ..tile }
        })
        .collect()
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
        .map(|p| TilePixels {
            rect: [p.rect[0], p.rect[1], p.rect[0], p.rect[1]],
            codec: PixelCodec::Raw,
            pixels: Vec::new(),
            ..p
        })
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
