//! `Frame`: a frame of a sorted model (`.bft`, chunked or not), or one sorter's share of it,
//! for one worker: its tiles, each one or more compressed streams with their border normals.

use crate::wire::{Body, Reader, Writer};
use crate::ProtocolError;

/// A frame's tiles for one worker, from rank 0 or from one sorter rank.
///
/// ```text
/// frame u32, width u32, height u32, view_proj 16 x f32 (column-major),
/// flags u8 (bit 0: decode only, do not rasterize; other bits zero),
/// sorter u8, sorters u8 (this message is sorter's share of the frame; a worker renders once
///   it has all `sorters` shares),
/// chunk cache bound u64 (bytes), tile count u32, then per tile:
///   index u32, rect 4 x u32 (x0 y0 x1 y1), stream count u32, per stream:
///     source u8: 0 bytes: bft length u32 + bytes
///                1 a chunk to keep: chunk u32, bft length u32 + bytes
///                2 a chunk kept before: chunk u32
///     normal count u32, then per normal: slot u32, 3 x f32
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct FrameJob {
    pub frame: u32,
    pub width: u32,
    pub height: u32,
    pub view_proj: [f32; 16],
    /// Decode the tiles but do not rasterize them (`render --decode-only`): the answer's
    /// pixels are transparent, so the distribution can be measured apart from the renderer.
    pub decode_only: bool,
    /// Which share of the frame this is (`render --sorters K`: sorter ranks send one each,
    /// in chunk order by sorter) and how many shares there are.
    pub sorter: u8,
    pub sorters: u8,
    /// The bound of the worker's chunk cache for this sorter's chunks, in bytes.
    pub chunk_cache: u64,
    pub tiles: Vec<TileJob>,
}

/// One tile of a frame, as the master sends it.
#[derive(Clone, Debug, PartialEq)]
pub struct TileJob {
    pub index: u32,
    pub rect: [u32; 4],
    /// The tile's compressed submeshes, drawn in order.
    pub streams: Vec<TileStream>,
}

/// One `.bft` stream of a tile.
#[derive(Clone, Debug, PartialEq)]
pub struct TileStream {
    pub source: StreamSource,
    /// `(stream slot, unit normal)` for vertices with triangles outside the stream.
    pub normals: Vec<(u32, [f32; 3])>,
}

/// Where a stream's bytes are.
#[derive(Clone, Debug, PartialEq)]
pub enum StreamSource {
    /// In the message: a tile submesh.
    Bytes(Vec<u8>),
    /// In the message, a verbatim chunk the worker keeps in its chunk cache.
    Keep { chunk: u32, bft: Vec<u8> },
    /// A chunk the worker kept before (no normals come with it: they were kept too).
    Kept { chunk: u32 },
}

impl TileStream {
    /// Bytes of `.bft` stream the message carries.
    pub fn bft_len(&self) -> usize {
        match &self.source {
            StreamSource::Bytes(b) | StreamSource::Keep { bft: b, .. } => b.len(),
            StreamSource::Kept { .. } => 0,
        }
    }
}

impl Body for FrameJob {
    fn write(&self, w: &mut Writer) {
        for v in [self.frame, self.width, self.height] {
            w.u32(v);
        }
        w.matrix(&self.view_proj);
        w.u8(self.decode_only as u8);
        w.u8(self.sorter);
        w.u8(self.sorters);
        w.u64(self.chunk_cache);
        w.u32(self.tiles.len() as u32);
        for t in &self.tiles {
            w.u32(t.index);
            w.rect(&t.rect);
            w.u32(t.streams.len() as u32);
            for st in &t.streams {
                match &st.source {
                    StreamSource::Bytes(b) => {
                        w.u8(0);
                        w.bytes(b);
                    }
                    StreamSource::Keep { chunk, bft } => {
                        w.u8(1);
                        w.u32(*chunk);
                        w.bytes(bft);
                    }
                    StreamSource::Kept { chunk } => {
                        w.u8(2);
                        w.u32(*chunk);
                    }
                }
                w.u32(st.normals.len() as u32);
                for (slot, n) in &st.normals {
                    w.u32(*slot);
                    n.iter().for_each(|&c| w.f32(c));
                }
            }
        }
    }

    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        let (frame, width, height) = (r.u32("frame")?, r.u32("width")?, r.u32("height")?);
        let view_proj = r.matrix("view_proj")?;
        let decode_only = match r.u8("flags")? {
            0 => false,
            1 => true,
            f => return Err(ProtocolError::Invalid(format!("unknown frame flags {f:#04x}"))),
        };
        let (sorter, sorters) = (r.u8("sorter")?, r.u8("sorter")?);
        if sorter >= sorters {
            return Err(ProtocolError::Invalid(format!("sorter {sorter} of {sorters}")));
        }
        let chunk_cache = r.u64("chunk cache bound")?;
        let n = r.count(24, "tiles")?;
        let mut tiles = Vec::with_capacity(n);
        for _ in 0..n {
            let index = r.u32("tile index")?;
            let rect = r.rect()?;
            let k = r.count(9, "streams")?;
            let mut streams = Vec::with_capacity(k);
            for _ in 0..k {
                let source = match r.u8("stream source")? {
                    0 => StreamSource::Bytes(r.bytes("tile submesh")?.to_vec()),
                    1 => StreamSource::Keep { chunk: r.u32("chunk")?, bft: r.bytes("chunk stream")?.to_vec() },
                    2 => StreamSource::Kept { chunk: r.u32("chunk")? },
                    s => return Err(ProtocolError::Invalid(format!("unknown stream source {s}"))),
                };
                let m = r.count(16, "normals")?;
                let mut normals = Vec::with_capacity(m);
                for _ in 0..m {
                    normals.push((r.u32("normal slot")?, [r.f32("normal")?, r.f32("normal")?, r.f32("normal")?]));
                }
                streams.push(TileStream { source, normals });
            }
            tiles.push(TileJob { index, rect, streams });
        }
        Ok(FrameJob { frame, width, height, view_proj, decode_only, sorter, sorters, chunk_cache, tiles })
    }
}
