//! The frame loop of rank 0: per frame the camera, the jobs, sending, receiving and
//! compositing the tiles, writing the images and the stats lines.

use std::time::Instant;

use anyhow::{bail, Context, Result};
use codec::view::Camera;
use glam::Quat;
use worker::protocol::ToWorker;
use worker::transport::Transport;

use super::jobs::{FrameContext, FrameJobs};
use super::link::{handshake, receive_pixels, Silence};
use super::plan::{frame_outputs, frame_path, save_wall, Plan};
use super::scene::{NspScene, PmScene, Scene};
use super::stats::{worker_stats, MasterStats};
use crate::cli::RenderArgs;
use crate::composite::Image;
use crate::output::{Identity, LineLog};

/// Runs every frame of `tessera render` over `t`, whose rank 0 this process is.
pub(super) fn run(t: &dyn Transport, args: &RenderArgs, plan: &Plan) -> Result<()> {
    // Opened first, so that an unwritable path fails before any work.
    let mut stats = args.stats.as_deref().map(LineLog::create).transpose()?;
    let mut scene = Scene::load(&args.model, args.tile_coding.into(), args)?;
    let grid = &plan.grid;
    let cam = scene.camera(&args.camera, grid)?;
    crate::cli::check_camera(&cam, grid.height)?;
    // Ranks 1..=workers render; with --sorters K the last K-1 ranks help rank 0 sort.
    let workers = t.size() - args.sorters as usize;
    let adapters = handshake(t, args.timeout, grid)?;
    eprintln!("tessera: {} worker(s) ready ({})", workers, adapters.join(", "));
    if let Scene::Pm(PmScene { bytes, .. }) = &scene {
        let model = ToWorker::Model(bytes.clone()).encode();
        t.send_many(&(1..=workers).map(|w| (w, model.clone())).collect::<Vec<_>>());
    }
    if let Scene::Nsp(nsp) = &scene {
        let NspScene { file, .. } = nsp.as_ref();
        let model = ToWorker::NspModel(file.skeleton().to_vec()).encode();
        t.send_many(&(1..=workers).map(|w| (w, model.clone())).collect::<Vec<_>>());
    }

    let mut movie = if crate::movie::is_movie(&args.out) {
        Some(crate::movie::Movie::start(&args.out, grid.width, grid.height, args.fps)?)
    } else {
        None
    };
    let mut costs: Vec<f64> = vec![0.0; grid.tiles()];
    let mut silence = Silence::new(workers, args.timeout);
    for k in 0..args.frames {
        let cam_k = if args.orbit { orbit_by(&cam, k, args.frames, args.orbit_degrees) } else { cam };
        let cam_k = zoom_by(&cam_k, k, args.frames, args.zoom);
        let start = Instant::now();
        let ctx = FrameContext { frame: k, camera: cam_k, grid, workers, args, costs: &costs };
        t.send_many(&scene.announce(&ctx));
        let FrameJobs { messages: msgs, tiles: mut tile_stats, chunks, nsp } = scene.jobs(&ctx)?;
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
        match (&plan.wall, movie.as_mut()) {
            (_, Some(m)) => m.frame(&frame.rgba)?,
            (None, None) => frame.save_png(&out)?,
            (Some(wall), None) => save_wall(wall, &frame, &out)?,
        }
        let write_ms = ms(start);
        eprintln!("frame {}: {} tiles, sort {:.1} ms, {}", k + 1, tile_stats.len(), sort_ms, out.display());

        if let Some(log) = stats.as_mut() {
            let line = MasterStats {
                frame: k,
                rank: 0,
                sort_ms,
                send_ms,
                wait_ms,
                composite_ms,
                write_ms,
                rss_mb: resident_mb(),
                chunks,
                nsp,
                tiles: tile_stats,
            };
            log.line(&serde_json::to_string(&line)?)?;
            worker_lines.sort_by_key(|l| l.rank);
            for l in worker_lines {
                log.line(&serde_json::to_string(&l)?)?;
            }
        }
    }
    let shutdown = ToWorker::Shutdown.encode();
    t.send_many(&(1..t.size()).map(|r| (r, shutdown.clone())).collect::<Vec<_>>());
    if let Some(m) = movie {
        m.finish().with_context(|| format!("cannot write {}", args.out.display()))?;
    }
    Ok(())
}

/// This process's resident memory in MB (Linux: `/proc/self/statm`), for the stats.
fn resident_mb() -> Option<f64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: f64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096.0 / (1 << 20) as f64)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orbit_keeps_distance_and_returns() {
        let cam = Camera::framing([0.0; 3], [1.0; 3], 1.0);
        let half = orbit(&cam, 2, 4);
        assert!((half.eye.distance(cam.target) - cam.eye.distance(cam.target)).abs() < 1e-4);
        assert!(half.eye.distance(cam.eye) > 1.0);
    }
}
