//! Every flag of `tessera`: the clap types of each command, and the value parsers that
//! validate each flag once, as it is parsed (sizes, numbers, camera vectors), so that the
//! commands receive values that are already in range.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{bail, Result};
use clap::{Args, Parser, Subcommand};
use codec::view::TileGrid;
use glam::Vec3;
use worker::node::HEARTBEAT;

use crate::camera::{CameraSpec, StereoOutput, ViewPreset};

/// Parses `WxH` (or `CxR`).
pub fn parse_pair(s: &str) -> Result<(u32, u32), String> {
    let (a, b) = s.split_once(['x', 'X']).ok_or_else(|| format!("expected WIDTHxHEIGHT, got '{s}'"))?;
    let n = |v: &str| v.trim().parse::<u32>().map_err(|_| format!("'{v}' is not a whole number in '{s}'"));
    Ok((n(a)?, n(b)?))
}

/// Parses a frame size `WxH`: each side 1 to [`MAX_FRAME_SIDE`], checked here, before anything
/// is allocated for it.
pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = parse_pair(s)?;
    check_frame_size(w as u64, h as u64).map_err(|e| e.to_string())?;
    Ok((w, h))
}

/// The largest frame side Tessera renders, in pixels. A worker renders each tile as a crop of
/// a frame-sized texture (exact tile borders; see `worker::render`), so the frame must fit one
/// texture: 16384 is the largest texture side of lavapipe and of most desktop GPUs, and the
/// handshake checks each worker's own adapter limit against the frame before the first
/// frame. The composited frame on rank 0 is then at most 1 GiB of RGBA.
pub const MAX_FRAME_SIDE: u64 = 16384;

/// Refuses a frame with a side of zero or above [`MAX_FRAME_SIDE`] (overflow-free: sides are
/// taken as `u64`, so wall arithmetic can pass its sums unclamped).
pub fn check_frame_size(w: u64, h: u64) -> Result<()> {
    if w == 0 || h == 0 {
        bail!("the frame size {w}x{h} must be at least 1x1");
    }
    if w > MAX_FRAME_SIDE || h > MAX_FRAME_SIDE {
        bail!("the frame is {w}x{h} pixels; at most {MAX_FRAME_SIDE} on a side is supported (one texture per worker)");
    }
    Ok(())
}

/// The longest `--timeout` accepted: about 31 years.
const MAX_TIMEOUT_S: f64 = 1e9;

/// Parses a positive number of seconds (at most about 31 years), never panicking on
/// `inf`, `1e20`, `-0` or `nan`.
pub fn parse_seconds(s: &str) -> Result<Duration, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("'{s}' is not a number of seconds"))?;
    if !(v > 0.0 && v <= MAX_TIMEOUT_S) {
        return Err(format!("expected a positive number of seconds up to {MAX_TIMEOUT_S:e}, not {s}"));
    }
    Ok(Duration::from_secs_f64(v))
}

/// Parses `--timeout`: [`parse_seconds`], and at least four heartbeats, so that one late
/// heartbeat is not taken for a dead worker.
pub fn parse_timeout(s: &str) -> Result<Duration, String> {
    let t = parse_seconds(s)?;
    if t < HEARTBEAT * 4 {
        return Err(format!(
            "--timeout must be at least {} s (workers send a heartbeat every {} ms)",
            (HEARTBEAT * 4).as_secs_f64(),
            HEARTBEAT.as_millis()
        ));
    }
    Ok(t)
}

/// Parses a finite number greater than zero.
pub fn parse_positive(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        Ok(_) => Err(format!("expected a finite number above zero, not {s}")),
        Err(_) => Err(format!("'{s}' is not a number")),
    }
}

/// Parses a finite number, zero or greater (`-0` is zero).
pub fn parse_non_negative(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v + 0.0),
        Ok(_) => Err(format!("expected a finite number, zero or above, not {s}")),
        Err(_) => Err(format!("'{s}' is not a number")),
    }
}

/// Parses a byte count: a whole number with an optional K, M, G or T suffix (powers of 1024).
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let (num, shift) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let shift = match c.to_ascii_uppercase() {
                'K' => 10,
                'M' => 20,
                'G' => 30,
                'T' => 40,
                _ => return Err(format!("'{s}': the suffix must be K, M, G or T")),
            };
            (&t[..i], shift)
        }
        _ => (t, 0),
    };
    let n: u64 = num.parse().map_err(|_| format!("'{s}' is not a byte count"))?;
    n.checked_mul(1u64 << shift).filter(|&v| v > 0).ok_or_else(|| format!("'{s}' is out of range"))
}

/// Parses `N` finite comma-separated numbers (`shape` names them in the error: `x,y,z`).
fn parse_floats<const N: usize>(s: &str, shape: &str) -> Result<[f32; N], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|c| {
            c.trim().parse::<f32>().map_err(|_| match c.trim() == s.trim() {
                true => format!("expected {shape}, got '{s}'"),
                false => format!("'{c}' is not a number in '{s}'"),
            })
        })
        .collect::<Result<_, _>>()?;
    let v: [f32; N] = v.try_into().map_err(|_| format!("expected {shape}, got '{s}'"))?;
    if !v.iter().all(|c| c.is_finite()) {
        return Err(format!("'{s}' has a non-finite coordinate"));
    }
    Ok(v)
}

/// Parses `x,y,z`.
pub fn parse_vec3(s: &str) -> Result<Vec3, String> {
    parse_floats::<3>(s, "x,y,z").map(Vec3::from)
}

/// Where a live run's eye positions come from (`--eye-stream`): standard input, or UDP
/// datagrams on an address, each a line `x y z` (or `x,y,z`).
#[derive(Clone, Debug, PartialEq)]
pub enum EyeStream {
    Stdin,
    Udp(SocketAddr),
}

/// Parses `--pixel-codec`: `raw`, `lz4`, `jpeg` or `jpeg:QUALITY` (1-100).
pub fn parse_pixel_codec(s: &str) -> Result<protocol::PixelCodec, String> {
    use protocol::PixelCodec;
    match s.split_once(':') {
        None if s == "raw" => Ok(PixelCodec::Raw),
        None if s == "lz4" => Ok(PixelCodec::Lz4),
        None if s == "jpeg" => Ok(PixelCodec::Jpeg { quality: 90 }),
        Some(("jpeg", q)) => match q.parse::<u8>() {
            Ok(quality @ 1..=100) => Ok(PixelCodec::Jpeg { quality }),
            _ => Err(format!("a JPEG quality is 1 to 100, not {q}")),
        },
        _ => Err(format!("{s} is not raw, lz4, jpeg or jpeg:QUALITY")),
    }
}

/// Parses `--eye-stream`: `-` or `udp:HOST:PORT`.
pub fn parse_eye_stream(s: &str) -> Result<EyeStream, String> {
    match s {
        "-" => Ok(EyeStream::Stdin),
        _ => match s.strip_prefix("udp:").map(str::parse::<SocketAddr>) {
            Some(Ok(addr)) => Ok(EyeStream::Udp(addr)),
            _ => Err(format!("'{s}': expected - (standard input) or udp:HOST:PORT")),
        },
    }
}

/// Parses a position written `x y z` or `x,y,z` (any mix of commas and blanks): a line of
/// an eye file or of an eye stream.
pub fn parse_point(line: &str) -> Result<Vec3, String> {
    let words: Vec<&str> = line.split(|c: char| c == ',' || c.is_whitespace()).filter(|w| !w.is_empty()).collect();
    parse_vec3(&words.join(","))
}

/// Parses `x,y`.
pub fn parse_vec2(s: &str) -> Result<[f32; 2], String> {
    parse_floats(s, "x,y")
}

#[derive(Parser)]
#[command(name = "tessera", version, about = "Sort-first parallel rendering of compressed meshes")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
    /// The most bytes a gzip-compressed input may expand to (K, M, G, T suffixes allowed).
    #[arg(long, global = true, value_parser = parse_bytes, default_value = "1G")]
    pub max_decompressed: u64,
    /// Let a glTF model's buffer URIs name files outside its folder (absolute paths, `..`,
    /// symlinks that lead out); by default they are refused.
    #[arg(long, global = true)]
    pub allow_outside_uris: bool,
}

#[derive(Subcommand)]
pub enum Command {
    /// Compress a mesh (OBJ, PLY, STL or glTF, optionally .gz) into a .bft file.
    Encode {
        input: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        options: EncodeArgs,
    },
    /// Decompress a .bft file into PLY or OBJ (chosen by the output's extension).
    Decode {
        input: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Sort a model into one compressed BFT submesh per screen tile (one frame).
    Sort(SortArgs),
    /// Render a model sort-first: rank 0 sorts it into compressed tiles, ranks 1.. render them.
    /// Run under mpirun for a cluster; alone, it runs the master and one worker in-process.
    Render(Box<RenderArgs>),
    /// Show a model in a window, sort-first through the same tiles as `render` (one process):
    /// drag to orbit, right-drag to pan, wheel to zoom, W/A/S/D to fly, P for a screenshot,
    /// G for the tile grid by cost, H for the heads-up line, Q to quit. Takes `render`'s
    /// flags; `--control` steers it from programs too.
    View(Box<RenderArgs>),
    /// Print sizes and rates of a .bft file.
    Stats {
        input: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Dependency-free progressive meshes (.dpm files).
    Pm {
        #[command(subcommand)]
        pm: Pm,
    },
    /// The nSP-tree store: lossless, progressive, view-dependent (.nsp files).
    Nsp {
        #[command(subcommand)]
        nsp: Nsp,
    },
    /// Draw a per-rank timeline of the stages in a `render --stats` file as a PNG.
    Plot {
        /// The stats file (JSON lines).
        input: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
        /// Only frames A to B (counted from 0, both included): `A..B`, or `A` alone.
        #[arg(long, value_parser = parse_frame_range)]
        frames: Option<(u32, u32)>,
        /// Image width in pixels.
        #[arg(long, default_value_t = 1600, value_parser = clap::value_parser!(u32).range(400..=16384))]
        width: u32,
    },
}

/// `A..B` or `A`: a range of frame numbers, both ends included.
pub fn parse_frame_range(s: &str) -> Result<(u32, u32), String> {
    let num = |v: &str| v.trim().parse::<u32>().map_err(|_| format!("'{s}' is not a frame range (A..B or A)"));
    let (a, b) = match s.split_once("..") {
        Some((a, b)) => (num(a)?, num(b)?),
        None => (num(s)?, num(s)?),
    };
    if a > b {
        return Err(format!("frame range {s} is empty (its first frame is after its last)"));
    }
    Ok((a, b))
}

#[derive(Subcommand)]
pub enum Nsp {
    /// Build an .nsp file from a mesh file.
    Build {
        input: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
        /// p: bits per quantized coordinate (1 to 30).
        #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u8).range(1..=30))]
        bits: u8,
        /// p_r: the root cell's maximal precision in bits.
        #[arg(long, default_value_t = 7, value_parser = clap::value_parser!(u8).range(1..=30))]
        root_bits: u8,
        /// n: splits per axis of a cell (2, 4, 8 or 16).
        #[arg(long, default_value_t = 4)]
        splits: u32,
        /// N_min: a cell splits only if it holds at least this many top-simplices.
        #[arg(long, default_value_t = 8000)]
        min_simplices: u32,
        /// m: bits of geometry advance (section 7): positions refined m bits ahead of the
        /// connectivity, so a view draws fewer, larger triangles at the same error (0 to 4).
        #[arg(long, default_value_t = 0)]
        advance: u8,
        /// Where temporary files go (the system's temporary folder by default). PLY and OBJ
        /// input is built out of core there; STL is loaded whole.
        #[arg(long)]
        temp_dir: Option<PathBuf>,
    },
    /// Print an .nsp file's parameters, counts and bytes by part (reads its tables only).
    Stats {
        input: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Refine an .nsp file's cells for a view (or fully) and write the mesh as PLY or OBJ.
    Adapt {
        input: PathBuf,
        #[command(flatten)]
        view: ViewArgs,
        /// Allowed projected error of a vertex, in pixels.
        #[arg(long, default_value_t = 1.0, value_parser = parse_positive)]
        error_px: f32,
        #[arg(short, long)]
        output: PathBuf,
        /// Refine every cell to full precision (ignores the view).
        #[arg(long)]
        full: bool,
    },
}

#[derive(Subcommand)]
pub enum Pm {
    /// Build a progressive mesh from a mesh file and compress it into a .dpm file.
    Build {
        input: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
        /// Bits per quantized position coordinate (8 to 24).
        #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u8).range(8..=24))]
        position_bits: u8,
        /// Bits per octahedral normal coordinate (4 to 16).
        #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u8).range(4..=16))]
        normal_bits: u8,
        /// Write an out-of-core file: operations grouped into a hierarchy of nodes of at most
        /// this many kB (1 to 64; the paper's 64), read node by node within a memory budget.
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
        node_kb: Option<u32>,
        /// Simplify a model of more triangles than this in spatial chunks of at most this
        /// many, so the simplifier's memory follows the chunk, not the model (0: never).
        #[arg(long, default_value_t = codec::pm::CHUNK_FACES)]
        chunk_faces: usize,
        /// Build even where the model plainly needs more memory than the machine has
        /// available (the build holds the whole model, about 65 bytes a triangle; without this
        /// it stops before simplifying, rather than be killed for memory later).
        #[arg(long)]
        no_memory_check: bool,
        /// Keep the build's large arrays in files in this folder (on a disk), mapped, so that
        /// a model larger than memory builds: the kernel writes their pages back and drops them
        /// under memory pressure. Without it, a build that plainly needs more memory than is
        /// available does this in the temporary folder ($TMPDIR or /tmp) where that is on a
        /// disk with room.
        #[arg(long, value_name = "DIR")]
        spill_dir: Option<PathBuf>,
        /// Blocks of at least this many MiB go to the spill folder (tests use a small one).
        #[arg(long, default_value_t = 4, hide = true)]
        spill_min_mb: usize,
        /// Take this many MiB as the memory available (tests of spilling by itself).
        #[arg(long, hide = true)]
        assume_available_mb: Option<u64>,
    },
    /// Print the size of a .dpm file per vertex, with the breakdown.
    Stats {
        input: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Adapt a .dpm file to a view (or refine it fully) and write the mesh as PLY.
    Adapt {
        input: PathBuf,
        #[command(flatten)]
        view: ViewArgs,
        /// Screen-space error threshold in pixels.
        #[arg(long, default_value_t = 0.5, value_parser = parse_positive)]
        error_px: f32,
        #[arg(short, long)]
        output: PathBuf,
        /// Apply every split (ignores the view).
        #[arg(long)]
        full: bool,
        /// The normal error's weight, as a fraction of the model's bounding box diagonal per
        /// unit of normal chord (0 ignores normals).
        #[arg(long, default_value_t = 0.0, value_parser = parse_non_negative)]
        normal_weight: f32,
        /// Adapt on the GPU (WGSL compute shaders through wgpu; lavapipe without a GPU). The
        /// mesh written is the same as the CPU reference's.
        #[arg(long)]
        gpu: bool,
        /// With --gpu, the graphics memory the adaptation may take, in MB (fractions allowed):
        /// the model's operations or node pool, its tables and the adapted mesh. Where the
        /// view would refine past it, the mesh is adapted to a larger pixel error (printed).
        /// Default: no bound but the GPU's.
        #[arg(long, value_parser = parse_positive, requires = "gpu")]
        gpu_budget_mb: Option<f32>,
        /// With --gpu, an out-of-core file's node pool in graphics memory, in MB (fractions
        /// allowed): the nodes of highest priority for the view that fit. Default: a quarter
        /// of --gpu-budget-mb, or without it slots for the nodes the view requires (every
        /// node with --full).
        #[arg(long, value_parser = parse_positive, requires = "gpu")]
        gpu_nodes_mb: Option<f32>,
        /// Adapt in the paper's passes of one level each (a view change of k levels takes k
        /// passes) instead of every level the view asks for in one pass (the default). The
        /// mesh written is the same.
        #[arg(long)]
        one_level: bool,
    },
}

/// Flags of `tessera encode`.
#[derive(Args, Clone, Debug)]
pub struct EncodeArgs {
    /// Bits per quantized coordinate (8 to 24).
    #[arg(long, default_value_t = codec::Quantization::DEFAULT_BITS, value_parser = clap::value_parser!(u8).range(8..=24))]
    pub quant_bits: u8,
    /// Triangles per chunk at most: a model with more is written as a chunked file, whose
    /// frames skip, forward and sort chunk by chunk (0: always one stream). Smaller chunks
    /// forward more of a frame untouched and cost more bytes at their borders. Without it, a
    /// model of at most 4,194,304 triangles (and 4M vertices) is one stream, and a larger
    /// one chunked at 4096 triangles a chunk.
    #[arg(long)]
    pub chunk_triangles: Option<u32>,
    /// Where the chunked encoder's temporary files go (the system's temporary folder by
    /// default).
    #[arg(long)]
    pub temp_dir: Option<PathBuf>,
    /// Bits per octahedral coordinate of the file's vertex normals (4 to 16).
    #[arg(long, default_value_t = codec::bft::attributes::DEFAULT_NORMAL_BITS, value_parser = clap::value_parser!(u8).range(4..=16))]
    pub normal_bits: u8,
    /// Drop the file's vertex colours (they are kept by default).
    #[arg(long)]
    pub no_colors: bool,
    /// Drop the file's vertex normals (kept by default; a renderer then computes them).
    #[arg(long)]
    pub no_normals: bool,
    /// Store the input vertex order, so that `decode` gives every vertex at its input index
    /// (for per-vertex data kept beside the file); without it `decode` gives the traversal's
    /// order. `stats` reports its cost in bits per vertex.
    #[arg(long)]
    pub keep_order: bool,
    /// How the file's streams (or its chunks') are entropy-coded: `range`, the smallest;
    /// `prefix`, a few percent larger and decoded several times faster (the workers decode
    /// a chunked file's whole chunks as the file has them).
    #[arg(long, value_enum, default_value_t = TileCoding::Range)]
    pub coding: TileCoding,
    /// Build a level-of-detail hierarchy above the chunks: groups of adjacent chunks
    /// simplified to half with their borders locked, level after level, each chunk an
    /// ordinary BFT stream with its error. `sort` and `render` then draw the cut of
    /// `--error-px`, crack-free. Chunks the model (at --chunk-triangles, 4096 by default),
    /// and holds its triangles in memory while it builds.
    #[arg(long)]
    pub lod: bool,
    /// With --lod: the weight of normals in the simplifier's error, against positions
    /// scaled to each group's extent. Larger keeps more triangles where shading changes
    /// (on the dragon at --error-px 1: 0 draws 76K triangles, 85-87% of covered pixels
    /// within 8/255 of the full model; 2 draws 322K, 99.3-99.4%).
    #[arg(long, default_value_t = codec::bft::chunked::lod::NORMAL_WEIGHT, value_parser = parse_non_negative)]
    pub lod_normal_weight: f32,
}

/// Flags of `tessera render`.
#[derive(Args, Clone, Debug)]
pub struct RenderArgs {
    /// A .bft file, a mesh file (OBJ, PLY, STL, glTF; encoded on load), or a progressive mesh
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
    /// The orbit's whole angle in degrees over the frames (with --orbit): 360 goes once
    /// around; `--frames 31 --orbit-degrees 30` turns one degree a frame.
    #[arg(long, default_value_t = 360.0, value_parser = parse_non_negative)]
    pub orbit_degrees: f32,
    /// Moves the eye toward the target over the frames so that the last frame's distance is
    /// this fraction of the first's (geometrically: each frame closer by the same factor);
    /// 1 keeps the distance. With --orbit, the eye orbits and zooms at once.
    #[arg(long, default_value_t = 1.0, value_parser = parse_positive)]
    pub zoom: f32,
    /// Output PNG; with several frames, frame-0001.png and so on beside it. Or a movie
    /// (.mp4, .mkv, .mov, .webm, .avi): every frame piped to ffmpeg, one file. `-o` and
    /// `--output` name it too, as they name every other command's output.
    #[arg(short = 'o', long, visible_alias = "output", default_value = "frame.png")]
    pub out: PathBuf,
    /// A live run: serve a control port at HOST:PORT (rank 0) whose newline-delimited JSON
    /// commands set or orbit the camera, write snapshots, stream stats and quit
    /// (docs/guide.md, "Control port"; `scripts/tessera_control.py` is a client). The run
    /// goes on until `quit` or a signal; a frame is sorted only when a command changes the
    /// view, and no frame file is written but snapshots. Loopback only, unless
    /// --control-token-file.
    #[arg(long)]
    pub control: Option<std::net::SocketAddr>,
    /// A live run shown in windows: one per display of --wall (opened by the display ranks
    /// with --display-ranks, else by rank 0; the wall file places them), or one for the
    /// frame. Steered from the first window's mouse and keys (docs/guide.md, "Live walls")
    /// and from --control; runs until Q, a closed window, `quit` or a signal.
    #[arg(long)]
    pub present: bool,
    /// A file whose first line (at least 16 characters) is the token every control client
    /// must present as its first line, `{"token":"..."}`; needed to bind --control to an
    /// address other than loopback.
    #[arg(long)]
    pub control_token_file: Option<PathBuf>,
    /// Head tracking in a live run: eye positions, `x y z` a line, from standard input (`-`)
    /// or from UDP datagrams (`udp:HOST:PORT`, loopback unless --control-token-file, whose
    /// token each datagram then starts with); each moves the eye of a --wall placed in the
    /// world (without one, the camera's eye) for the next frame.
    #[arg(long, value_parser = parse_eye_stream)]
    pub eye_stream: Option<EyeStream>,
    /// Frames rank 0 sorts and sends ahead of the one it composites (1: no pipelining).
    /// `--balance` keeps 1, as it sorts each frame from the costs of the one before, and so
    /// does `--sorters` above 1.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=16))]
    pub frames_in_flight: u32,
    /// Frames a second of a movie output.
    #[arg(long, default_value_t = 30.0, value_parser = parse_positive)]
    pub fps: f32,
    /// Write one JSON line per frame per rank.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Reassign tiles every frame from the costs measured the frame before.
    #[arg(long)]
    pub balance: bool,
    /// Make every frame, even one whose view is the frame before's (which is otherwise
    /// reused: no sort, no send, no render, its files copied). For measuring what a still
    /// view would cost, and for tests of what changes between frames.
    #[arg(long)]
    pub no_frame_reuse: bool,
    /// How the tiles sent to the workers are entropy-coded: `prefix` (static Huffman codes
    /// per tile) sorts and decodes several times faster; `range` (the adaptive range coder
    /// of `.bft` files) sends about 5% fewer bytes.
    #[arg(long, value_enum, default_value_t = TileCoding::Prefix)]
    pub tile_coding: TileCoding,
    /// How workers code the tile pixels they send to rank 0 or the display ranks: `raw`,
    /// `lz4` (lossless) or `jpeg[:QUALITY]` (lossy colour, 1-100, default 90; the alpha
    /// plane kept exact). A tile whose coding is not smaller goes raw.
    #[arg(long, value_parser = parse_pixel_codec, default_value = "raw")]
    pub pixel_codec: protocol::PixelCodec,
    /// A tile wall description (TOML): one PNG per display plus an overview.
    #[arg(long)]
    pub wall: Option<PathBuf>,
    /// Direct send: the last D ranks of the job own the wall's displays (display i on the
    /// (i mod D)-th of them); workers send them their tiles' pixels, each assembles and
    /// writes its displays at a swap barrier, and no display pixel passes through rank 0
    /// (which writes no overview). Needs --wall and mpirun; 0 (default): rank 0 composites.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=4096))]
    pub display_ranks: u32,
    /// Head tracking on a wall with a `plane`: a text file of eye positions in world units,
    /// one `x y z` (or `x,y,z`) line per frame; each frame's off-axis frustum goes from that
    /// eye through the wall.
    #[arg(long)]
    pub eye_path: Option<PathBuf>,
    /// Render a left and a right eye this far apart (world units) per frame, with off-axis
    /// frusta converging on the focal plane: the wall's plane for a wall with a `plane`, else
    /// the plane through the target.
    #[arg(long, value_parser = parse_positive)]
    pub stereo: Option<f32>,
    /// How a stereo pair is written: `separate` (`frame-left.png` and `frame-right.png`) or
    /// `side-by-side` (one image twice as wide, the left eye on the left; movies take only
    /// this).
    #[arg(long, value_enum, default_value_t = StereoOutput::Separate)]
    pub stereo_output: StereoOutput,
    /// Seconds of silence after which a worker counts as dead. Workers send a heartbeat
    /// while they work, so a slow frame is not silence. At least 1.
    #[arg(long, default_value = "60", value_parser = parse_timeout)]
    pub timeout: Duration,
    /// Workers decode their tiles but do not rasterize them: the frames are transparent, and
    /// --stats measures the distribution (sort, send, decode, composite) apart from the
    /// rasterizer. Sorted models only (.bft and mesh files).
    #[arg(long)]
    pub decode_only: bool,
    /// Chunked models: ranks that share the sort. Under `mpirun -np N`, rank 0 and the last
    /// K-1 ranks each sort a contiguous share of the chunks and send its pieces straight to
    /// the workers (ranks 1..=N-K), so that no one rank reads the whole model or carries all
    /// the traffic; rank 0 still composites. Frames are the same for every K.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=64))]
    pub sorters: u8,
    /// Chunked models: rank 0's cache of straddling chunks' sort tables, in MB (a chunk
    /// that straddles a tile border is decoded once and kept while it fits).
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u64).range(0..=1 << 24))]
    pub cache_mb: u64,
    /// Chunked models: each worker's cache of the chunks it was sent whole, in MB (kept
    /// compressed, with their border normals); rank 0 sends a chunk again only when the
    /// worker no longer holds it. `.bft` models: it bounds too the meshes a worker keeps
    /// from the frame before, so that a stream byte-identical to one it decoded then (a
    /// verbatim chunk still in view, a tile whose submesh did not change) is not decoded
    /// again (0 keeps none).
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u64).range(0..=1 << 24))]
    pub worker_cache_mb: u64,
    /// Progressive meshes, `.nsp` stores and level-of-detail `.bft` files (`encode --lod`):
    /// the screen-space error bound in pixels.
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
    /// Progressive meshes: the graphics memory each worker's adaptation may take, in MB: the
    /// model's operations (out of core its node pool, see --gpu-nodes-mb), its tables and the
    /// adapted mesh. Where a view would refine past it, the worker adapts to a larger pixel
    /// error (the stats' `error_scale`, and a note). Fractions of a MB are allowed.
    #[arg(long, default_value_t = 512.0, value_parser = parse_positive)]
    pub gpu_budget_mb: f32,
    /// Out-of-core progressive meshes (`pm build --node-kb`): the part of --gpu-budget-mb each
    /// worker keeps of the model's nodes, in MB (default: a quarter). Workers read the file
    /// themselves (a path every rank can open), the nodes their view needs first (the
    /// paper's priority), others while room is left. Fractions of a MB are allowed.
    #[arg(long, value_parser = parse_positive)]
    pub gpu_nodes_mb: Option<f32>,
    /// Progressive meshes: occlusion culling one frame late. Each worker keeps the depth of
    /// the frame it drew last and does not refine what it hid (the paper's section 5.7), so
    /// hidden parts stay at what the frame before showed of them; the first frame is drawn
    /// without.
    #[arg(long)]
    pub occlusion: bool,
}

/// Screen size and tile grid.
#[derive(Args, Clone, Debug)]
pub struct GridArgs {
    /// Frame size in pixels, WIDTHxHEIGHT.
    #[arg(long, value_parser = parse_size, default_value = "1920x1080")]
    pub size: (u32, u32),
    /// Tile grid, COLSxROWS.
    #[arg(long, value_parser = parse_pair, default_value = "8x8")]
    pub tiles: (u32, u32),
}

impl GridArgs {
    pub fn grid(&self) -> Result<TileGrid> {
        Ok(TileGrid::new(self.size.0, self.size.1, self.tiles.0, self.tiles.1)?)
    }
}

/// `tessera sort`.
#[derive(Args, Clone, Debug)]
pub struct SortArgs {
    /// A .bft file, or a mesh file (encoded on load at 16 bits).
    pub model: PathBuf,
    #[command(flatten)]
    pub grid: GridArgs,
    #[command(flatten)]
    pub camera: CameraArgs,
    /// Write `DIR/tile-<index>.ply` for every non-empty tile, and `DIR/summary.json`.
    #[arg(long)]
    pub dump: Option<PathBuf>,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
    /// How the tiles are entropy-coded: `range` (the adaptive range coder of `.bft`
    /// files, the smallest tiles) or `prefix` (static Huffman codes per tile, several times
    /// faster to sort and decode, about 5% larger).
    #[arg(long, value_enum, default_value_t = TileCoding::Range)]
    pub tile_coding: TileCoding,
    /// Level-of-detail files (`encode --lod`): sort the cut of chunks whose error projects
    /// to at most this many pixels (as `render` draws it).
    #[arg(long, default_value_t = 0.5, value_parser = parse_positive)]
    pub error_px: f32,
}

/// The view a model is adapted to (`pm adapt`, `nsp adapt`): the camera and the frame size.
#[derive(Args, Clone, Debug)]
pub struct ViewArgs {
    #[command(flatten)]
    pub camera: CameraArgs,
    /// Frame size in pixels, WIDTHxHEIGHT.
    #[arg(long, value_parser = parse_size, default_value = "1920x1080")]
    pub size: (u32, u32),
}

/// The camera; every flag left out comes from the default camera, which frames the model.
#[derive(Args, Clone, Debug, Default)]
pub struct CameraArgs {
    /// Where the camera starts before --eye, --target and the rest: `front` looks down -Z
    /// with the model's bounding sphere in view (the figures' camera); `three-quarter`
    /// looks from above, right and in front, close enough that the model's box fills the
    /// frame.
    #[arg(long, value_enum, default_value = "front")]
    pub view: ViewPreset,
    /// With --view three-quarter: degrees about +Y from the +Z side (45: front right;
    /// -135: back left, for a model that faces -Z).
    #[arg(long, default_value_t = 45.0, allow_hyphen_values = true)]
    pub azimuth: f32,
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<Vec3>,
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub target: Option<Vec3>,
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub up: Option<Vec3>,
    /// Vertical field of view in degrees.
    #[arg(long, value_parser = parse_positive)]
    pub fovy: Option<f32>,
    #[arg(long, value_parser = parse_positive)]
    pub near: Option<f32>,
    #[arg(long, value_parser = parse_positive)]
    pub far: Option<f32>,
    /// Lens shift `x,y` in normalised device coordinates (half-widths right, half-heights
    /// up): an off-axis frustum, as a wall display seen from off its centre, or a stereo eye.
    #[arg(long, value_parser = parse_vec2, allow_hyphen_values = true)]
    pub shift: Option<[f32; 2]>,
}

impl CameraArgs {
    /// The camera these flags ask for, as the commands and the render plan carry it.
    pub fn spec(&self) -> CameraSpec {
        let CameraArgs { view, azimuth, eye, target, up, fovy, near, far, shift } = self.clone();
        CameraSpec { view, azimuth, eye, target, up, fovy, near, far, shift }
    }
}

/// `--tile-coding` and `encode --coding`: how streams are entropy-coded
/// ([`codec::bft::Coding`]).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileCoding {
    Prefix,
    Range,
}

impl From<TileCoding> for codec::bft::Coding {
    fn from(c: TileCoding) -> Self {
        match c {
            TileCoding::Prefix => codec::bft::Coding::Prefix,
            TileCoding::Range => codec::bft::Coding::Range,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_names_its_output_as_every_command_does() {
        use clap::Parser;
        for flag in ["--out", "-o", "--output"] {
            let cli = Cli::try_parse_from(["tessera", "render", "m.bft", flag, "f.png"]).expect("parses");
            let Command::Render(args) = cli.command else { panic!("a render") };
            assert_eq!(args.out, PathBuf::from("f.png"), "{flag}");
        }
    }

    #[test]
    fn parsers() {
        assert_eq!(parse_pair("1920x1080"), Ok((1920, 1080)));
        assert!(parse_pair("1920").is_err());
        assert!(parse_pair("-1x3").is_err());
        assert_eq!(parse_vec3("1,-2.5,3"), Ok(Vec3::new(1.0, -2.5, 3.0)));
        assert!(parse_vec3("1,2").is_err());
        assert!(parse_vec3("1,nan,2").is_err());
    }

    #[test]
    fn numbers_never_panic() {
        for v in ["1e20", "inf", "-inf", "nan", "-0", "0", "-1", "1e-45", "x", ""] {
            let _ = parse_seconds(v);
            let _ = parse_positive(v);
            let _ = parse_non_negative(v);
            let _ = parse_bytes(v);
            let _ = parse_size(&format!("{v}x{v}"));
        }
        assert!(parse_seconds("1e20").is_err());
        assert!(parse_seconds("inf").is_err());
        assert!(parse_seconds("-0").is_err());
        assert_eq!(parse_seconds("1.5"), Ok(std::time::Duration::from_millis(1500)));
        assert_eq!(parse_non_negative("-0"), Ok(0.0));
        assert!(parse_non_negative("-0").unwrap().is_sign_positive());
        assert!(parse_positive("-0").is_err());
        assert_eq!(parse_bytes("4G"), Ok(4 << 30));
        assert!(parse_bytes("99999999999T").is_err());
        assert!(parse_size("192000x108000").is_err());
        assert!(parse_size("4294967295x4294967295").is_err());
        assert_eq!(parse_size("16384x16384"), Ok((16384, 16384)));
    }
}
