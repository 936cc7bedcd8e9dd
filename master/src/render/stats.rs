//! The `--stats` schema: one JSON line per frame for rank 0 and one per worker, each stage's
//! time in milliseconds and a timeline of when each stage ran (the README lists the fields).

use protocol::{FrameSpan, PmMemory, TilePixels, TileTimes};
use serde::{Deserialize, Serialize};

use super::eye::Eye;

/// When a stage of a frame ran on a rank: milliseconds from the start of the run (rank 0's
/// clock when it began; workers' spans are moved onto it through the Unix epoch, see
/// [`FrameSpan`]). `tessera plot` draws these.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Span {
    pub stage: String,
    pub start_ms: f64,
    pub end_ms: f64,
}

impl Span {
    /// The span from `start` to `end` (Unix milliseconds) of a run that began at `epoch`.
    pub(super) fn between(stage: &str, start: f64, end: f64, epoch: f64) -> Span {
        Span { stage: stage.to_string(), start_ms: start - epoch, end_ms: end - epoch }
    }
}

/// One stats line of rank 0.
#[derive(Serialize)]
pub(super) struct MasterStats {
    pub frame: u32,
    /// `--stereo`: which eye's view this line is of.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub eye: Option<Eye>,
    /// On a wall whose displays have frames of their own: which display's frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub display: Option<String>,
    pub rank: usize,
    /// The frame is the frame before, reused (a still camera of a `--frames` run): nothing
    /// was sorted, sent or rendered, and its files are the frame before's.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub reused: bool,
    pub sort_ms: f64,
    pub send_ms: f64,
    pub wait_ms: f64,
    pub composite_ms: f64,
    pub write_ms: f64,
    /// Time from the previous frame's image written to this one's (the frame period; from
    /// the start of writing for the first frame).
    pub frame_ms: f64,
    /// Rank 0's resident memory after the frame, in MB (Linux).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rss_mb: Option<f64>,
    /// Chunked models: what the frame did with the chunks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chunks: Option<ChunkStats>,
    /// `.nsp` models: the cells the view selected and what went to the workers.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nsp: Option<NspStats>,
    pub tiles: Vec<TileStats>,
    /// `--pixel-codec`.
    pub pixel_codec: String,
    /// Bytes of tile pixels rank 0 received (0 with display ranks: the pixels go to them).
    pub pixel_bytes: u64,
    /// Bytes of the tiles' coded pixels as the workers sent them (to rank 0, or to the display
    /// ranks, where a tile on two display ranks' displays goes to each), and their raw size.
    pub pixel_coded_bytes: u64,
    pub pixel_raw_bytes: u64,
    /// The workers' time coding them, summed over the tiles (each worker codes its tiles in
    /// parallel, so a frame waits for less).
    pub pixel_encode_ms: f64,
    /// Rank 0's time decoding them (0 with display ranks: theirs is in `displays`).
    pub pixel_decode_ms: f64,
    /// With display ranks: when the view's displays were complete, and the swap.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub displays: Option<DisplayStats>,
    /// Rank 0's stages: `sort` (with the frame's announcements), `send`, `receive` (waiting
    /// for and compositing the workers' pixels), `swap` (with display ranks: waiting for
    /// every display to be complete) and `write` (on the writer thread).
    pub timeline: Vec<Span>,
}

impl MasterStats {
    /// A line of nothing done yet, for frame 0.
    pub fn new(pixel_codec: String) -> MasterStats {
        MasterStats {
            frame: 0,
            eye: None,
            display: None,
            rank: 0,
            reused: false,
            sort_ms: 0.0,
            send_ms: 0.0,
            wait_ms: 0.0,
            composite_ms: 0.0,
            write_ms: 0.0,
            frame_ms: 0.0,
            rss_mb: None,
            chunks: None,
            nsp: None,
            tiles: Vec::new(),
            pixel_codec,
            pixel_bytes: 0,
            pixel_coded_bytes: 0,
            pixel_raw_bytes: 0,
            pixel_encode_ms: 0.0,
            pixel_decode_ms: 0.0,
            displays: None,
            timeline: Vec::new(),
        }
    }
}

/// The swap barrier of a view on a wall with display ranks: how many displays, when the
/// first and the last was complete (ms from the run's start), the spread between them, and
/// when rank 0 sent the swap (after the last).
#[derive(Serialize, Clone, Copy, Debug, Default)]
pub(super) struct DisplayStats {
    pub displays: u32,
    /// The longest any display rank took to decode the view's coded pixels.
    pub pixel_decode_ms: f64,
    pub first_ready_ms: f64,
    pub last_ready_ms: f64,
    pub spread_ms: f64,
    pub swap_ms: f64,
}

/// An `.nsp` model's frame: cells selected (drawn) for the view, cells the workers draw in
/// all (a cell near a tile border is drawn by each worker it reaches), cell streams sent and
/// their bytes, and the bytes rank 0 has read from the file so far (tables included).
#[derive(Serialize, Clone, Copy, Debug, Default)]
pub(super) struct NspStats {
    pub selected: u32,
    pub drawn: u32,
    pub sent: u32,
    pub bytes_sent: u64,
    pub bytes_read: u64,
}

/// A chunked model's frame: chunks culled, forwarded verbatim and sorted, the triangles of
/// the sorted ones, how many of those had their tables built (not cached), and how many
/// verbatim chunks went as bytes or as a name of a chunk the worker kept.
#[derive(Serialize, Clone, Copy, Debug, Default)]
pub(super) struct ChunkStats {
    /// Chunks a level-of-detail file's cut leaves out (`--error-px`).
    pub not_in_cut: u32,
    pub culled: u32,
    pub verbatim: u32,
    pub straddling: u32,
    pub straddling_triangles: u64,
    /// Triangles of pieces taken from the frame before, not sorted again (once per tile a
    /// triangle is in, as pieces count them).
    pub reused_triangles: u64,
    pub built: u32,
    pub sent: u32,
    pub kept: u32,
    /// The master's cache of straddling chunks' tables, in MB.
    pub cache_mb: f64,
}

#[derive(Serialize)]
pub(super) struct TileStats {
    pub index: u32,
    pub worker: usize,
    pub triangles: u32,
    pub bytes: usize,
    /// Bytes the tile's triangles need as independent triangles (36 each).
    pub tri_bytes: usize,
    /// Bytes of border normals sent with the tile.
    pub normal_bytes: usize,
}

/// One stats line of a worker, as reported back to rank 0.
#[derive(Serialize)]
pub(super) struct WorkerStats {
    frame: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    eye: Option<Eye>,
    pub rank: usize,
    decode_ms: f64,
    adapt_ms: f64,
    upload_ms: f64,
    render_ms: f64,
    readback_ms: f64,
    /// Coding the pixels for the wire (`--pixel-codec`).
    encode_ms: f64,
    /// Triangles decoded this frame, and taken instead from the frame before's meshes
    /// (streams byte-identical to ones decoded then).
    decoded_triangles: u64,
    reused_triangles: u64,
    tiles: Vec<WorkerTileStats>,
    /// A progressive mesh's memory: graphics memory of the adaptation (static and dynamic
    /// buffers), and out of core the node bytes loaded this frame, the nodes resident, the
    /// nodes the view requires (priority at least 1) and the slots the budget holds; and the
    /// factor on `--error-px` the mesh was adapted to (above 1 where the budget held it back).
    #[serde(skip_serializing_if = "Option::is_none")]
    pm: Option<PmMemoryStats>,
    /// The worker's stages: `decode` (or `adapt` for a progressive mesh), then `render`
    /// (upload, draw and readback of every tile).
    timeline: Vec<Span>,
}

#[derive(Serialize)]
struct PmMemoryStats {
    gpu_bytes: u64,
    loaded_bytes: u64,
    resident_nodes: u32,
    required_nodes: u32,
    node_slots: u32,
    error_scale: f32,
}

#[derive(Serialize)]
struct WorkerTileStats {
    index: u32,
    triangles: u32,
    reused_triangles: u32,
    decode_ms: f64,
    adapt_ms: f64,
    upload_ms: f64,
    render_ms: f64,
    readback_ms: f64,
    encode_ms: f64,
    /// Coded bytes of its pixels.
    pixel_bytes: u32,
}

impl WorkerStats {
    /// The worker's node slots, for a progressive mesh out of core.
    pub(super) fn node_slots(&self) -> Option<u32> {
        self.pm.as_ref().map(|p| p.node_slots).filter(|&s| s > 0)
    }

    /// The factor on `--error-px` the worker's progressive mesh was adapted to, where above 1.
    pub(super) fn error_scale(&self) -> Option<f32> {
        self.pm.as_ref().map(|p| p.error_scale).filter(|&s| s > 1.0)
    }
}

/// A worker's line for `frame`, from the tiles it sent back and its span of work, on a run
/// that began at `epoch` (Unix milliseconds).
pub(super) fn worker_stats(
    frame: u32,
    eye: Option<Eye>,
    rank: usize,
    pixels: &[TilePixels],
    span: FrameSpan,
    pm: PmMemory,
    epoch: f64,
) -> WorkerStats {
    let sum = |f: fn(&TileTimes) -> f64| pixels.iter().map(|p| f(&p.times)).sum();
    let first = if pixels.iter().any(|p| p.times.adapt_ms > 0.0) { "adapt" } else { "decode" };
    WorkerStats {
        frame,
        eye,
        rank,
        decode_ms: sum(|t| t.decode_ms),
        adapt_ms: sum(|t| t.adapt_ms),
        upload_ms: sum(|t| t.upload_ms),
        render_ms: sum(|t| t.render_ms),
        readback_ms: sum(|t| t.readback_ms),
        encode_ms: sum(|t| t.encode_ms),
        decoded_triangles: pixels.iter().map(|p| (p.triangles - p.reused.min(p.triangles)) as u64).sum(),
        reused_triangles: pixels.iter().map(|p| p.reused as u64).sum(),
        tiles: pixels
            .iter()
            .map(|p| WorkerTileStats {
                index: p.index,
                triangles: p.triangles,
                reused_triangles: p.reused,
                decode_ms: p.times.decode_ms,
                adapt_ms: p.times.adapt_ms,
                upload_ms: p.times.upload_ms,
                render_ms: p.times.render_ms,
                readback_ms: p.times.readback_ms,
                encode_ms: p.times.encode_ms,
                pixel_bytes: p.coded_bytes,
            })
            .collect(),
        pm: (pm.gpu_bytes > 0).then_some(PmMemoryStats {
            gpu_bytes: pm.gpu_bytes,
            loaded_bytes: pm.loaded_bytes,
            resident_nodes: pm.resident_nodes,
            required_nodes: pm.required_nodes,
            node_slots: pm.slots,
            error_scale: pm.error_scale,
        }),
        timeline: vec![
            Span::between(first, span.start_ms, span.prepared_ms, epoch),
            Span::between("render", span.prepared_ms, span.end_ms, epoch),
        ],
    }
}
