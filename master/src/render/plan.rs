//! What `tessera render` checks before any rank talks to another, and the names of the files
//! each frame writes.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use codec::view::TileGrid;
use glam::Vec3;

use crate::camera::{CameraSpec, StereoOutput};
use crate::cli::RenderArgs;
use crate::composite::Image;
use crate::output::{check_distinct, check_extension, Identity};
use crate::wall::Wall;

/// The run, resolved from the flags once and checked before any rank talks to another:
/// what the frame loop, the scenes, and the sorter and display ranks read (never the flags).
pub struct Plan {
    /// The model file.
    pub model: PathBuf,
    /// How rank 0 codes a BFT model's tiles.
    pub coding: codec::bft::Coding,
    /// `--pixel-codec`: how workers code the tiles' pixels they send.
    pub pixel_codec: protocol::PixelCodec,
    /// The camera asked for; what it leaves out frames the model.
    pub camera: CameraSpec,
    /// Frames to render.
    pub frames: u32,
    /// `--orbit` and its degrees a frame (0: a full turn over the frames), and `--zoom`.
    pub orbit: bool,
    pub orbit_degrees: f32,
    pub zoom: f32,
    /// `--stereo`: the eyes' separation.
    pub separation: Option<f32>,
    pub out: PathBuf,
    pub fps: f32,
    pub stats: Option<PathBuf>,
    /// Frames in flight: one with `--balance` (it sorts from the frame before's costs) or
    /// with sorters (they send one frame at a time), else `--frames-in-flight`.
    pub depth: usize,
    /// How long a silent rank may stay silent before it counts as dead.
    pub timeout: std::time::Duration,
    pub balance: bool,
    pub decode_only: bool,
    /// The ranks that share the sort (`--sorters`, rank 0 included) and own the wall's
    /// displays (`--display-ranks`).
    pub sorters: u8,
    pub display_ranks: u32,
    /// Bytes of rank 0's chunk cache (`--cache-mb`) and of each worker's (`--worker-cache-mb`).
    pub cache_bytes: usize,
    pub worker_cache_bytes: u64,
    /// A progressive mesh's and an `.nsp` model's view: the screen error in pixels, and the
    /// progressive mesh's adaptation settings.
    pub error_px: f32,
    pub pm: PmSettings,
    pub grid: TileGrid,
    /// On a wall whose displays each have a frame, each display's grid.
    pub display_grids: Vec<TileGrid>,
    pub wall: Option<Wall>,
    /// `--eye-path`: the eye of every frame.
    pub eyes: Option<Vec<Vec3>>,
    /// `--stereo`: how the pairs are written.
    pub stereo: Option<StereoOutput>,
    /// `--display-ranks`: display ranks write the displays, rank 0 no overview.
    pub direct: bool,
    /// The inputs' identities, which no output may be.
    pub inputs: Vec<Identity>,
    /// `--control`: a live run served on this address, with the token clients must present
    /// (`--control-token-file`).
    pub control: Option<(std::net::SocketAddr, Option<String>)>,
    /// `--eye-stream`: where a live run's eye positions come from.
    pub eye_stream: Option<crate::cli::EyeStream>,
    /// `--present`: a live run shown in windows.
    pub present: bool,
    /// `--no-frame-reuse`: a frame whose views are the frame before's is made again.
    pub no_frame_reuse: bool,
}
/// How the workers adapt a progressive mesh (`render`'s PM flags, in bytes where they are
/// sizes).
#[derive(Clone, Copy, Debug)]
pub struct PmSettings {
    pub normal_weight: f32,
    pub c_lod: f32,
    pub max_passes: u32,
    /// Graphics memory each worker's adaptation may take, and of it the node pool's (out of
    /// core), in bytes.
    pub gpu_budget: u64,
    pub gpu_nodes: Option<u64>,
    pub occlusion: bool,
}

/// Above this many output files the up-front identity check looks only at the first and
/// last frames' names (each frame is checked again as it is written), so that start-up does
/// not grow with `--frames`: frames' names differ in their numbers, so only an input can
/// clash with a later frame, and that is what the per-frame check catches.
const CHECKED_OUTPUTS: u64 = 1_000;

/// Checks the flags that need more than their own value (the wall, the grid against the
/// frame, outputs against inputs); every rank runs it before MPI starts.
pub fn plan(args: &RenderArgs) -> Result<Plan> {
    plan_with(args, false)
}

/// [`plan`] for `tessera view`: a live run in a window.
pub fn plan_view(args: &RenderArgs) -> Result<Plan> {
    plan_with(args, true)
}

fn plan_with(args: &RenderArgs, window: bool) -> Result<Plan> {
    let wall = args.wall.as_deref().map(Wall::load).transpose()?;
    let (w, h) = wall.as_ref().map_or(args.size, Wall::frame_size);
    crate::cli::check_frame_size(w as u64, h as u64)?;
    let grid = TileGrid::new(w, h, args.tiles.0, args.tiles.1)?;
    let movie = crate::movie::is_movie(&args.out);
    let stereo = args.stereo.map(|_| args.stereo_output);
    let placed = wall.as_ref().is_some_and(Wall::placed);
    let control = live_run(args, window, movie, wall.as_ref())?;
    if args.eye_path.is_some() && !placed {
        bail!("--eye-path needs a --wall placed in the world (a plane, or its displays' corners)");
    }
    if placed {
        let c = &args.camera;
        if c.eye.is_some() || c.target.is_some() || c.up.is_some() || c.fovy.is_some() || c.shift.is_some() {
            bail!(
                "a wall placed in the world sets the eye, target, up, field of view and shift; leave out those flags"
            );
        }
        if args.orbit || args.zoom != 1.0 {
            bail!("a wall placed in the world is still: the eye moves with --eye-path, not --orbit or --zoom");
        }
        if wall.as_ref().is_some_and(|w| w.eye.is_none()) && args.eye_path.is_none() {
            bail!("a wall placed in the world needs an eye: `eye = [x, y, z]` in the wall file, or --eye-path");
        }
    }
    let mut display_grids = Vec::new();
    if let Some(w) = wall.as_ref().filter(|w| w.per_display()) {
        for d in &w.displays {
            let [x0, y0, x1, y1] = d.rect;
            let grid = TileGrid::new(x1 - x0, y1 - y0, args.tiles.0, args.tiles.1)
                .with_context(|| format!("display {} has its own frame, cut into --tiles", d.name))?;
            display_grids.push(grid);
        }
        if args.balance {
            bail!("--balance and a wall whose displays each have a frame do not go together yet");
        }
        if args.display_ranks > 0 {
            bail!("--display-ranks and a wall whose displays each have a frame do not go together yet");
        }
    }
    let eyes = match args.eye_path.as_deref() {
        Some(path) => {
            let eyes = read_eyes(path, args.frames)?;
            if let Some(wall) = &wall {
                for &(line, eye) in &eyes {
                    wall.check_eye(eye).with_context(|| format!("{}: line {line}", path.display()))?;
                }
            }
            Some(eyes.into_iter().map(|(_, e)| e).collect())
        }
        None => None,
    };
    let direct = args.display_ranks > 0;
    if direct {
        let Some(w) = &wall else {
            bail!("--display-ranks needs a --wall whose displays they own");
        };
        if args.display_ranks as usize > w.displays.len() {
            bail!("--display-ranks {} is more than the wall's {} displays", args.display_ranks, w.displays.len());
        }
        if args.sorters > 1 {
            bail!("--display-ranks and --sorters do not go together yet");
        }
        if stereo == Some(StereoOutput::SideBySide) {
            bail!("display ranks write each eye's displays separately: leave out --stereo-output side-by-side");
        }
    }
    if args.out.as_os_str() == "-" {
        let images = args.frames as u64 * if stereo == Some(StereoOutput::Separate) { 2 } else { 1 };
        if images > 1 || wall.is_some() {
            bail!(
                "--out - takes one image; for {} name a file (its images are numbered) or a movie",
                if wall.is_some() { "a wall's displays" } else { "several images" }
            );
        }
    }
    if movie && stereo == Some(StereoOutput::Separate) {
        bail!("a movie holds a stereo pair side by side: add --stereo-output side-by-side, or write PNGs");
    }
    if movie {
        if wall.is_some() {
            anyhow::bail!("a wall writes one image per display: --out must be a .png with --wall");
        }
        crate::movie::check_ffmpeg()?;
    } else {
        let mut allowed = vec!["png"];
        allowed.extend(crate::movie::EXTENSIONS);
        check_extension(&args.out, &allowed, "--out")?;
    }
    if args.decode_only && codec::kind::ModelKind::of(&args.model) == codec::kind::ModelKind::Dpm {
        anyhow::bail!("--decode-only applies to sorted models; a progressive mesh (.dpm) has no tiles to decode");
    }
    if args.decode_only && codec::kind::ModelKind::of(&args.model) == codec::kind::ModelKind::Nsp {
        anyhow::bail!("--decode-only applies to sorted models; an .nsp model has no tiles to decode");
    }
    // No output may be an input or another output.
    let mut inputs: Vec<&Path> = vec![&args.model];
    inputs.extend(args.wall.as_deref());
    let displays = wall.as_ref().map_or(0, |w| w.displays.len() as u64);
    let per_frame = (1 + displays) * if stereo == Some(StereoOutput::Separate) { 2 } else { 1 };
    let frames: Vec<u32> = if movie {
        vec![0]
    } else if per_frame * args.frames as u64 <= CHECKED_OUTPUTS {
        (0..args.frames).collect()
    } else {
        vec![0, args.frames - 1]
    };
    let mut outputs: Vec<PathBuf> =
        frames.iter().flat_map(|&k| frame_outputs(&args.out, k, args.frames, wall.as_ref(), stereo, direct)).collect();
    outputs.extend(args.stats.clone());
    let outputs: Vec<&Path> = outputs.iter().map(PathBuf::as_path).collect();
    check_distinct(&inputs, &outputs)?;
    let inputs = inputs.iter().filter_map(|p| Identity::of(p).ok()).collect();
    const MB: f64 = (1 << 20) as f64;
    Ok(Plan {
        model: args.model.clone(),
        coding: args.tile_coding.into(),
        pixel_codec: args.pixel_codec,
        camera: args.camera.spec(),
        frames: args.frames,
        orbit: args.orbit,
        orbit_degrees: args.orbit_degrees,
        zoom: args.zoom,
        separation: args.stereo,
        out: args.out.clone(),
        fps: args.fps,
        stats: args.stats.clone(),
        depth: if args.balance || args.sorters > 1 { 1 } else { args.frames_in_flight as usize },
        timeout: args.timeout,
        balance: args.balance,
        decode_only: args.decode_only,
        sorters: args.sorters,
        display_ranks: args.display_ranks,
        cache_bytes: args.cache_mb as usize * (1 << 20),
        worker_cache_bytes: args.worker_cache_mb * (1 << 20),
        error_px: args.error_px,
        pm: PmSettings {
            normal_weight: args.normal_weight,
            c_lod: args.c_lod,
            max_passes: args.max_passes,
            gpu_budget: (args.gpu_budget_mb as f64 * MB) as u64,
            gpu_nodes: args.gpu_nodes_mb.map(|mb| (mb as f64 * MB) as u64),
            occlusion: args.occlusion,
        },
        grid,
        display_grids,
        wall,
        eyes,
        stereo,
        direct,
        inputs,
        control,
        eye_stream: args.eye_stream.clone(),
        present: args.present,
        no_frame_reuse: args.no_frame_reuse,
    })
}

/// The eyes of `--eye-path` with their line numbers: one `x y z` (or `x,y,z`) line per
/// frame, at least `frames` of them (blank lines and `#` comments skipped).
fn read_eyes(path: &Path, frames: u32) -> Result<Vec<(usize, Vec3)>> {
    let bytes = crate::model::read_input(path)?;
    let text = String::from_utf8(bytes).map_err(|_| anyhow::anyhow!("{}: not UTF-8 text", path.display()))?;
    let mut eyes = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let eye =
            crate::cli::parse_point(line).map_err(|e| anyhow::anyhow!("{}: line {}: {e}", path.display(), i + 1))?;
        eyes.push((i + 1, eye));
    }
    if eyes.len() < frames as usize {
        bail!("{}: {} eye positions for {frames} frames", path.display(), eyes.len());
    }
    Ok(eyes)
}

/// Every file frame `k` writes: the frame, and with a wall each display's image (and no
/// overview with display ranks, `direct`); for separate stereo images, each of those for the
/// left and the right eye.
pub(super) fn frame_outputs(
    out: &Path,
    k: u32,
    frames: u32,
    wall: Option<&Wall>,
    stereo: Option<StereoOutput>,
    direct: bool,
) -> Vec<PathBuf> {
    let path = frame_path(out, k, frames);
    let paths = match stereo {
        Some(StereoOutput::Separate) => vec![eye_path(&path, "left"), eye_path(&path, "right")],
        _ => vec![path],
    };
    let mut v = Vec::new();
    for path in paths {
        if let Some(wall) = wall {
            v.extend(wall.displays.iter().map(|d| display_path(&path, &d.name)));
        }
        if !direct {
            v.push(path);
        }
    }
    v
}

/// The image of one eye (`left` or `right`) beside `path`.
pub(super) fn eye_path(path: &Path, eye: &str) -> PathBuf {
    let stem = path.file_stem().map_or("frame".into(), |s| s.to_string_lossy().into_owned());
    path.with_file_name(format!("{stem}-{eye}.png"))
}

/// The image of display `name` beside the frame's overview `path`.
pub(super) fn display_path(path: &Path, name: &str) -> PathBuf {
    let stem = path.file_stem().map_or("frame".into(), |s| s.to_string_lossy().into_owned());
    path.with_file_name(format!("{stem}-display-{name}.png"))
}

/// `frame.png` for one frame; `frame-0001.png`, ... for several; a movie is one file.
pub fn frame_path(out: &Path, k: u32, frames: u32) -> PathBuf {
    if frames == 1 || crate::movie::is_movie(out) {
        return out.to_path_buf();
    }
    let stem = out.file_stem().map_or("frame".into(), |s| s.to_string_lossy().into_owned());
    out.with_file_name(format!("{stem}-{:04}.png", k + 1))
}

/// Writes one PNG per display of `wall`, and the overview at `out`; with `right`, a stereo
/// pair side by side (`frame` the left eye).
pub(super) fn save_wall(wall: &Wall, frame: &Image, right: Option<&Image>, out: &Path) -> Result<()> {
    let (mut displays, mut overview) = wall.split(frame);
    if let Some(right) = right {
        let (r_displays, r_overview) = wall.split(right);
        displays = displays.iter().zip(&r_displays).map(|(l, r)| l.beside(r)).collect();
        overview = overview.beside(&r_overview);
    }
    for (d, image) in wall.displays.iter().zip(&displays) {
        image.save_png(&display_path(out, &d.name))?;
    }
    overview.save_png(out)
}

/// A live run's checks (`--control`, or `tessera view` with `window`): it takes its frames
/// from its commands, so it refuses the flags that make frames of their own; and its control
/// port's address with the token clients must present.
fn live_run(
    args: &RenderArgs,
    window: bool,
    movie: bool,
    wall: Option<&Wall>,
) -> Result<Option<(std::net::SocketAddr, Option<String>)>> {
    let live = match (window, args.present, args.control) {
        (true, _, _) => Some("tessera view"),
        (false, true, _) => Some("--present"),
        (false, false, Some(_)) => Some("--control"),
        (false, false, None) => None,
    };
    if let Some(who) = live {
        let given = [
            (args.frames > 1, "--frames"),
            (args.orbit, "--orbit"),
            (args.zoom != 1.0, "--zoom"),
            (args.eye_path.is_some(), "--eye-path"),
            (movie, "a movie --out"),
            (args.stereo.is_some(), "--stereo"),
            (window && wall.is_some(), "--wall"),
            (window && args.present, "--present"),
            // Display ranks show their displays in windows, or write them (not a live run).
            (args.display_ranks > 0 && !args.present, "--display-ranks"),
        ];
        if let Some((_, flag)) = given.iter().find(|(given, _)| *given) {
            bail!("{who} takes the frames from its commands: leave out {flag}");
        }
    }
    let control = match args.control {
        Some(addr) => {
            let token = args.control_token_file.as_deref().map(super::control::read_token).transpose()?;
            Some((addr, token))
        }
        None if args.control_token_file.is_some() => bail!("--control-token-file needs --control"),
        None => None,
    };
    if args.eye_stream.is_some() && live.is_none() {
        bail!("--eye-stream steers a live run: give --control or --present (or use tessera view)");
    }
    if let Some(crate::cli::EyeStream::Udp(addr)) = &args.eye_stream {
        if !addr.ip().is_loopback() && control.as_ref().is_none_or(|(_, token)| token.is_none()) {
            bail!(
                "--eye-stream udp:{addr} is not a loopback address: give --control-token-file, whose token each datagram must start with"
            );
        }
    }
    Ok(control)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_numbered() {
        assert_eq!(frame_path(Path::new("out/f.png"), 0, 1), PathBuf::from("out/f.png"));
        assert_eq!(frame_path(Path::new("out/f.png"), 2, 10), PathBuf::from("out/f-0003.png"));
    }
}
