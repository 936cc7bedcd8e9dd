//! What rank 0 is sent: by a worker its readiness, heartbeats, pixels or failure; by a
//! display rank that a view's displays are ready. (Workers send their `Pixels` to display
//! ranks too, with `render --display-ranks`.)

use crate::wire::{Body, Reader, Writer};
use crate::ProtocolError;

/// A message to rank 0 (or a worker's pixels to a display rank).
#[derive(Clone, Debug, PartialEq)]
pub enum ToMaster {
    /// Kind 3: the worker's adapter, and the largest frame side it can render.
    Ready(Ready),
    /// Kind 8: still alive and working (sent every `worker::node::HEARTBEAT` while a worker
    /// starts or renders a frame).
    Heartbeat,
    /// Kind 4: a frame's tiles.
    Pixels(Pixels),
    /// Kind 5: the rank failed, and why.
    Failed(Failed),
    /// Kind 14: from a display rank, its displays of a view are assembled.
    DisplayReady(DisplayReady),
    /// Kind 18: from a display rank, what a person did in its steering window, as a control
    /// command (a JSON line of the control port's), for rank 0 to apply to the next frame.
    Input(Input),
}

const READY: u8 = 3;
const PIXELS: u8 = 4;
const FAILED: u8 = 5;
const HEARTBEAT: u8 = 8;
const DISPLAY_READY: u8 = 14;
const INPUT: u8 = 18;

/// A control command from a display rank's window.
///
/// ```text
/// JSON length u32 + UTF-8 bytes
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Input {
    pub json: String,
}

impl Body for Input {
    fn write(&self, w: &mut Writer) {
        w.bytes(self.json.as_bytes());
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        Ok(Input { json: r.string("input")? })
    }
}

/// The worker's adapter, and the largest frame side it can render (its largest 2D texture
/// side).
///
/// ```text
/// adapter name length u32 + UTF-8 bytes, largest texture side u32
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Ready {
    pub adapter: String,
    pub max_texture_side: u32,
}

impl Body for Ready {
    fn write(&self, w: &mut Writer) {
        w.bytes(self.adapter.as_bytes());
        w.u32(self.max_texture_side);
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        Ok(Ready { adapter: r.string("adapter name")?, max_texture_side: r.u32("texture side")? })
    }
}

/// Why a rank failed.
///
/// ```text
/// reason length u32 + UTF-8 bytes
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Failed {
    pub reason: String,
}

impl Body for Failed {
    fn write(&self, w: &mut Writer) {
        w.bytes(self.reason.as_bytes());
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        Ok(Failed { reason: r.string("failure reason")? })
    }
}

/// A display rank's displays of `view` are assembled, each at the time given (Unix ms), and
/// wait for the swap; it took `decode_ms` to decode their coded pixels.
///
/// ```text
/// view u32, display count u32, then per display: index u32, ready time f64 (Unix ms);
/// then decode ms f64
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct DisplayReady {
    pub view: u32,
    pub ready: Vec<(u32, f64)>,
    pub decode_ms: f64,
}

impl Body for DisplayReady {
    fn write(&self, w: &mut Writer) {
        w.u32(self.view);
        w.u32(self.ready.len() as u32);
        for &(d, t) in &self.ready {
            w.u32(d);
            w.f64(t);
        }
        w.f64(self.decode_ms);
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        let view = r.u32("view")?;
        let n = r.count(12, "displays")?;
        let ready =
            (0..n).map(|_| Ok::<_, ProtocolError>((r.u32("display")?, r.f64("ready")?))).collect::<Result<_, _>>()?;
        Ok(DisplayReady { view, ready, decode_ms: r.f64("decode ms")? })
    }
}

/// A frame's tiles from a worker, and what the frame cost it.
///
/// ```text
/// frame u32, tile count u32, then per tile:
///   index u32, rect 4 x u32, decode/adapt/upload/render/readback/encode ms 6 x f64,
///   triangles u32, reused triangles u32, codec (PixelCodec, 2 bytes), coded bytes u32,
///   pixels length u32 +
///   bytes (raw: (x1-x0)*(y1-y0)*4; coded: at most that);
/// then the frame's span on the worker's clock (ms since the Unix epoch): start, prepared,
/// end 3 x f64 (FrameSpan); then what a progressive mesh's adaptation held (PmMemory, zeros
/// otherwise): GPU bytes u64, node bytes loaded this frame u64, resident nodes u32, required
/// nodes u32, node slots u32, error scale f32
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Pixels {
    pub frame: u32,
    pub tiles: Vec<TilePixels>,
    pub span: FrameSpan,
    pub pm: PmMemory,
}

/// One tile's pixels (RGBA8, rows top first, coded by `codec`) and what it cost.
#[derive(Clone, Debug, PartialEq)]
pub struct TilePixels {
    pub index: u32,
    pub rect: [u32; 4],
    pub times: TileTimes,
    pub triangles: u32,
    /// Of `triangles`, those the worker did not decode again: streams byte-identical to ones
    /// it decoded the frame before.
    pub reused: u32,
    pub codec: PixelCodec,
    /// The coded pixels' size as the worker sent them (the same as `pixels.len()`, except in
    /// rank 0's copy of a tile whose pixels went to display ranks, which has none).
    pub coded_bytes: u32,
    pub pixels: Vec<u8>,
}

/// How tile pixels are coded on their way to rank 0 or the display ranks (`render
/// --pixel-codec`): as they are, with LZ4 (lossless), or as a JPEG of quality 1-100 with the
/// alpha plane beside it in LZ4 (lossy colour, exact coverage). A worker sends a tile raw
/// where its coding would not be smaller.
///
/// ```text
/// kind u8 (0 raw, 1 lz4, 2 jpeg), quality u8 (0 unless jpeg)
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PixelCodec {
    #[default]
    Raw,
    Lz4,
    Jpeg {
        quality: u8,
    },
}

impl Body for PixelCodec {
    fn write(&self, w: &mut Writer) {
        let (kind, quality) = match *self {
            PixelCodec::Raw => (0, 0),
            PixelCodec::Lz4 => (1, 0),
            PixelCodec::Jpeg { quality } => (2, quality),
        };
        w.u8(kind);
        w.u8(quality);
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        match (r.u8("pixel codec")?, r.u8("quality")?) {
            (0, 0) => Ok(PixelCodec::Raw),
            (1, 0) => Ok(PixelCodec::Lz4),
            (2, quality @ 1..=100) => Ok(PixelCodec::Jpeg { quality }),
            (kind, quality) => Err(ProtocolError::Invalid(format!("pixel codec {kind} of quality {quality}"))),
        }
    }
}

/// Stage times of one tile on a worker, in milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TileTimes {
    pub decode_ms: f64,
    /// Progressive-mesh adaptation (zero for BFT tiles).
    pub adapt_ms: f64,
    pub upload_ms: f64,
    pub render_ms: f64,
    pub readback_ms: f64,
    /// Coding the pixels for the wire (`--pixel-codec`).
    pub encode_ms: f64,
}

impl TileTimes {
    pub fn total_ms(&self) -> f64 {
        self.decode_ms + self.adapt_ms + self.upload_ms + self.render_ms + self.readback_ms + self.encode_ms
    }
}

/// When a worker worked on a frame, on its own clock in milliseconds since the Unix epoch
/// ([`crate::unix_ms`]): from the start of its work (the frame's last share in) through the
/// end of its first phase (decoding the tiles, refining `.nsp` cells or adapting a
/// progressive mesh) to the end of its rendering, just before the pixels are sent. The
/// `--stats` timeline and `tessera plot` draw it; ranks on different nodes line up as well
/// as their clocks agree.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameSpan {
    pub start_ms: f64,
    pub prepared_ms: f64,
    pub end_ms: f64,
}

/// What a worker's progressive mesh held in a frame (all zero for other models and in-core
/// files' node fields).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PmMemory {
    /// Graphics memory of the adaptation: the static buffers (compressed operations or the
    /// node pool, tables), the dynamic ones at their capacities, the occlusion pyramid.
    pub gpu_bytes: u64,
    /// Out of core: node bytes uploaded this frame (the load traffic), nodes resident at its
    /// end, nodes of priority at least 1 for its view, and the pool's slots.
    pub loaded_bytes: u64,
    pub resident_nodes: u32,
    pub required_nodes: u32,
    pub slots: u32,
    /// The factor on the frame's pixel error the mesh was adapted to: above 1 where the GPU
    /// budget (or the device's binding limit) held splits back (0 for other models).
    pub error_scale: f32,
}

impl Body for Pixels {
    fn write(&self, w: &mut Writer) {
        w.u32(self.frame);
        w.u32(self.tiles.len() as u32);
        for t in &self.tiles {
            w.u32(t.index);
            w.rect(&t.rect);
            let times = &t.times;
            for v in
                [times.decode_ms, times.adapt_ms, times.upload_ms, times.render_ms, times.readback_ms, times.encode_ms]
            {
                w.f64(v);
            }
            w.u32(t.triangles);
            w.u32(t.reused);
            t.codec.write(w);
            w.u32(t.coded_bytes);
            w.bytes(&t.pixels);
        }
        let (span, pm) = (&self.span, &self.pm);
        [span.start_ms, span.prepared_ms, span.end_ms].into_iter().for_each(|v| w.f64(v));
        w.u64(pm.gpu_bytes);
        w.u64(pm.loaded_bytes);
        w.u32(pm.resident_nodes);
        w.u32(pm.required_nodes);
        w.u32(pm.slots);
        w.f32(pm.error_scale);
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        let frame = r.u32("frame")?;
        let n = r.count(86, "tiles")?;
        let mut tiles = Vec::with_capacity(n);
        for _ in 0..n {
            let index = r.u32("tile index")?;
            let rect = r.rect()?;
            let times = TileTimes {
                decode_ms: r.f64("times")?,
                adapt_ms: r.f64("times")?,
                upload_ms: r.f64("times")?,
                render_ms: r.f64("times")?,
                readback_ms: r.f64("times")?,
                encode_ms: r.f64("times")?,
            };
            let triangles = r.u32("triangles")?;
            let reused = r.u32("reused triangles")?;
            let codec = PixelCodec::read(r)?;
            let coded_bytes = r.u32("coded bytes")?;
            let pixels = r.bytes("pixels")?.to_vec();
            // In u64 and checked: a forged rect's area times 4 overflows even 64 bits (found
            // by the decode_protocol fuzz target).
            let expected = ((rect[2] - rect[0]) as u64 * (rect[3] - rect[1]) as u64).checked_mul(4);
            let fits = match codec {
                PixelCodec::Raw => expected == Some(pixels.len() as u64),
                _ => expected.is_some_and(|e| pixels.len() as u64 <= e),
            };
            if !fits {
                return Err(ProtocolError::Invalid(format!(
                    "tile {index} has {} bytes of pixels, its rectangle {rect:?} needs {}{}",
                    pixels.len(),
                    if codec == PixelCodec::Raw { "" } else { "at most " },
                    expected.map_or("more than 2^64".into(), |e| e.to_string())
                )));
            }
            tiles.push(TilePixels { index, rect, times, triangles, reused, codec, coded_bytes, pixels });
        }
        let span = FrameSpan { start_ms: r.f64("span")?, prepared_ms: r.f64("span")?, end_ms: r.f64("span")? };
        let pm = PmMemory {
            gpu_bytes: r.u64("memory")?,
            loaded_bytes: r.u64("memory")?,
            resident_nodes: r.u32("memory")?,
            required_nodes: r.u32("memory")?,
            slots: r.u32("memory")?,
            error_scale: r.f32("memory")?,
        };
        Ok(Pixels { frame, tiles, span, pm })
    }
}

impl ToMaster {
    /// The message's kind, for errors that name one without dumping its contents.
    pub fn name(&self) -> &'static str {
        match self {
            ToMaster::Ready(_) => "its adapter",
            ToMaster::Heartbeat => "a heartbeat",
            ToMaster::Pixels(_) => "pixels",
            ToMaster::Failed(_) => "a failure",
            ToMaster::DisplayReady(_) => "a display's readiness",
            ToMaster::Input(_) => "a window's input",
        }
    }

    pub fn encode(&self) -> Vec<u8> {
        match self {
            ToMaster::Ready(m) => Writer::message(READY, m),
            ToMaster::Heartbeat => Writer::new(HEARTBEAT).finish(),
            ToMaster::Pixels(m) => Writer::message(PIXELS, m),
            ToMaster::Failed(m) => Writer::message(FAILED, m),
            ToMaster::DisplayReady(m) => Writer::message(DISPLAY_READY, m),
            ToMaster::Input(m) => Writer::message(INPUT, m),
        }
    }

    pub fn decode(b: &[u8]) -> Result<ToMaster, ProtocolError> {
        let (r, kind) = Reader::open(b)?;
        Ok(match kind {
            READY => ToMaster::Ready(r.body()?),
            HEARTBEAT => {
                r.body::<()>()?;
                ToMaster::Heartbeat
            }
            PIXELS => ToMaster::Pixels(r.body()?),
            FAILED => ToMaster::Failed(r.body()?),
            DISPLAY_READY => ToMaster::DisplayReady(r.body()?),
            INPUT => ToMaster::Input(r.body()?),
            k => return Err(ProtocolError::UnknownKind(k)),
        })
    }
}
