//! The frame loop of rank 0: per frame the camera, the jobs, sending, receiving and
//! compositing the tiles, writing the images and the stats lines.

use std::collections::VecDeque;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use codec::view::{Camera, TileGrid};
use glam::{Quat, Vec3};
use protocol::{unix_ms, Swap, ToDisplay, ToWorker};
use worker::transport::Transport;

use super::control::{steer, Client, Command, Control, Publisher};
use super::display::DirectSend;
use super::eye::Eye;
use super::link::{handshake, receive_pixels, receive_ready, send_all, Answer, Early, Silence};
use super::plan::{eye_path, frame_outputs, frame_path, save_wall, Plan};
use super::scene::{FrameContext, FrameJobs, Scene};
use super::stats::{worker_stats, ChunkStats, DisplayStats, MasterStats, NspStats, Span, TileStats, WorkerStats};
use crate::camera::StereoOutput;
use crate::composite::Image;
use crate::output::{Identity, LineLog};

/// A frame (or one eye of a stereo frame) sent to the workers and not yet composited.
struct InFlight {
    k: u32,
    /// The view's number in the messages: the frame's, or `2k` and `2k + 1` for stereo eyes.
    view: u32,
    eye: Option<Eye>,
    /// The display whose own frame this is (a wall whose displays have their corners).
    display: Option<usize>,
    /// The view's tile grid (its frame size).
    grid: TileGrid,
    answering: Vec<usize>,
    tiles: Vec<TileStats>,
    chunks: Option<ChunkStats>,
    nsp: Option<NspStats>,
    sort_ms: f64,
    send_ms: f64,
    /// Rank 0's `sort` and `send` spans.
    timeline: Vec<Span>,
}

/// What the writer thread does with a composited frame: write its image (or movie frame)
/// and its stats lines, in frame order (a stereo frame's left eye waits for its right).
struct Written {
    frame: Image,
    display: Option<usize>,
    /// Rank 0's stats line, whose `frame` is this frame's number.
    stats: MasterStats,
    workers: Vec<WorkerStats>,
}

/// Runs every frame of `tessera render` over `t`, whose rank 0 this process is.
///
/// Frames are pipelined: rank 0 sorts and sends frame k+1 (up to `--frames-in-flight`
/// frames ahead) before it waits for frame k's pixels, and a writer thread encodes and
/// writes the images and stats lines while rank 0 goes on. Workers take their messages in
/// order, so every frame's pixels, and so its image, are those of the unpipelined loop.
/// `--balance` sorts each frame from the costs of the frame before, so it keeps one frame
/// in flight.
pub(super) fn run(t: &dyn Transport, plan: &Plan) -> Result<()> {
    run_live(t, plan, None)
}

/// What a window hands the frame loop: its control (the window's input, and `--control`'s
/// port if given, on one channel), and what shows each frame.
pub struct Window {
    pub control: Control,
    pub present: Present,
}

/// Shows a frame: its image, rank 0's stats line and the workers' (as `--stats` writes them).
pub type Present = Box<dyn FnMut(&std::sync::Arc<Image>, &serde_json::Value, &[serde_json::Value]) + Send>;

/// [`run`], live in a window when `window` is given.
pub(super) fn run_live(t: &dyn Transport, plan: &Plan, window: Option<Window>) -> Result<()> {
    // The origin of the stats' timelines.
    let epoch = unix_ms();
    // Opened first, so that an unwritable path fails before any work.
    let stats = plan.stats.as_deref().map(LineLog::create).transpose()?;
    // Bound before the model loads, so that a taken port fails before any work.
    let (control, present) = match window {
        Some(w) => (Some(w.control), Some(w.present)),
        None => (plan.control.as_ref().map(|_| Control::default()), None),
    };
    if let Some(control) = &control {
        let token = plan.control.as_ref().and_then(|(_, token)| token.clone());
        // The eye stream first: once the port is announced, the stream is there too.
        if let Some(stream) = &plan.eye_stream {
            super::control::start_eye_stream(stream, token.clone(), control.sender())?;
        }
        if let Some((addr, _)) = &plan.control {
            control.listen(*addr, token)?;
        }
    }
    let mut scene = super::scene::load(plan)?;
    let grid = &plan.grid;
    let cam = scene.camera(&plan.camera, grid)?;
    check_cameras(scene.as_ref(), plan, &cam)?;
    // Ranks 1..=workers render; with --sorters K the last K-1 ranks help rank 0 sort.
    let workers = t.size() - plan.sorters as usize - plan.display_ranks as usize;
    let adapters = handshake(t, plan.timeout, grid)?;
    eprintln!("tessera: {} worker(s) ready ({})", workers, adapters.join(", "));
    if plan.pixel_codec != protocol::PixelCodec::Raw {
        let codec = ToWorker::PixelCodec(plan.pixel_codec).encode();
        send_all(t, (1..=workers).map(|w| (w, codec.clone())).collect(), plan.timeout)?;
    }
    // The kinds whose workers hold the model whole get it once, before the first frame.
    if let Some(model) = scene.model_message() {
        send_all(t, (1..=workers).map(|w| (w, model.clone())).collect(), plan.timeout)?;
    }
    let to_movie = crate::movie::is_movie(&plan.out);
    let movie = if to_movie {
        let width = if plan.stereo.is_some() { grid.width * 2 } else { grid.width };
        Some(crate::movie::Movie::start(&plan.out, width, grid.height, plan.fps, plan.timeout)?)
    } else {
        None
    };
    // Sorter ranks send the workers their shares of one frame at a time (the protocol has no
    // frame in flight beside another), so with --sorters a frame waits for the one before.
    let depth = plan.depth;
    let budget_slots = scene.budget_slots();
    let writer = Writer::start(
        plan,
        movie,
        stats,
        depth,
        epoch,
        budget_slots,
        Shows { publisher: control.as_ref().map(Control::publisher), present },
    );

    let direct =
        plan.wall.as_ref().filter(|_| plan.direct).map(|w| DirectSend::new(w, t.size(), plan.display_ranks as usize));
    let direct = direct.as_ref();
    let mut inbox = Inbox {
        costs: vec![0.0; grid.tiles()],
        silence: Silence::new(workers, plan.timeout),
        early: Early::default(),
        epoch,
    };
    let mut flight: VecDeque<InFlight> = VecDeque::new();
    let mut frames = frame_source(plan, cam, control.as_ref());
    // Display ranks with windows send what a person does in the first of them.
    let windowed_displays = plan.present && direct.is_some();
    // A `--frames` run whose frame is the one before (a still camera, a repeated eye
    // position) reuses it: rank 0 neither sorts nor sends, the workers do nothing, and the
    // writer copies the frame before's files. Not for movies, nor with display ranks (which
    // write the displays themselves); a live run makes no frame that did not change.
    let reuse = control.is_none() && !plan.direct && !to_movie && !plan.no_frame_reuse;
    let mut last_views: Option<Vec<ViewSpec>> = None;
    let result = (|| -> Result<()> {
        loop {
            let (k, views) = match frames.next_step(scene.as_ref())? {
                Step::End => break,
                // Nothing to do until an event: every frame in flight is shown first.
                Step::Idle => {
                    finish_all(t, &mut flight, plan, direct, &mut inbox, &writer)?;
                    if idle(t, frames.as_mut(), control.as_ref(), windowed_displays, &mut inbox)? {
                        let alive = ToWorker::KeepAlive.encode();
                        send_all(t, (1..t.size()).map(|r| (r, alive.clone())).collect(), plan.timeout)?;
                    }
                    continue;
                }
                Step::Load(path, client) => {
                    finish_all(t, &mut flight, plan, direct, &mut inbox, &writer)?;
                    let step = match swap_model(t, plan, workers, &path)? {
                        Ok(next) => {
                            scene = next;
                            inbox.costs.iter_mut().for_each(|c| *c = 0.0);
                            frames.loaded(scene.as_ref(), client, None)?
                        }
                        Err(e) => frames.loaded(scene.as_ref(), client, Some(e))?,
                    };
                    match step {
                        Step::Frame(k, views) => (k, views),
                        _ => continue,
                    }
                }
                Step::Snapshot(path, client) => {
                    finish_all(t, &mut flight, plan, direct, &mut inbox, &writer)?;
                    writer.snapshot(path, client)?;
                    continue;
                }
                Step::Frame(k, views) => (k, views),
            };
            if reuse && last_views.as_ref() == Some(&views) {
                finish_all(t, &mut flight, plan, direct, &mut inbox, &writer)?;
                check_outputs(plan, k)?;
                writer.repeat(k)?;
                continue;
            }
            last_views = reuse.then(|| views.clone());
            let n = views.len() as u32;
            for (j, spec) in views.into_iter().enumerate() {
                let ViewSpec { camera, eye, display, grid } = spec;
                let grid = &grid;
                let view = k * n + j as u32;
                let start = Instant::now();
                let sort_start = unix_ms();
                // A live run's grid may change (the window's size, a command): a new grid's
                // tiles have no costs yet.
                if inbox.costs.len() != grid.tiles() {
                    inbox.costs = vec![0.0; grid.tiles()];
                }
                let Settings { error_px, balance } = frames.settings();
                let ctx =
                    FrameContext { frame: view, camera, grid, workers, plan, costs: &inbox.costs, error_px, balance };
                send_all(t, scene.announce(&ctx), plan.timeout)?;
                let FrameJobs { messages: msgs, tiles, chunks, nsp } = scene.jobs(&ctx)?;
                if let Some(d) = direct {
                    let indices: Vec<u32> = tiles.iter().map(|s| s.index).collect();
                    let code = match eye {
                        None => 0,
                        Some(Eye::Left) => 1,
                        Some(Eye::Right) => 2,
                    };
                    send_all(t, d.frame_messages(view, k, code, &indices, grid), plan.timeout)?;
                }
                let answering: Vec<usize> = msgs.iter().map(|(w, _)| *w).collect();
                let sort_ms = ms(start);
                let (start, send_start) = (Instant::now(), unix_ms());
                send_all(t, msgs, plan.timeout)?;
                let send_ms = ms(start);
                let timeline = vec![
                    Span::between("sort", sort_start, send_start, epoch),
                    Span::between("send", send_start, unix_ms(), epoch),
                ];
                inbox.silence.expect(&answering);
                let f = InFlight {
                    k,
                    view,
                    eye,
                    display,
                    grid: *grid,
                    answering,
                    tiles,
                    chunks,
                    nsp,
                    sort_ms,
                    send_ms,
                    timeline,
                };
                flight.push_back(f);
                if flight.len() >= depth {
                    let f = flight.pop_front().expect("a frame in flight");
                    let done = complete(t, f, plan, direct, &mut inbox)?;
                    writer.send(done)?;
                }
            }
        }
        finish_all(t, &mut flight, plan, direct, &mut inbox, &writer)?;
        Ok(())
    })();
    let shutdown = ToWorker::Shutdown.encode();
    // Small enough for MPI to buffer at once; a rank that takes nothing within a moment is
    // already the run's error, which the result below reports.
    let shutdown_wait = plan.timeout.min(std::time::Duration::from_secs(2));
    let _ = t.send_many((1..t.size()).map(|r| (r, shutdown.clone())).collect(), shutdown_wait);
    // The writer's own error (a full disk, ffmpeg) is the cause when sending to it failed.
    let written = writer.finish();
    match (result, written) {
        // The loop stopped because the writer did: the writer's error says why.
        (Err(_), Err(w)) => Err(w),
        (r, w) => r.and(w),
    }
}

/// How often an idle rank 0 looks for input from display ranks' windows (which comes over
/// MPI, not on the control channel it sleeps on): a person's key or drag waits at most this.
const INPUT_POLL: std::time::Duration = std::time::Duration::from_millis(20);

/// An idle live run's wait for the next event: a command on the control channel, or (with
/// `windowed_displays`) a display rank's input, which goes onto that channel. True if none
/// came within [`KEEP_ALIVE`], for the loop to tell the other ranks it is there.
fn idle(
    t: &dyn Transport,
    frames: &mut dyn FrameSource,
    control: Option<&Control>,
    windowed_displays: bool,
    inbox: &mut Inbox,
) -> Result<bool> {
    let (Some(control), true) = (control, windowed_displays) else { return Ok(frames.wait(KEEP_ALIVE)) };
    let start = Instant::now();
    loop {
        for json in inbox.early.inputs.drain(..) {
            control.relay(&json);
        }
        if !frames.wait(INPUT_POLL) {
            return Ok(false);
        }
        if start.elapsed() >= KEEP_ALIVE {
            return Ok(true);
        }
        super::link::receive_inputs(t, &mut inbox.early)?;
    }
}

/// An error if a file frame `k` writes is an input (the plan checks the first and last
/// frames' names; this, each frame's as it comes).
fn check_outputs(plan: &Plan, k: u32) -> Result<()> {
    for p in frame_outputs(&plan.out, k, plan.frames, plan.wall.as_ref(), plan.stereo, plan.direct) {
        if Identity::of(&p).is_ok_and(|id| plan.inputs.contains(&id)) {
            bail!("the output {} is the same file as an input; refusing to overwrite it", p.display());
        }
    }
    Ok(())
}

/// Composites every frame in flight and hands it to the writer, in order.
fn finish_all(
    t: &dyn Transport,
    flight: &mut VecDeque<InFlight>,
    plan: &Plan,
    direct: Option<&DirectSend>,
    inbox: &mut Inbox,
    writer: &Writer,
) -> Result<()> {
    while let Some(f) = flight.pop_front() {
        writer.send(complete(t, f, plan, direct, inbox)?)?;
    }
    Ok(())
}

/// A live run's `load`: the model at `path` opened with the plan's settings, then the workers
/// told to free theirs and its caches, and sent the new one's model message if its kind has
/// one. The inner error is the model's (the run keeps its own); the outer, the transport's.
fn swap_model(
    t: &dyn Transport,
    plan: &Plan,
    workers: usize,
    path: &std::path::Path,
) -> Result<Result<Box<dyn Scene>>> {
    let next = match super::scene::load_path(plan, path) {
        Ok(next) => next,
        Err(e) => return Ok(Err(e)),
    };
    let unload = ToWorker::Unload.encode();
    send_all(t, (1..=workers).map(|w| (w, unload.clone())).collect(), plan.timeout)?;
    if let Some(model) = next.model_message() {
        send_all(t, (1..=workers).map(|w| (w, model.clone())).collect(), plan.timeout)?;
    }
    Ok(Ok(next))
}

/// What rank 0 keeps from one receive to the next: when each rank was last heard from,
/// messages that came before their turn, each tile's last measured cost (for `--balance`),
/// and the origin of the stats' timelines.
struct Inbox {
    costs: Vec<f64>,
    silence: Silence,
    early: Early,
    epoch: f64,
}

/// Receives and composites frame `f`'s pixels.
fn complete(
    t: &dyn Transport,
    f: InFlight,
    plan: &Plan,
    direct: Option<&DirectSend>,
    inbox: &mut Inbox,
) -> Result<Written> {
    let Inbox { costs, silence, early, epoch } = inbox;
    let epoch = *epoch;
    let InFlight { k, view, eye, display, grid, answering, mut tiles, chunks, nsp, sort_ms, send_ms, mut timeline } = f;
    let size = (grid.width, grid.height);
    let (start, receive_start) = (Instant::now(), unix_ms());
    // With display ranks the pixels go to them: rank 0 holds no frame.
    let mut frame = if direct.is_some() { Image::new(0, 0) } else { Image::new(size.0, size.1) };
    let mut composite_ms = 0.0;
    let (mut pixel_bytes, mut coded_bytes, mut raw_bytes) = (0u64, 0u64, 0u64);
    let (mut pixel_encode_ms, mut pixel_decode_ms) = (0.0, 0.0);
    let mut worker_lines = Vec::new();
    for _ in 0..answering.len() {
        let Answer { rank, tiles: pixels, span, pm } = receive_pixels(t, view, silence, early)?;
        let c = Instant::now();
        pixel_bytes += pixels.iter().map(|p| p.pixels.len() as u64).sum::<u64>();
        coded_bytes += pixels.iter().map(|p| p.coded_bytes as u64).sum::<u64>();
        pixel_encode_ms += pixels.iter().map(|p| p.times.encode_ms).sum::<f64>();
        // What the tiles are uncoded (a display rank's tiles come to rank 0 without pixels).
        raw_bytes += pixels
            .iter()
            .filter(|p| (p.index as usize) < grid.tiles())
            .map(|p| {
                let [x0, y0, x1, y1] = grid.tile_rect(p.index as usize);
                (x1 - x0) as u64 * (y1 - y0) as u64 * 4
            })
            .sum::<u64>();
        for p in &pixels {
            if direct.is_none() {
                let d = Instant::now();
                let rgba = worker::pixels::decode(p).with_context(|| format!("rank {rank}"))?;
                pixel_decode_ms += ms(d);
                frame.blit(p.rect, &rgba).with_context(|| format!("rank {rank}, tile {}", p.index))?;
            } else if !p.pixels.is_empty() {
                bail!("rank {rank} sent tile {}'s pixels to rank 0, which display ranks should have", p.index);
            }
            // A frame of a grid a live run has left since has no place among the costs.
            if let Some(cost) = costs.get_mut(p.index as usize) {
                *cost = p.times.total_ms();
            }
            if let Some(s) = tiles.iter_mut().find(|s| s.index == p.index) {
                s.triangles = p.triangles;
            }
        }
        composite_ms += ms(c);
        worker_lines.push(worker_stats(k, eye, rank, &pixels, span, pm, epoch));
    }
    let wait_ms = ms(start) - composite_ms;
    let receive_end = unix_ms();
    timeline.push(Span::between("receive", receive_start, receive_end, epoch));
    // Direct send: every display of the view assembled, then the swap.
    let displays = match direct {
        Some(d) => {
            let mut ready = Vec::new();
            let mut heard = Vec::new();
            let mut decode_ms = 0.0f64;
            for _ in d.display_ranks() {
                let r = receive_ready(t, view, silence, early)?;
                if heard.contains(&r.rank) {
                    bail!("rank {} reported view {view}'s displays twice", r.rank);
                }
                heard.push(r.rank);
                ready.extend(r.displays);
                decode_ms = decode_ms.max(r.decode_ms);
            }
            let swap = ToDisplay::Swap(Swap { view }).encode();
            send_all(t, d.display_ranks().map(|r| (r, swap.clone())).collect(), plan.timeout)?;
            let swap_ms = unix_ms();
            timeline.push(Span::between("swap", receive_end, swap_ms, epoch));
            let (first, last) =
                ready.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &(_, t)| (a.min(t), b.max(t)));
            Some(DisplayStats {
                displays: ready.len() as u32,
                pixel_decode_ms: decode_ms,
                first_ready_ms: first - epoch,
                last_ready_ms: last - epoch,
                spread_ms: last - first,
                swap_ms: swap_ms - epoch,
            })
        }
        None => None,
    };
    check_outputs(plan, k)?;
    worker_lines.sort_by_key(|l| l.rank);
    let stats = MasterStats {
        frame: k,
        eye,
        display: display.map(|i| plan.wall.as_ref().expect("a wall").displays[i].name.clone()),
        rank: 0,
        reused: false,
        sort_ms,
        send_ms,
        wait_ms,
        composite_ms,
        write_ms: 0.0,
        frame_ms: 0.0,
        rss_mb: resident_mb(),
        chunks,
        nsp,
        tiles,
        pixel_codec: codec_name(plan.pixel_codec),
        pixel_bytes,
        pixel_coded_bytes: coded_bytes,
        pixel_raw_bytes: raw_bytes,
        pixel_encode_ms,
        pixel_decode_ms,
        displays,
        timeline,
    };
    Ok(Written { frame, display, stats, workers: worker_lines })
}

/// Where a live run's frames go besides snapshots: the control port's subscribers (stats
/// lines) and a window.
struct Shows {
    publisher: Option<Publisher>,
    present: Option<Present>,
}

/// What the writer thread is handed, in order: a frame's view, or (a live run) a snapshot of
/// the last frame written, to a file, answered to the control client that asked.
enum WriterJob {
    View(Box<Written>),
    Snapshot(std::path::PathBuf, Client),
    /// Frame `k` is the frame before, again: its files are copied.
    Repeat(u32),
}

/// The writer thread: images (or movie frames) and stats lines, in frame order, off rank
/// 0's critical path; at most `depth` frames wait for it. In a live run (`--control`) it
/// writes no frame file: it keeps the last frame for snapshots and sends every stats line to
/// the control port's subscribers.
struct Writer {
    tx: Option<std::sync::mpsc::SyncSender<WriterJob>>,
    thread: Option<std::thread::JoinHandle<Result<()>>>,
}

impl Writer {
    fn start(
        plan: &Plan,
        mut movie: Option<crate::movie::Movie>,
        mut stats: Option<LineLog>,
        depth: usize,
        epoch: f64,
        budget_slots: Option<u32>,
        shows: Shows,
    ) -> Writer {
        let Shows { publisher, mut present } = shows;
        let (tx, rx) = std::sync::mpsc::sync_channel::<WriterJob>(depth);
        let (out, frames, wall, stereo) = (plan.out.clone(), plan.frames, plan.wall.clone(), plan.stereo);
        let (direct, codec_name) = (plan.direct, codec_name(plan.pixel_codec));
        // With display ranks, they write the displays and rank 0 writes no image; a live run
        // writes snapshots only.
        let images = !plan.direct;
        let live = publisher.is_some();
        let eyes = if plan.stereo.is_some() { 2 } else { 1 };
        let per_frame = eyes * plan.wall.as_ref().filter(|w| w.per_display()).map_or(1, |w| w.displays.len());
        let thread = std::thread::spawn(move || -> Result<()> {
            let begin = Instant::now();
            let mut last = begin;
            // Workers already told about a node pool smaller than their budget.
            let mut capped = std::collections::HashSet::new();
            // Workers already told about a mesh coarsened to stay within the budget.
            let mut coarsened = std::collections::HashSet::new();
            // A frame's views (eyes, displays with frames of their own) wait for the last.
            let mut views: Vec<Written> = Vec::with_capacity(per_frame);
            // A live run's last frame, for snapshots.
            // Shared with a window without a copy.
            let mut shown: Option<std::sync::Arc<Image>> = None;
            for job in rx {
                let w = match job {
                    WriterJob::View(w) => *w,
                    WriterJob::Snapshot(path, client) => {
                        // A wall's snapshot is what render writes: each display and the overview.
                        let save = |f: &Image| match &wall {
                            Some(wall) => save_wall(wall, f, None, &path),
                            None => f.save_png(&path),
                        };
                        match shown.as_deref().map(save) {
                            Some(Ok(())) => client.send(&serde_json::json!({ "ok": "snapshot", "path": path })),
                            Some(Err(e)) => client.error(format!("snapshot: {}", crate::output::one_line(&e))),
                            None => client.error("snapshot: no frame has been shown yet"),
                        }
                        continue;
                    }
                    WriterJob::Repeat(k) => {
                        let (start, write_start) = (Instant::now(), unix_ms());
                        let before = frame_outputs(&out, k.saturating_sub(1), frames, wall.as_ref(), stereo, direct);
                        let now = frame_outputs(&out, k, frames, wall.as_ref(), stereo, direct);
                        for (from, to) in before.iter().zip(&now).filter(|_| images && !live) {
                            let bytes =
                                std::fs::read(from).with_context(|| format!("cannot read {}", from.display()))?;
                            crate::output::write_atomic(to, |w| std::io::Write::write_all(w, &bytes))?;
                        }
                        let write_ms = ms(start);
                        let frame_ms = lap(&mut last);
                        eprintln!("frame {}: the frame before, still ({write_ms:.1} ms)", k + 1);
                        let line = MasterStats {
                            frame: k,
                            reused: true,
                            write_ms,
                            frame_ms,
                            rss_mb: resident_mb(),
                            timeline: vec![Span::between("write", write_start, unix_ms(), epoch)],
                            ..MasterStats::new(codec_name.clone())
                        };
                        if let Some(log) = stats.as_mut() {
                            log.line(&serde_json::to_string(&line)?)?;
                        }
                        continue;
                    }
                };
                views.push(w);
                if views.len() < per_frame {
                    continue;
                }
                let mut views = std::mem::take(&mut views);
                let k = views[0].stats.frame;
                let (start, write_start) = (Instant::now(), unix_ms());
                let path = frame_path(&out, k, frames);
                // One image per eye: a display's own frame goes to its place on the wall.
                let per_eye = if views[0].display.is_some() { per_frame / eyes } else { 1 };
                // The frames move out of the views (whose stats lines are written below).
                let mut images_by_eye: Vec<Image> = views
                    .chunks_mut(per_eye)
                    .filter(|_| images)
                    .map(|group| match (&wall, group[0].display) {
                        (Some(wall), Some(_)) => {
                            let mut frame = Image::new(wall.width, wall.height);
                            for v in group.iter() {
                                let rect = wall.displays[v.display.expect("a display's view")].rect;
                                frame.blit(rect, &v.frame.rgba)?;
                            }
                            Ok(frame)
                        }
                        _ => Ok(std::mem::replace(&mut group[0].frame, Image::new(0, 0))),
                    })
                    .collect::<Result<_>>()?;
                if live && images_by_eye.len() == 1 {
                    // Kept for snapshots and the window, not written.
                    shown = images_by_eye.pop().map(std::sync::Arc::new);
                }
                match (&images_by_eye[..], stereo) {
                    _ if !images || live => {}
                    ([l, r], Some(StereoOutput::Separate)) => {
                        write_image(l, &eye_path(&path, "left"), wall.as_ref(), None, None)?;
                        write_image(r, &eye_path(&path, "right"), wall.as_ref(), None, None)?;
                    }
                    ([l, r], _) => write_image(l, &path, wall.as_ref(), Some(r), movie.as_mut())?,
                    ([frame], _) => write_image(frame, &path, wall.as_ref(), None, movie.as_mut())?,
                    (other, _) => bail!("frame {} came with {} images", k + 1, other.len()),
                }
                let write_ms = ms(start);
                let frame_ms = lap(&mut last);
                let fps = (k + 1) as f64 / (last - begin).as_secs_f64().max(1e-9);
                eprintln!(
                    "frame {}: {} tiles, sort {:.1} ms, {} ({fps:.1} frames/s)",
                    k + 1,
                    views.iter().map(|v| v.stats.tiles.len()).sum::<usize>(),
                    views.iter().map(|v| v.stats.sort_ms).sum::<f64>(),
                    if live { "shown".into() } else { path.display().to_string() }
                );
                let write = Span::between("write", write_start, unix_ms(), epoch);
                for Written { workers, .. } in &views {
                    for w in workers {
                        if let Some(note) = capped_slots_note(budget_slots, w, &mut capped) {
                            eprintln!("{note}");
                        }
                        if let Some(scale) = w.error_scale().filter(|_| coarsened.insert(w.rank)) {
                            eprintln!(
                                "note: rank {} adapts frame {} at {scale:.2}x --error-px to keep its mesh within \
                                 --gpu-budget-mb (the stats' error_scale, each frame)",
                                w.rank,
                                k + 1
                            );
                        }
                    }
                }
                for Written { stats: mut line, workers, .. } in views {
                    (line.write_ms, line.frame_ms) = (write_ms, frame_ms);
                    line.timeline.push(write.clone());
                    if let Some(p) = &publisher {
                        p.publish(&serde_json::to_value(&line)?);
                    }
                    if let (Some(show), Some(frame)) = (present.as_mut(), shown.as_ref()) {
                        let lines: Vec<serde_json::Value> =
                            workers.iter().map(serde_json::to_value).collect::<Result<_, _>>()?;
                        show(frame, &serde_json::to_value(&line)?, &lines);
                    }
                    if let Some(log) = stats.as_mut() {
                        log.line(&serde_json::to_string(&line)?)?;
                        for l in workers {
                            log.line(&serde_json::to_string(&l)?)?;
                        }
                    }
                }
            }
            if let Some(m) = movie {
                m.finish().with_context(|| format!("cannot write {}", out.display()))?;
            }
            Ok(())
        });
        Writer { tx: Some(tx), thread: Some(thread) }
    }

    /// Hands a frame to the writer (waiting while `depth` frames wait already); an error if
    /// the writer stopped, which [`Writer::finish`] reports.
    fn send(&self, w: Written) -> Result<()> {
        self.job(WriterJob::View(Box::new(w)))
    }

    /// Frame `k` is the frame before: its files are that frame's, copied.
    fn repeat(&self, k: u32) -> Result<()> {
        self.job(WriterJob::Repeat(k))
    }

    /// Writes the last frame written to `path` once the frames before it are written, and
    /// answers `client`.
    fn snapshot(&self, path: std::path::PathBuf, client: Client) -> Result<()> {
        self.job(WriterJob::Snapshot(path, client))
    }

    fn job(&self, job: WriterJob) -> Result<()> {
        match self.tx.as_ref().map(|tx| tx.send(job).is_ok()) {
            Some(true) => Ok(()),
            _ => bail!("the image writer stopped"),
        }
    }

    /// Waits for every frame to be written; the writer's error, if any.
    fn finish(mut self) -> Result<()> {
        drop(self.tx.take());
        match self.thread.take().map(|h| h.join()) {
            Some(Ok(r)) => r,
            Some(Err(_)) => bail!("the image writer panicked"),
            None => Ok(()),
        }
    }
}

/// Writes a frame: a movie frame, a PNG, or a wall's displays and overview; with `right`,
/// a stereo pair side by side.
fn write_image(
    frame: &Image,
    path: &std::path::Path,
    wall: Option<&crate::wall::Wall>,
    right: Option<&Image>,
    movie: Option<&mut crate::movie::Movie>,
) -> Result<()> {
    match (wall, movie, right) {
        (_, Some(m), None) => m.frame(&frame.rgba),
        (_, Some(m), Some(r)) => m.frame(&frame.beside(r).rgba),
        (Some(wall), None, _) => save_wall(wall, frame, right, path),
        (None, None, None) => frame.save_png(path),
        (None, None, Some(r)) => frame.beside(r).save_png(path),
    }
}

/// What the frame loop does next: sort frame `k`'s views, write a snapshot of the last frame
/// (a live run), wait for an event (a live run), or end.
enum Step {
    Frame(u32, Vec<ViewSpec>),
    Snapshot(std::path::PathBuf, Client),
    /// Another model in place of this one (a live run).
    Load(std::path::PathBuf, Client),
    Idle,
    End,
}

/// Where the frame loop's frames come from, one step at a time: a fixed count
/// ([`FixedFrames`]), or a live run's commands ([`Controlled`]), whose still view costs no
/// frame.
trait FrameSource {
    /// The next step, without waiting: [`Step::Idle`] when there is none yet.
    fn next_step(&mut self, scene: &dyn Scene) -> Result<Step>;

    /// The error threshold and balancing of the frames it gives.
    fn settings(&self) -> Settings;

    /// Waits for the next event, after an idle step (the loop has shown every frame in
    /// flight by then, so that what was asked for is on screen while nothing happens); true
    /// if none came within `timeout`.
    fn wait(&mut self, _timeout: std::time::Duration) -> bool {
        false
    }

    /// After [`Step::Load`]: `scene` is the new model (or the old one, with `failed`); the
    /// step that answers `client`.
    fn loaded(&mut self, _scene: &dyn Scene, client: Client, failed: Option<anyhow::Error>) -> Result<Step> {
        if let Some(e) = failed {
            client.error(format!("load: {}", crate::output::one_line(&e)));
        }
        Ok(Step::Idle)
    }
}

/// How long an idle live run waits before it tells its workers and sorters it is there: well
/// within their silence limit of an hour.
const KEEP_ALIVE: std::time::Duration = std::time::Duration::from_secs(600);

/// What a frame is sorted with besides its views: the screen error of `.dpm` and `.nsp`
/// models, and whether tiles go to workers by cost.
#[derive(Clone, Copy)]
struct Settings {
    error_px: f32,
    balance: bool,
}

/// The frames of a run from camera `cam`: a live run's (`control`), or `--frames`.
fn frame_source<'a>(plan: &'a Plan, cam: Camera, control: Option<&'a Control>) -> Box<dyn FrameSource + 'a> {
    match control {
        Some(control) => Box::new(Controlled {
            plan,
            spec: plan.camera.clone(),
            cam,
            grid: plan.grid,
            settings: Settings { error_px: plan.error_px, balance: plan.balance },
            tracked: None,
            next: 0,
            control,
            pending: None,
            animation: None,
        }),
        None => Box::new(FixedFrames { plan, cam, next: 0 }),
    }
}

/// `--frames` frames, orbiting, zooming or following `--eye-path` from the first camera.
struct FixedFrames<'a> {
    plan: &'a Plan,
    cam: Camera,
    next: u32,
}

impl FrameSource for FixedFrames<'_> {
    fn settings(&self) -> Settings {
        Settings { error_px: self.plan.error_px, balance: self.plan.balance }
    }

    fn next_step(&mut self, scene: &dyn Scene) -> Result<Step> {
        if self.next >= self.plan.frames {
            return Ok(Step::End);
        }
        let k = self.next;
        self.next += 1;
        Ok(Step::Frame(k, frame_views(scene, self.plan, &self.cam, k)?))
    }
}

/// A live run's frames (`--control`): the first from the flags, then one for each command
/// that changes the view, until `quit`. Between them rank 0 waits: a still view costs no
/// sort, no message and no render.
struct Controlled<'a> {
    plan: &'a Plan,
    /// The camera flags of the view shown, and the camera they give.
    spec: crate::camera::CameraSpec,
    cam: Camera,
    /// The frame's grid: the plan's, or as the window's size and commands made it.
    grid: TileGrid,
    /// The error threshold and balancing, the plan's until a command changes them.
    settings: Settings,
    /// The eye a head tracker last gave (a wall placed in the world).
    tracked: Option<Vec3>,
    next: u32,
    control: &'a Control,
    /// A request taken by [`FrameSource::wait`] (or left by the steering that joins a
    /// frame) and not yet handled.
    pending: Option<super::control::Request>,
    /// A timed camera move in progress (`animate`).
    animation: Option<Animation>,
}

/// A timed camera move (`animate`): from the camera flags and camera it began at, by an
/// orbit or to an eye and target, over `seconds`.
struct Animation {
    start: Instant,
    seconds: f32,
    spec: crate::camera::CameraSpec,
    cam: Camera,
    /// The move at its end: an `orbit`, or a `camera` with the eye and target.
    end: Command,
    client: Client,
}

impl Animation {
    /// How far the move is now (0 to 1), and the steering command from its start to there.
    fn now(&self) -> (f32, Command) {
        let t = (self.start.elapsed().as_secs_f32() / self.seconds).min(1.0);
        let command = match &self.end {
            Command::Orbit { degrees, pitch } => Command::Orbit { degrees: degrees * t, pitch: pitch.map(|p| p * t) },
            Command::Camera { eye, target, .. } => Command::Camera {
                eye: eye.map(|e| self.cam.eye.lerp(Vec3::from(e), t).to_array()),
                target: target.map(|e| self.cam.target.lerp(Vec3::from(e), t).to_array()),
                up: None,
                fovy: None,
            },
            _ => Command::Reset {},
        };
        (t, command)
    }
}

/// How often a running animation looks for commands while its view stays the same.
const ANIMATION_TICK: std::time::Duration = std::time::Duration::from_millis(16);

impl FrameSource for Controlled<'_> {
    fn settings(&self) -> Settings {
        self.settings
    }

    fn wait(&mut self, timeout: std::time::Duration) -> bool {
        if self.pending.is_some() {
            return false;
        }
        let timeout = if self.animation.is_some() { timeout.min(ANIMATION_TICK) } else { timeout };
        // The control keeps a sender of its own: the channel stays open while the run does.
        match self.control.requests.recv_timeout(timeout) {
            Ok(r) => {
                self.pending = Some(r);
                false
            }
            // A running animation's tick is no silence: its frames go on.
            Err(_) => self.animation.is_none(),
        }
    }

    fn loaded(&mut self, scene: &dyn Scene, client: Client, failed: Option<anyhow::Error>) -> Result<Step> {
        if let Some(e) = failed {
            client.error(format!("load: {}", crate::output::one_line(&e)));
            return Ok(Step::Idle);
        }
        // The new model is framed as the flags frame a model.
        let framed = scene.camera(&self.plan.camera, &self.grid).and_then(|cam| {
            crate::camera::check_precision(&cam, self.grid.height)?;
            Ok(cam)
        });
        match framed {
            Ok(cam) => {
                (self.spec, self.cam) = (self.plan.camera.clone(), cam);
                self.frame(scene, &client, "load")
            }
            // Loaded, but the flags' camera cannot frame it: a camera command can.
            Err(e) => {
                client.error(format!("load: {}", crate::output::one_line(&e)));
                Ok(Step::Idle)
            }
        }
    }

    fn next_step(&mut self, scene: &dyn Scene) -> Result<Step> {
        if self.next == 0 {
            self.next = 1;
            return Ok(Step::Frame(0, self.views(scene)?));
        }
        loop {
            let request = match self.pending.take().map(Ok).unwrap_or_else(|| self.control.requests.try_recv()) {
                Ok(r) => r,
                Err(std::sync::mpsc::TryRecvError::Empty) => match self.animation.take() {
                    Some(animation) => return self.animate(scene, animation),
                    None => return Ok(Step::Idle),
                },
                Err(std::sync::mpsc::TryRecvError::Disconnected) => return Ok(Step::End),
            };
            let client = request.client;
            match request.command {
                Command::Quit {} => {
                    client.send(&serde_json::json!({ "ok": "quit" }));
                    return Ok(Step::End);
                }
                Command::Snapshot { .. } if self.plan.direct => {
                    client.error("snapshot: with --display-ranks the display ranks hold the frames, rank 0 none")
                }
                Command::Snapshot { path } => return Ok(Step::Snapshot(path, client)),
                Command::Animate { seconds, degrees, pitch, eye, target } => {
                    let end = match degrees.or(pitch) {
                        Some(_) => Command::Orbit { degrees: degrees.unwrap_or(0.0), pitch },
                        None => Command::Camera { eye, target, up: None, fovy: None },
                    };
                    client.send(&serde_json::json!({ "ok": "animate", "frame": self.next }));
                    self.animation = Some(Animation {
                        start: Instant::now(),
                        seconds,
                        spec: self.spec.clone(),
                        cam: self.cam,
                        end,
                        client,
                    });
                }
                Command::Eye { position } if self.plan.wall.as_ref().is_some_and(|w| w.placed()) => {
                    self.animation = None;
                    // A tracker's positions that came meanwhile: the last is where the head is.
                    let mut eye = Vec3::from(position);
                    let mut answer = vec![client];
                    while let Ok(next) = self.control.requests.try_recv() {
                        match next.command {
                            Command::Eye { position } => {
                                eye = Vec3::from(position);
                                answer.push(next.client);
                            }
                            _ => {
                                self.pending = Some(next);
                                break;
                            }
                        }
                    }
                    if self.tracked == Some(eye) {
                        answer.iter().for_each(|c| c.send(&serde_json::json!({ "ok": "eye", "frame": self.next - 1 })));
                        continue;
                    }
                    let checked =
                        self.plan.wall.as_ref().map(|w| w.camera_args(&self.plan.camera, eye)).transpose().and_then(
                            |spec| {
                                let cam = scene.camera(&spec.unwrap_or_default(), &self.grid)?;
                                crate::camera::check_precision(&cam, self.grid.height)
                            },
                        );
                    if let Err(e) = checked {
                        answer.iter().for_each(|c| c.error(format!("eye: {}", crate::output::one_line(&e))));
                        continue;
                    }
                    self.tracked = Some(eye);
                    let step = self.frame(scene, &answer[0], "eye")?;
                    let k = self.next - 1;
                    answer[1..].iter().for_each(|c| c.send(&serde_json::json!({ "ok": "eye", "frame": k })));
                    return Ok(step);
                }
                Command::Load { path } => {
                    if self.plan.sorters > 1 || self.plan.display_ranks > 0 {
                        client.error("load: sorter and display ranks keep the model of the flags");
                        continue;
                    }
                    self.animation = None;
                    return Ok(Step::Load(path, client));
                }
                Command::Subscribe {} => {
                    self.control.subscribe(client.clone());
                    client.send(&serde_json::json!({ "ok": "subscribe" }));
                }
                Command::Status {} => client.send(&serde_json::json!({
                    "ok": "status",
                    "frames": self.next,
                    "eye": self.cam.eye.to_array(),
                    "target": self.cam.target.to_array(),
                    "up": self.cam.up.to_array(),
                    "fovy": self.cam.fovy,
                    "animating": self.animation.is_some(),
                })),
                Command::Resize { width, height } => {
                    if let Some(step) =
                        self.regrid(scene, &client, "resize", (width, height), (self.grid.cols, self.grid.rows))?
                    {
                        return Ok(step);
                    }
                }
                Command::Tiles { cols, rows } => {
                    if self.plan.sorters > 1 || self.plan.display_ranks > 0 || self.plan.wall.is_some() {
                        client.error("tiles: sorter ranks and walls keep the grid of the flags");
                    } else if let Some(step) =
                        self.regrid(scene, &client, "tiles", (self.grid.width, self.grid.height), (cols, rows))?
                    {
                        return Ok(step);
                    }
                }
                Command::ErrorPx { value } if value != self.settings.error_px => {
                    self.settings.error_px = value;
                    return self.frame(scene, &client, "error_px");
                }
                Command::Balance { on } if on != self.settings.balance => {
                    self.settings.balance = on;
                    return self.frame(scene, &client, "balance");
                }
                // The same setting: nothing to sort or show.
                command @ (Command::ErrorPx { .. } | Command::Balance { .. }) => {
                    client.send(&serde_json::json!({ "ok": command_name(&command), "frame": self.next - 1 }))
                }
                command => {
                    // A person or program steering takes over from a timed move.
                    self.animation = None;
                    let what = command_name(&command);
                    match self.steer(scene, &command) {
                        Ok(Some((spec, cam))) => {
                            (self.spec, self.cam) = (spec, cam);
                            // Steering that came meanwhile (a drag's many moves) joins this
                            // frame: a still view waits, a moving one shows where it is now.
                            let mut answer = vec![(client, what)];
                            while let Ok(next) = self.control.requests.try_recv() {
                                let what = command_name(&next.command);
                                match self.steer(scene, &next.command) {
                                    Ok(Some((spec, cam))) => {
                                        (self.spec, self.cam) = (spec, cam);
                                        answer.push((next.client, what));
                                    }
                                    Ok(None) => answer.push((next.client, what)),
                                    Err(None) => {
                                        self.pending = Some(next);
                                        break;
                                    }
                                    Err(Some(e)) => {
                                        next.client.error(format!("{what}: {}", crate::output::one_line(&e)))
                                    }
                                }
                            }
                            let k = self.next;
                            self.next += 1;
                            for (client, what) in answer {
                                client.send(&serde_json::json!({ "ok": what, "frame": k }));
                            }
                            return Ok(Step::Frame(k, self.views(scene)?));
                        }
                        // The same view: nothing to sort or show.
                        Ok(None) => client.send(&serde_json::json!({ "ok": what, "frame": self.next - 1 })),
                        Err(e) => {
                            let e = e.map_or_else(
                                || "not a command of a live run".to_string(),
                                |e| crate::output::one_line(&e),
                            );
                            client.error(format!("{what}: {e}"));
                        }
                    }
                }
            }
        }
    }
}

impl Controlled<'_> {
    /// The camera flags and camera after a steering `command`: `Ok(None)` if the view stays
    /// the same, `Err(None)` if it is no steering command, `Err(Some(why))` if the camera
    /// it asks for cannot be rendered.
    fn steer(
        &self,
        scene: &dyn Scene,
        command: &Command,
    ) -> Result<Option<(crate::camera::CameraSpec, Camera)>, Option<anyhow::Error>> {
        self.steer_from(scene, &self.spec, &self.cam, command)
    }

    /// [`Controlled::steer`] from the camera flags `spec` and the camera `cam` they gave.
    fn steer_from(
        &self,
        scene: &dyn Scene,
        spec: &crate::camera::CameraSpec,
        cam: &Camera,
        command: &Command,
    ) -> Result<Option<(crate::camera::CameraSpec, Camera)>, Option<anyhow::Error>> {
        let spec = steer(spec, cam, &self.plan.camera, command).ok_or(None)?;
        let cam = scene.camera(&spec, &self.grid).map_err(Some)?;
        crate::camera::check_precision(&cam, self.grid.height).map_err(Some)?;
        Ok((cam != self.cam).then_some((spec, cam)))
    }

    /// The next frame of a timed move: where it is now (the move kept until its end); an
    /// idle step while its view stays the same; its error, to the client that started it,
    /// ends it.
    fn animate(&mut self, scene: &dyn Scene, animation: Animation) -> Result<Step> {
        let (t, command) = animation.now();
        let steered = self.steer_from(scene, &animation.spec, &animation.cam, &command);
        let step = match steered {
            Ok(Some((spec, cam))) => {
                (self.spec, self.cam) = (spec, cam);
                let k = self.next;
                self.next += 1;
                Step::Frame(k, self.views(scene)?)
            }
            Ok(None) => Step::Idle,
            Err(e) => {
                let e = e.map_or_else(|| "not a move".to_string(), |e| crate::output::one_line(&e));
                animation.client.error(format!("animate: {e}"));
                return Ok(Step::Idle);
            }
        };
        if t < 1.0 {
            self.animation = Some(animation);
        }
        Ok(step)
    }
}

impl Controlled<'_> {
    /// The frame re-planned at `size` in `tiles` (`what` names the command), or `None` when
    /// that is the grid already or cannot be (answered to `client`).
    fn regrid(
        &mut self,
        scene: &dyn Scene,
        client: &Client,
        what: &str,
        (width, height): (u32, u32),
        (cols, rows): (u32, u32),
    ) -> Result<Option<Step>> {
        let regridded = TileGrid::new(width, height, cols, rows)
            .map_err(anyhow::Error::from)
            .and_then(|grid| Ok((scene.camera(&self.spec, &grid)?, grid)));
        match regridded {
            Ok((cam, grid)) if grid != self.grid => {
                (self.cam, self.grid) = (cam, grid);
                return self.frame(scene, client, what).map(Some);
            }
            Ok(_) => client.send(&serde_json::json!({ "ok": what, "frame": self.next - 1 })),
            Err(e) => client.error(format!("{what}: {}", crate::output::one_line(&e))),
        }
        Ok(None)
    }

    /// The views of the camera and grid now: one, or a wall's (a live run has no stereo).
    fn views(&self, scene: &dyn Scene) -> Result<Vec<ViewSpec>> {
        if self.plan.wall.is_some() {
            return views_from(scene, self.plan, &self.cam, 0, self.tracked);
        }
        Ok(vec![ViewSpec { camera: self.cam, eye: None, display: None, grid: self.grid }])
    }

    /// The next frame, answered to `client` with its number.
    fn frame(&mut self, scene: &dyn Scene, client: &Client, what: &str) -> Result<Step> {
        let views = self.views(scene)?;
        let k = self.next;
        self.next += 1;
        client.send(&serde_json::json!({ "ok": what, "frame": k }));
        Ok(Step::Frame(k, views))
    }
}

/// `--pixel-codec` as the stats say it.
fn codec_name(codec: protocol::PixelCodec) -> String {
    match codec {
        protocol::PixelCodec::Raw => "raw".into(),
        protocol::PixelCodec::Lz4 => "lz4".into(),
        protocol::PixelCodec::Jpeg { quality } => format!("jpeg:{quality}"),
    }
}

/// A command's name, as its JSON `cmd` says it.
fn command_name(command: &Command) -> &'static str {
    match command {
        Command::Camera { .. } => "camera",
        Command::Orbit { .. } => "orbit",
        Command::Zoom { .. } => "zoom",
        Command::Move { .. } => "move",
        Command::Reset {} => "reset",
        Command::Animate { .. } => "animate",
        Command::Resize { .. } => "resize",
        Command::Tiles { .. } => "tiles",
        Command::ErrorPx { .. } => "error_px",
        Command::Balance { .. } => "balance",
        Command::Snapshot { .. } => "snapshot",
        Command::Load { .. } => "load",
        Command::Eye { .. } => "eye",
        Command::Subscribe {} => "subscribe",
        Command::Status {} => "status",
        Command::Quit {} => "quit",
    }
}

/// One view of a frame: its camera, its eye (stereo) and, on a wall whose displays each
/// have a frame, the display, with the grid of the view's frame.
#[derive(Clone, PartialEq)]
struct ViewSpec {
    camera: Camera,
    eye: Option<Eye>,
    display: Option<usize>,
    grid: TileGrid,
}

/// The views of frame `k`: one, or a left and a right eye with `--stereo`, and on a wall
/// whose displays have their corners one per display (per eye). A wall placed in the world
/// gives each eye (from the wall file or `--eye-path`) the off-axis frustum through it, or
/// through each display; otherwise the frame's camera orbits and zooms from `cam`, and
/// stereo eyes converge on the plane through its target. Their cameras were checked once, before
/// the first frame ([`check_cameras`]).
fn frame_views(scene: &dyn Scene, plan: &Plan, cam: &Camera, k: u32) -> Result<Vec<ViewSpec>> {
    views_from(scene, plan, cam, k, None)
}

/// [`frame_views`], with a live run's tracked eye in place of `--eye-path`'s or the wall
/// file's.
fn views_from(scene: &dyn Scene, plan: &Plan, cam: &Camera, k: u32, tracked: Option<Vec3>) -> Result<Vec<ViewSpec>> {
    let half = plan.separation.map(|s| s * 0.5);
    let eye_of = |e: usize| half.map(|_| if e == 0 { Eye::Left } else { Eye::Right });
    if let Some(wall) = plan.wall.as_ref().filter(|w| w.placed()) {
        let eye = match (tracked, &plan.eyes) {
            (Some(eye), _) => eye,
            (None, Some(eyes)) => eyes[k as usize],
            (None, None) => wall.eye.context("a wall placed in the world needs an eye")?,
        };
        let right = wall.right().context("a wall placed in the world")?;
        let eyes = match half {
            Some(h) => vec![eye - right * h, eye + right * h],
            None => vec![eye],
        };
        let mut views = Vec::new();
        for (e, &at) in eyes.iter().enumerate() {
            if !wall.per_display() {
                let camera = scene.camera(&wall.camera_args(&plan.camera, at)?, &plan.grid)?;
                views.push(ViewSpec { camera, eye: eye_of(e), display: None, grid: plan.grid });
                continue;
            }
            for (i, &grid) in plan.display_grids.iter().enumerate() {
                let camera = scene.camera(&wall.display_camera_args(i, &plan.camera, at)?, &grid)?;
                views.push(ViewSpec { camera, eye: eye_of(e), display: Some(i), grid });
            }
        }
        return Ok(views);
    }
    let cam_k = if plan.orbit { orbit_by(cam, k, plan.frames, plan.orbit_degrees) } else { *cam };
    let cam_k = zoom_by(&cam_k, k, plan.frames, plan.zoom);
    let cameras = match half {
        Some(h) => {
            let (focus, aspect) = (cam_k.eye.distance(cam_k.target), plan.grid.aspect());
            vec![cam_k.stereo_eye(-h, focus, aspect), cam_k.stereo_eye(h, focus, aspect)]
        }
        None => vec![cam_k],
    };
    Ok(cameras
        .into_iter()
        .enumerate()
        .map(|(e, camera)| ViewSpec { camera, eye: eye_of(e), display: None, grid: plan.grid })
        .collect())
}

/// Checks every camera the run will use before any work ([`crate::camera::check_precision`]),
/// printing its warnings once: each view (eye, display) of the first and the last frame,
/// which bound a zoom (an orbit changes no depth range, field of view or shift), and of
/// every frame when `--eye-path` moves the eye.
fn check_cameras(scene: &dyn Scene, plan: &Plan, cam: &Camera) -> Result<()> {
    let last = plan.frames.saturating_sub(1);
    let mut frames: Vec<u32> = if plan.eyes.is_some() { (0..plan.frames).collect() } else { vec![0, last] };
    // One frame: its first is its last.
    frames.dedup();
    let mut warned = std::collections::HashSet::new();
    for k in frames {
        for v in frame_views(scene, plan, cam, k).with_context(|| format!("frame {}", k + 1))? {
            let eye = match v.eye {
                Some(Eye::Left) => ", left eye",
                Some(Eye::Right) => ", right eye",
                None => "",
            };
            let display = match (v.display, &plan.wall) {
                (Some(i), Some(w)) => format!(", display {}", w.displays[i].name),
                _ => String::new(),
            };
            let what = format!("frame {}{eye}{display}", k + 1);
            for w in crate::camera::check_precision(&v.camera, v.grid.height).with_context(|| what.clone())? {
                if warned.insert(w.clone()) {
                    eprintln!("warning: {w}");
                }
            }
        }
    }
    Ok(())
}

/// This process's resident memory in MB (Linux: `/proc/self/statm`), for the stats.
fn resident_mb() -> Option<f64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: f64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096.0 / (1 << 20) as f64)
}

/// Milliseconds since `last`, which becomes now (a frame's period, on the writer).
fn lap(last: &mut Instant) -> f64 {
    let now = Instant::now();
    let ms = (now - *last).as_secs_f64() * 1e3;
    *last = now;
    ms
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

/// The camera of frame `k` of `n` on a full orbit around the target, about the up axis.
pub fn orbit(cam: &Camera, k: u32, n: u32) -> Camera {
    orbit_by(cam, k, n, 360.0)
}

/// Frame `k` of `n` of a zoom whose last frame is at `last` times the first's distance
/// from the target (the near plane follows the eye; the far plane stays).
pub fn zoom_by(cam: &Camera, k: u32, n: u32, last: f32) -> Camera {
    if last == 1.0 || n < 2 {
        return *cam;
    }
    let f = last.powf(k as f32 / (n - 1) as f32);
    Camera { eye: cam.target + (cam.eye - cam.target) * f, near: cam.near * f, ..*cam }
}

/// The camera of frame `k` of `n` on an orbit of `degrees` in all, about the up axis.
pub fn orbit_by(cam: &Camera, k: u32, n: u32, degrees: f32) -> Camera {
    let angle = degrees.to_radians() * k as f32 / n as f32;
    let rot = Quat::from_axis_angle(cam.up.normalize(), angle);
    Camera { eye: cam.target + rot * (cam.eye - cam.target), ..*cam }
}

/// Once per worker, a note when its node pool holds fewer slots than `--gpu-budget-mb`
/// makes: its GPU binds less than the budget in one buffer, which the pool is.
fn capped_slots_note(
    budget_slots: Option<u32>,
    w: &super::stats::WorkerStats,
    told: &mut std::collections::HashSet<usize>,
) -> Option<String> {
    let note = slots_note(w.rank, budget_slots?, w.node_slots()?)?;
    told.insert(w.rank).then_some(note)
}

fn slots_note(rank: usize, budget_slots: u32, slots: u32) -> Option<String> {
    (slots < budget_slots).then(|| {
        format!(
            "note: rank {rank} keeps {slots} node slots, fewer than the {budget_slots} --gpu-budget-mb allows: \
             its GPU binds less than the budget in one buffer"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pool_smaller_than_the_budget_is_noted() {
        assert_eq!(slots_note(1, 288, 288), None);
        let note = slots_note(2, 9000, 2356).unwrap();
        assert!(note.starts_with("note: rank 2 keeps 2356 node slots, fewer than the 9000"), "{note}");
    }

    #[test]
    fn orbit_keeps_distance_and_returns() {
        let cam = Camera::framing([0.0; 3], [1.0; 3], 1.0);
        let half = orbit(&cam, 2, 4);
        assert!((half.eye.distance(cam.target) - cam.eye.distance(cam.target)).abs() < 1e-4);
        assert!(half.eye.distance(cam.eye) > 1.0);
    }
}
