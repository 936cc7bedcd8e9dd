//! `tessera render`: the sort-first frame loop of rank 0.
//!
//! Per frame: place the camera, sort the model into compressed tile submeshes, assign the
//! tiles to workers, send each worker its tiles (non-blocking, all at once), receive the
//! tile pixels, stitch them, write the PNG (or one per display of a tile wall) and a stats
//! line per rank. Without `mpirun` the same loop drives one worker thread over channels.
//!
//! A progressive mesh (`.dpm`) takes another path through the same loop: rank 0 sends the
//! file to every worker once, then per frame only the camera and each worker's tiles; each
//! worker adapts the mesh on its GPU to each tile's sub-frustum and renders it.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use rayon::prelude::*;

use anyhow::{bail, Context, Result};
use clap::Args;
use codec::bft::tile_sort::{self, Boxes, Tile};
use codec::view::{Camera, TileGrid};
use glam::Quat;
use serde::Serialize;
use worker::protocol::{FrameJob, PmFrameJob, TileJob, ToMaster, ToWorker};
use worker::transport::{self, RecvError, Transport};

use crate::args::TileCoding;
use crate::args::{parse_non_negative, parse_pair, parse_positive, parse_seconds, parse_size, CameraArgs};
use crate::composite::{Image, Wall};
use crate::output::{check_distinct, check_extension, Identity, LineLog};
use crate::sort::{load_model, Model};

/// Flags of `tessera render`.
#[derive(Args, Clone, Debug)]
pub struct RenderArgs {
    /// A .bft file, a mesh file (OBJ, PLY, STL; encoded on load), or a progressive mesh
    /// (.dpm, from `tessera pm build`), which the workers adapt per tile on the GPU.
    pub model: PathBuf,
    /// Frame size in pixels, WIDTHxHEIGHT (ignored with --wall, which sets it), at most
    /// 16384 on a side.
    #[arg(long, value_parser = parse_size, default_value = "1920x1080")]
    pub size: (u32, u32),
    /// Tile grid, COLSxROWS.
    #[arg(long, value_parser = parse_pair, default_value = "4x4")]
    pub tiles: (u32, u32),
    #[command(flatten)]
    pub camera: CameraArgs,
    /// Frames to render.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub frames: u32,
    /// Orbit the camera once around the model over the frames.
    #[arg(long)]
    pub orbit: bool,
    /// Output PNG; with several frames, frame-0001.png and so on beside it.
    #[arg(long, default_value = "frame.png")]
    pub out: PathBuf,
    /// Write one JSON line per frame per rank.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Reassign tiles every frame from the costs measured the frame before.
    #[arg(long)]
    pub balance: bool,
    /// How the tiles sent to the workers are entropy-coded: `prefix` (static Huffman codes
    /// per tile) sorts and decodes several times faster; `range` (the adaptive range coder
    /// of `.bft` files) sends about 5% fewer bytes.
    #[arg(long, value_enum, default_value_t = TileCoding::Prefix)]
    pub tile_coding: TileCoding,
    /// A tile wall description (TOML): one PNG per display plus an overview.
    #[arg(long)]
    pub wall: Option<PathBuf>,
    /// Seconds of silence after which a worker counts as dead. Workers send a heartbeat
    /// while they work, so a slow frame is not silence. At least 1.
    #[arg(long, default_value = "60", value_parser = parse_seconds)]
    pub timeout: Duration,
    /// Progressive meshes: the screen-space error bound in pixels.
    #[arg(long, default_value_t = 0.5, value_parser = parse_positive)]
    pub error_px: f32,
    /// Progressive meshes: the normal error's weight, as a fraction of the model's bounding
    /// box diagonal per unit of normal chord (0 ignores normals).
    #[arg(long, default_value_t = 0.0, value_parser = parse_non_negative)]
    pub normal_weight: f32,
    /// Progressive meshes: the LOD falloff outside each tile's sub-frustum (the paper's c_LOD):
    /// the distance used for the error test grows by this factor times the world distance by
    /// which a vertex's bounding sphere lies outside the tile. The paper uses 100 for a whole
    /// screen, against popping when the view turns; a tile's outside is hidden by its scissor
    /// and refined by the neighbouring tile, so the default is steeper: on the dragon at
    /// 1920x1080 in 8x8 tiles, 1000 cuts the triangles summed over the tiles from 4.39M (100)
    /// to 0.84M with the same pixels.
    #[arg(long, default_value_t = 1000.0, value_parser = parse_non_negative)]
    pub c_lod: f32,
    /// Progressive meshes: adaptation passes per tile and frame at most; a tile stops as soon
    /// as a pass changes nothing.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..))]
    pub max_passes: u32,
}

/// Everything checked before any rank talks to another.
struct Plan {
    grid: TileGrid,
    wall: Option<Wall>,
    timeout: Duration,
    /// The inputs' identities, which no output may be.
    inputs: Vec<Identity>,
}

/// Above this many output files the up-front identity check looks only at the first and
/// last frames' names (each frame is checked again as it is written).
const CHECKED_OUTPUTS: u64 = 100_000;

fn plan(args: &RenderArgs) -> Result<Plan> {
    let wall = args.wall.as_deref().map(Wall::load).transpose()?;
    let (w, h) = wall.as_ref().map_or(args.size, Wall::frame_size);
    crate::args::check_frame_size(w as u64, h as u64)?;
    let grid = TileGrid::new(w, h, args.tiles.0, args.tiles.1)?;
    check_extension(&args.out, &["png"], "--out")?;
    if args.timeout < HEARTBEAT * 4 {
        bail!(
            "--timeout must be at least {} s (workers send a heartbeat every {} ms)",
            (HEARTBEAT * 4).as_secs_f64(),
            HEARTBEAT.as_millis()
        );
    }
    // No output may be an input or another output.
    let mut inputs: Vec<&Path> = vec![&args.model];
    inputs.extend(args.wall.as_deref());
    let displays = wall.as_ref().map_or(0, |w| w.columns as u64 * w.rows as u64);
    let per_frame = 1 + displays;
    let frames: Vec<u32> = if per_frame * args.frames as u64 <= CHECKED_OUTPUTS {
        (0..args.frames).collect()
    } else {
        vec![0, args.frames - 1]
    };
    let mut outputs: Vec<PathBuf> =
        frames.iter().flat_map(|&k| frame_outputs(&args.out, k, args.frames, wall.as_ref())).collect();
    outputs.extend(args.stats.clone());
    let outputs: Vec<&Path> = outputs.iter().map(PathBuf::as_path).collect();
    check_distinct(&inputs, &outputs)?;
    let inputs = inputs.iter().filter_map(|p| Identity::of(p).ok()).collect();
    Ok(Plan { grid, wall, timeout: args.timeout, inputs })
}

/// How often a worker says it is alive while it works.
pub const HEARTBEAT: Duration = worker::node::HEARTBEAT;

/// Every file frame `k` writes: the frame, and with a wall each display's image.
fn frame_outputs(out: &Path, k: u32, frames: u32, wall: Option<&Wall>) -> Vec<PathBuf> {
    let path = frame_path(out, k, frames);
    let mut v = vec![path.clone()];
    if let Some(wall) = wall {
        v.extend(
            (0..wall.rows).flat_map(|r| (0..wall.columns).map(move |c| (c, r))).map(|(c, r)| display_path(&path, c, r)),
        );
    }
    v
}

/// The image of display `(c, r)` beside the frame's overview `path`.
fn display_path(path: &Path, c: u32, r: u32) -> PathBuf {
    let stem = path.file_stem().map_or("frame".into(), |s| s.to_string_lossy().into_owned());
    path.with_file_name(format!("{stem}-display-{c}-{r}.png"))
}

/// Runs `tessera render` in whichever role this process has.
pub fn run(args: &RenderArgs) -> Result<()> {
    let plan = plan(args)?;
    if transport::launched_by_mpirun() {
        let mpi = transport::Mpi::init().context(
            "MPI is already initialized, or cannot serialize calls from two threads (MPI_THREAD_SERIALIZED)",
        )?;
        if mpi.rank() > 0 {
            return worker::node::run(&mpi).map_err(anyhow::Error::msg);
        }
        if mpi.size() < 2 {
            bail!("run with at least 2 ranks: rank 0 sorts and composites, ranks 1.. render");
        }
        // Rank 0: any error must end every rank, not leave the workers waiting.
        if let Err(e) = master(&mpi, args, &plan) {
            eprintln!("error: {e:#}");
            mpi.abort(1);
        }
        Ok(())
    } else {
        let mut ranks = transport::local_ranks(2);
        let worker_end = ranks.pop().expect("two ranks");
        let handle = std::thread::spawn(move || worker::node::run(&worker_end));
        // On an error the worker thread may be stuck (that may be the error): return at once,
        // and the process's exit ends it, so that --timeout bounds the run.
        master(&ranks[0], args, &plan)?;
        drop(ranks);
        let worker_result = handle.join().map_err(|_| anyhow::anyhow!("the worker thread panicked"))?;
        worker_result.map_err(anyhow::Error::msg)
    }
}

/// One stats line of rank 0.
#[derive(Serialize)]
struct MasterStats {
    frame: u32,
    rank: usize,
    sort_ms: f64,
    send_ms: f64,
    wait_ms: f64,
    composite_ms: f64,
    write_ms: f64,
    tiles: Vec<TileStats>,
}

#[derive(Serialize)]
struct TileStats {
    index: u32,
    worker: usize,
    triangles: u32,
    bytes: usize,
    /// Bytes the tile's triangles need as independent triangles (36 each).
    tri_bytes: usize,
    /// Bytes of border normals sent with the tile.
    normal_bytes: usize,
}

/// One stats line of a worker, as reported back to rank 0.
#[derive(Serialize)]
struct WorkerStats {
    frame: u32,
    rank: usize,
    decode_ms: f64,
    adapt_ms: f64,
    upload_ms: f64,
    render_ms: f64,
    readback_ms: f64,
    tiles: Vec<WorkerTileStats>,
}

#[derive(Serialize)]
struct WorkerTileStats {
    index: u32,
    triangles: u32,
    decode_ms: f64,
    adapt_ms: f64,
    upload_ms: f64,
    render_ms: f64,
    readback_ms: f64,
}

/// What rank 0 renders: a BFT model it sorts every frame, or a progressive mesh the workers
/// adapt themselves.
enum Scene {
    Bft { model: Box<Model>, normals: FullNormals, sorter: tile_sort::Sorter, boxes: Box<Boxes> },
    Pm { bytes: Vec<u8>, bbox: ([f32; 3], [f32; 3]) },
}

impl Scene {
    fn load(path: &Path, coding: codec::bft::Coding) -> Result<Scene> {
        let mut magic = [0u8; 8];
        let is_dpm = std::fs::File::open(path)
            .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut magic))
            .is_ok_and(|()| magic == codec::pm::format::MAGIC);
        if !is_dpm {
            let model = load_model(path, codec::bft::EncodeOptions::default())?;
            let normals = FullNormals::of(&model);
            return Ok(Scene::Bft {
                model: Box::new(model),
                normals,
                sorter: tile_sort::Sorter::new(coding),
                boxes: Box::default(),
            });
        }
        let bytes = crate::commands::read_input(path)?;
        // Decoded here once, so that a corrupt file fails before any worker sees it.
        let pm = codec::pm::format::decode(&bytes).with_context(|| format!("{}", path.display()))?.pm;
        let (lo, hi) = crate::pm::bbox(&pm.positions);
        if !lo.iter().chain(&hi).all(|v| v.is_finite()) {
            bail!("{}: a bad model: its bounding box {lo:?} .. {hi:?} is not finite", path.display());
        }
        Ok(Scene::Pm { bytes, bbox: (lo, hi) })
    }

    fn camera(&self, args: &CameraArgs, grid: &TileGrid) -> Result<Camera> {
        match self {
            Scene::Bft { model, .. } => model.camera(args, grid),
            Scene::Pm { bbox: (lo, hi), .. } => args.camera(*lo, *hi, grid.aspect()),
        }
    }
}

fn master(t: &dyn Transport, args: &RenderArgs, plan: &Plan) -> Result<()> {
    // Opened first, so that an unwritable path fails before any work.
    let mut stats = args.stats.as_deref().map(LineLog::create).transpose()?;
    let mut scene = Scene::load(&args.model, args.tile_coding.into())?;
    let grid = &plan.grid;
    let cam = scene.camera(&args.camera, grid)?;
    crate::args::check_camera(&cam, grid.height)?;
    let workers = t.size() - 1;
    let adapters = handshake(t, plan.timeout, grid)?;
    eprintln!("tessera: {} worker(s) ready ({})", workers, adapters.join(", "));
    if let Scene::Pm { bytes, .. } = &scene {
        let model = ToWorker::Model(bytes.clone()).encode();
        t.send_many(&(1..=workers).map(|w| (w, model.clone())).collect::<Vec<_>>());
    }

    let mut costs: Vec<f64> = vec![0.0; grid.tiles()];
    let mut silence = Silence::new(workers, plan.timeout);
    for k in 0..args.frames {
        let cam_k = if args.orbit { orbit(&cam, k, args.frames) } else { cam };
        let vp = cam_k.view_proj(grid.aspect());

        let start = Instant::now();
        let (msgs, mut tile_stats) = match &mut scene {
            Scene::Bft { model, normals, sorter, boxes } => {
                bft_jobs(model, normals, sorter, boxes, vp, grid, k, workers, args, &costs)?
            }
            Scene::Pm { bbox: (lo, hi), .. } => pm_jobs(&cam_k, grid, k, workers, args, &costs, *lo, *hi),
        };
        let answering: Vec<usize> = msgs.iter().map(|(w, _)| *w).collect();
        let sort_ms = ms(start);

        let start = Instant::now();
        t.send_many(&msgs);
        let send_ms = ms(start);

        let start = Instant::now();
        let mut frame = Image::new(grid.width, grid.height);
        let mut composite_ms = 0.0;
        let mut worker_lines = Vec::new();
        silence.expect(&answering);
        for _ in 0..answering.len() {
            let (rank, pixels) = receive_pixels(t, k, &mut silence)?;
            let c = Instant::now();
            for p in &pixels {
                frame.blit(p.rect, &p.rgba).with_context(|| format!("rank {rank}, tile {}", p.index))?;
                costs[p.index as usize] = p.times.total_ms();
                if let Some(s) = tile_stats.iter_mut().find(|s| s.index == p.index) {
                    s.triangles = p.triangles;
                }
            }
            composite_ms += ms(c);
            worker_lines.push(worker_stats(k, rank, &pixels));
        }
        let wait_ms = ms(start) - composite_ms;

        let start = Instant::now();
        let out = frame_path(&args.out, k, args.frames);
        for p in frame_outputs(&args.out, k, args.frames, plan.wall.as_ref()) {
            if Identity::of(&p).is_ok_and(|id| plan.inputs.contains(&id)) {
                bail!("the output {} is the same file as an input; refusing to overwrite it", p.display());
            }
        }
        match &plan.wall {
            None => frame.save_png(&out)?,
            Some(wall) => save_wall(wall, &frame, &out)?,
        }
        let write_ms = ms(start);
        eprintln!("frame {}: {} tiles, sort {:.1} ms, {}", k + 1, tile_stats.len(), sort_ms, out.display());

        if let Some(log) = stats.as_mut() {
            let line =
                MasterStats { frame: k, rank: 0, sort_ms, send_ms, wait_ms, composite_ms, write_ms, tiles: tile_stats };
            log.line(&serde_json::to_string(&line)?)?;
            worker_lines.sort_by_key(|l| l.rank);
            for l in worker_lines {
                log.line(&serde_json::to_string(&l)?)?;
            }
        }
    }
    let shutdown = ToWorker::Shutdown.encode();
    t.send_many(&(1..=workers).map(|w| (w, shutdown.clone())).collect::<Vec<_>>());
    Ok(())
}

/// When each worker was last heard from, for telling a dead worker from a busy one: a worker
/// sends heartbeats while it works, so only silence longer than the timeout counts.
struct Silence {
    timeout: Duration,
    last: Vec<Instant>,
    /// The workers whose answer the current wait needs.
    pending: Vec<bool>,
}

impl Silence {
    fn new(workers: usize, timeout: Duration) -> Silence {
        Silence { timeout, last: vec![Instant::now(); workers + 1], pending: vec![false; workers + 1] }
    }

    /// Starts a wait for answers from `ranks`, counting their silence from now.
    fn expect(&mut self, ranks: &[usize]) {
        let now = Instant::now();
        for &r in ranks {
            self.pending[r] = true;
            self.last[r] = now;
        }
    }

    fn heard(&mut self, rank: usize) {
        if let Some(t) = self.last.get_mut(rank) {
            *t = Instant::now();
        }
    }

    fn answered(&mut self, rank: usize) {
        if let Some(p) = self.pending.get_mut(rank) {
            *p = false;
        }
    }

    /// How long to wait for the next message, and the worker silent the longest.
    fn next_wait(&self) -> (Duration, usize) {
        let (rank, last) = (1..self.last.len())
            .filter(|&r| self.pending[r])
            .map(|r| (r, self.last[r]))
            .min_by_key(|&(_, t)| t)
            .unwrap_or((0, Instant::now()));
        (self.timeout.saturating_sub(last.elapsed()), rank)
    }
}

/// A frame's messages to the workers (by rank) and its tile lines for the stats.
type FrameJobs = (Vec<(usize, Vec<u8>)>, Vec<TileStats>);

/// One frame of a BFT model: the tile sort, then each worker's tiles with their border
/// normals, as messages.
#[allow(clippy::too_many_arguments)]
fn bft_jobs(
    model: &Model,
    normals: &FullNormals,
    sorter: &mut tile_sort::Sorter,
    boxes: &mut Boxes,
    vp: glam::Mat4,
    grid: &TileGrid,
    k: u32,
    workers: usize,
    args: &RenderArgs,
    costs: &[f64],
) -> Result<FrameJobs> {
    tile_sort::boxes_into(&model.tiles, vp, grid, boxes);
    let tiles = sorter.sort(&model.tiles, boxes, grid)?;
    let borders = border_normals(model, boxes, &tiles, grid, normals);
    let indices: Vec<usize> = tiles.iter().map(|t| t.index).collect();
    let owner = assign(&indices, workers, args.balance.then_some(costs));
    let mut jobs: Vec<FrameJob> = (0..workers)
        .map(|_| FrameJob {
            frame: k,
            width: grid.width,
            height: grid.height,
            view_proj: vp.to_cols_array(),
            tiles: vec![],
        })
        .collect();
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
            bft: tile.bytes,
            normals,
        });
    }
    let msgs = jobs.into_iter().enumerate().map(|(i, j)| (i + 1, ToWorker::Frame(j).encode())).collect();
    Ok((msgs, tile_stats))
}

/// One frame of a progressive mesh: every tile of the grid goes to a worker with the camera;
/// nothing of the mesh is sent. The tiles' triangle counts come back with the pixels.
#[allow(clippy::too_many_arguments)]
fn pm_jobs(
    cam: &Camera,
    grid: &TileGrid,
    k: u32,
    workers: usize,
    args: &RenderArgs,
    costs: &[f64],
    lo: [f32; 3],
    hi: [f32; 3],
) -> FrameJobs {
    let view = codec::pm::Viewpoint::new(cam, grid.width, grid.height, args.error_px);
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
    let owner = assign(&indices, workers, args.balance.then_some(costs));
    let mut jobs: Vec<PmFrameJob> = (0..workers)
        .map(|_| PmFrameJob {
            frame: k,
            width: grid.width,
            height: grid.height,
            view_proj: view.view_proj.to_cols_array(),
            eye: view.eye.to_array(),
            pixels_per_unit: view.pixels_per_unit,
            error_px: view.error_px,
            c_lod: args.c_lod,
            attribute_scale: args.normal_weight * diagonal,
            max_passes: args.max_passes,
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
    let msgs = jobs
        .into_iter()
        .enumerate()
        .filter(|(_, j)| !j.tiles.is_empty())
        .map(|(i, j)| (i + 1, ToWorker::PmFrame(j).encode()))
        .collect();
    (msgs, tile_stats)
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

/// Waits for every worker's `Ready`; a `Failed` or silence ends the run with its reason.
fn handshake(t: &dyn Transport, timeout: Duration, grid: &TileGrid) -> Result<Vec<String>> {
    let mut adapters = vec![String::new(); t.size()];
    let mut ready = vec![false; t.size()];
    ready[0] = true;
    let mut last = Instant::now();
    while ready.iter().any(|r| !r) {
        let (rank, bytes) = match t.recv(timeout.saturating_sub(last.elapsed())) {
            Ok(m) => m,
            Err(RecvError::Timeout) => {
                bail!("{} did not start within {:.0} s", missing(&ready), timeout.as_secs_f64())
            }
            Err(RecvError::Disconnected) => bail!("{} exited before it was ready", missing(&ready)),
        };
        match ToMaster::decode(&bytes).with_context(|| format!("bad message from rank {rank}"))? {
            // Workers still starting (a device can take seconds to open) say so.
            ToMaster::Heartbeat => last = Instant::now(),
            ToMaster::Ready { adapter, max_texture_side } => {
                if grid.width > max_texture_side || grid.height > max_texture_side {
                    bail!(
                        "the {}x{} frame does not fit rank {rank}'s adapter ({adapter}), whose largest texture side is {max_texture_side}",
                        grid.width,
                        grid.height
                    );
                }
                ready[rank] = true;
                adapters[rank] = format!("rank {rank}: {adapter}");
            }
            ToMaster::Failed { reason } => bail!("rank {rank} failed: {reason}"),
            other => bail!("rank {rank} sent {other:?} before it was ready"),
        }
    }
    Ok(adapters.split_off(1))
}

fn missing(flags: &[bool]) -> String {
    let ranks: Vec<String> = flags.iter().enumerate().filter(|(_, &f)| !f).map(|(r, _)| r.to_string()).collect();
    format!("rank {}", ranks.join(", rank "))
}

/// The next worker's pixels for `frame`; heartbeats in between keep a busy worker alive, and
/// a worker silent for the whole timeout ends the run.
fn receive_pixels(
    t: &dyn Transport,
    frame: u32,
    silence: &mut Silence,
) -> Result<(usize, Vec<worker::protocol::TilePixels>)> {
    loop {
        let (wait, quiet) = silence.next_wait();
        let (rank, bytes) = match t.recv(wait) {
            Ok(m) => m,
            Err(RecvError::Timeout) => bail!(
                "rank {quiet} sent nothing for {:.0} s during frame {} (--timeout); counting it as dead",
                silence.timeout.as_secs_f64(),
                frame + 1
            ),
            Err(RecvError::Disconnected) => bail!("the worker exited during frame {}", frame + 1),
        };
        silence.heard(rank);
        match ToMaster::decode(&bytes).with_context(|| format!("bad message from rank {rank}"))? {
            ToMaster::Heartbeat => continue,
            ToMaster::Pixels { frame: f, tiles } if f == frame => {
                silence.answered(rank);
                return Ok((rank, tiles));
            }
            ToMaster::Pixels { frame: f, .. } => bail!("rank {rank} answered frame {f} during frame {frame}"),
            ToMaster::Failed { reason } => bail!("rank {rank} failed: {reason}"),
            ToMaster::Ready { .. } => bail!("rank {rank} sent Ready twice"),
        }
    }
}

fn worker_stats(frame: u32, rank: usize, pixels: &[worker::protocol::TilePixels]) -> WorkerStats {
    let sum = |f: fn(&worker::protocol::TileTimes) -> f64| pixels.iter().map(|p| f(&p.times)).sum();
    WorkerStats {
        frame,
        rank,
        decode_ms: sum(|t| t.decode_ms),
        adapt_ms: sum(|t| t.adapt_ms),
        upload_ms: sum(|t| t.upload_ms),
        render_ms: sum(|t| t.render_ms),
        readback_ms: sum(|t| t.readback_ms),
        tiles: pixels
            .iter()
            .map(|p| WorkerTileStats {
                index: p.index,
                triangles: p.triangles,
                decode_ms: p.times.decode_ms,
                adapt_ms: p.times.adapt_ms,
                upload_ms: p.times.upload_ms,
                render_ms: p.times.render_ms,
                readback_ms: p.times.readback_ms,
            })
            .collect(),
    }
}

/// The camera of frame `k` of `n` on a full orbit around the target, about the up axis.
pub fn orbit(cam: &Camera, k: u32, n: u32) -> Camera {
    let angle = std::f32::consts::TAU * k as f32 / n as f32;
    let rot = Quat::from_axis_angle(cam.up.normalize(), angle);
    Camera { eye: cam.target + rot * (cam.eye - cam.target), ..*cam }
}

/// `frame.png` for one frame; `frame-0001.png`, ... for several.
pub fn frame_path(out: &Path, k: u32, frames: u32) -> PathBuf {
    if frames == 1 {
        return out.to_path_buf();
    }
    let stem = out.file_stem().map_or("frame".into(), |s| s.to_string_lossy().into_owned());
    out.with_file_name(format!("{stem}-{:04}.png", k + 1))
}

fn save_wall(wall: &Wall, frame: &Image, out: &Path) -> Result<()> {
    let (displays, overview) = wall.split(frame);
    for (i, d) in displays.iter().enumerate() {
        let (c, r) = (i as u32 % wall.columns, i as u32 / wall.columns);
        d.save_png(&display_path(out, c, r))?;
    }
    overview.save_png(out)
}

/// Tiles (by index) to workers (ranks `1..=workers`), one entry per tile in `tiles`' order. By
/// default tile `i` goes to worker `1 + i % workers`, so each worker keeps its tiles from
/// frame to frame. With `costs` (last frame's per-tile time), tiles go longest first to
/// the least loaded worker, in the manner of Equalizer's load equalizer; a tile without a
/// cost yet counts as the mean.
pub fn assign(tiles: &[usize], workers: usize, costs: Option<&[f64]>) -> Vec<usize> {
    let Some(costs) = costs else {
        return tiles.iter().map(|t| 1 + t % workers).collect();
    };
    let known: Vec<f64> = tiles.iter().map(|&t| costs[t]).filter(|&c| c > 0.0).collect();
    let mean = if known.is_empty() { 1.0 } else { known.iter().sum::<f64>() / known.len() as f64 };
    let cost = |&t: &usize| if costs[t] > 0.0 { costs[t] } else { mean };
    let mut order: Vec<usize> = (0..tiles.len()).collect();
    order.sort_by(|&a, &b| cost(&tiles[b]).total_cmp(&cost(&tiles[a])).then(a.cmp(&b)));
    let mut load = vec![0.0f64; workers];
    let mut owner = vec![0; tiles.len()];
    for i in order {
        let w = (0..workers).min_by(|&a, &b| load[a].total_cmp(&load[b])).expect("at least one worker");
        load[w] += cost(&tiles[i]);
        owner[i] = w + 1;
    }
    owner
}

/// The whole mesh's vertex normals, and which slots are duplicates (or have them), whose
/// normals a tile never computes alone.
struct FullNormals {
    normals: Vec<[f32; 3]>,
    duplicated: Vec<bool>,
}

impl FullNormals {
    fn of(model: &Model) -> FullNormals {
        let d = &model.tiles.decoded;
        let mut duplicated = vec![false; d.positions.len()];
        for &(slot, src) in &d.duplicates {
            duplicated[slot as usize] = true;
            duplicated[src as usize] = true;
        }
        FullNormals { normals: worker::RenderMesh::from_decoded(d).normals, duplicated }
    }
}

/// The normals each tile needs from the whole mesh: a worker computes a vertex's normal
/// from the tile's triangles, which is the whole mesh's normal only when every triangle of
/// the vertex lies in the tile and the vertex has a single slot. The rest are sent.
fn border_normals(
    model: &Model,
    boxes: &Boxes,
    tiles: &[Tile],
    grid: &TileGrid,
    full: &FullNormals,
) -> Vec<Vec<(u32, [f32; 3])>> {
    let (normals, duplicated) = (&full.normals, &full.duplicated);
    tiles
        .par_iter()
        .map(|tile| {
            let (c, r) = ((tile.index % grid.cols as usize) as u16, (tile.index / grid.cols as usize) as u16);
            tile.slots
                .iter()
                .enumerate()
                .filter(|(_, &s)| duplicated[s as usize] || !boxes.whole_fan_in(&model.tiles, s, c, r))
                .map(|(i, &s)| (i as u32, normals[s as usize]))
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_robin_and_balanced_assignment() {
        let tiles = [0, 1, 2, 5, 6];
        assert_eq!(assign(&tiles, 2, None), vec![1, 2, 1, 2, 1]);
        // More workers than tiles: the extra ones get nothing.
        assert_eq!(assign(&tiles[..2], 4, None), vec![1, 2]);
        let mut costs = vec![0.0; 8];
        costs[0] = 10.0;
        costs[1] = 1.0;
        costs[2] = 1.0;
        costs[5] = 1.0;
        costs[6] = 7.0;
        // LPT: 10 -> w1, 7 -> w2, then the ones fill w2 (7 + 1 + 1 + 1 = 10).
        assert_eq!(assign(&tiles, 2, Some(&costs)), vec![1, 2, 2, 2, 2]);
    }

    #[test]
    fn frames_are_numbered() {
        assert_eq!(frame_path(Path::new("out/f.png"), 0, 1), PathBuf::from("out/f.png"));
        assert_eq!(frame_path(Path::new("out/f.png"), 2, 10), PathBuf::from("out/f-0003.png"));
    }

    #[test]
    fn orbit_keeps_distance_and_returns() {
        let cam = Camera::framing([0.0; 3], [1.0; 3], 1.0);
        let half = orbit(&cam, 2, 4);
        assert!((half.eye.distance(cam.target) - cam.eye.distance(cam.target)).abs() < 1e-4);
        assert!(half.eye.distance(cam.eye) > 1.0);
    }
}
