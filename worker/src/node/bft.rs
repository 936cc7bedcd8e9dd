//! `.bft` models on a worker, single-stream and chunked: every frame carries each tile's
//! compressed streams (a chunked model's chunks kept from frame to frame in a [`ChunkCache`]
//! per sorter, which that sorter mirrors), and with `render --sorters K` a frame comes in K
//! shares that are joined in sorter order. The streams decode in parallel, then the tiles
//! render one after the other on the one device.

use std::collections::HashMap;
use std::sync::{Arc, OnceLock};
use std::time::Instant;

use glam::Mat4;
use protocol::{unix_ms, FrameJob, PixelCodec, PmMemory, ProtocolError, StreamSource, TilePixels, TileTimes, ToWorker};
use rayon::prelude::*;

use super::model::{wrong_kind, Model, Rendered};
use super::{TileError, WorkerError};
use crate::chunk_cache::ChunkCache;
use crate::render::{Draw, GpuMesh, Renderer};
use crate::RenderMesh;

/// A `.bft` model's state on a worker: the chunks it keeps, one cache per sorter, and the
/// shares of the frame received so far, by sorter.
#[derive(Default)]
pub(super) struct BftTiles {
    chunks: Vec<ChunkCache<KeptChunk>>,
    shares: Vec<Option<FrameJob>>,
    decoded: DecodedCache,
}

/// The meshes the worker decoded the frame before, by their stream: a stream byte-identical
/// to one of them (a verbatim chunk still in view, a tile whose submesh did not change) is
/// not decoded again, and from its second frame on it is drawn from buffers of its own on
/// the device, not uploaded again. A tile's new meshes are joined and uploaded together, as
/// one draw for each run of them between kept ones: a mesh seen once is not worth buffers of
/// its own (on lavapipe, a draw and four buffers for each of a frame's few hundred sorted
/// pieces cost more than the upload they save). It keeps only the last frame's meshes,
/// within `--worker-cache-mb` (the bound of the kept chunks, given to each cache alike),
/// counting each mesh's bytes on the host and, drawn, on the device. Frames are the same
/// with it or without: the same bytes decode to the same mesh, and a tile's meshes are drawn
/// in stream order, as one mesh joined in that order would be.
#[derive(Default)]
struct DecodedCache {
    entries: HashMap<u64, Decoded>,
}

/// A stream's bytes and border normals (compared in full on a hit: the hash only finds the
/// candidate), and its mesh.
struct Decoded {
    bft: Vec<u8>,
    normals: Vec<(u32, [f32; 3])>,
    mesh: Arc<Part>,
}

/// One stream's decoded mesh and, once a frame has drawn it, its buffers on the device
/// (`None` inside for a mesh without triangles).
struct Part {
    mesh: RenderMesh,
    gpu: OnceLock<Option<GpuMesh>>,
}

impl Part {
    /// Bytes it holds on the host, and with `drawn` on the device too (what
    /// [`Renderer::upload`] makes of it: positions, normals, colours and indices).
    fn bytes(&self, drawn: bool) -> u64 {
        let m = &self.mesh;
        let host = (m.positions.len() * 24 + m.colors.len() * 4 + m.indices.len() * 4) as u64;
        let device = if drawn && !m.indices.is_empty() { m.positions.len() * 28 + m.indices.len() * 4 } else { 0 };
        host + device as u64
    }
}

impl DecodedCache {
    fn key((bft, normals): (&[u8], &[(u32, [f32; 3])])) -> u64 {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        bft.hash(&mut h);
        for (slot, n) in normals {
            slot.hash(&mut h);
            n.map(f32::to_bits).hash(&mut h);
        }
        h.finish()
    }

    fn get(&self, key: u64, (bft, normals): (&[u8], &[(u32, [f32; 3])])) -> Option<Arc<Part>> {
        self.entries.get(&key).filter(|d| d.bft == bft && d.normals == normals).map(|d| d.mesh.clone())
    }
}

impl Model for BftTiles {
    fn frame(&mut self, renderer: &mut Renderer, msg: ToWorker) -> Result<Option<Rendered>, WorkerError> {
        let ToWorker::Frame(job) = msg else { return Err(wrong_kind(&msg)) };
        // A frame comes in `sorters` shares (one unless `render --sorters K`); it renders
        // once every share is here.
        let n = job.sorters as usize;
        if self.shares.len() != n {
            self.shares = (0..n).map(|_| None).collect();
        }
        if let Some(other) = self.shares.iter().flatten().find(|s| s.frame != job.frame) {
            let why = format!("shares of frames {} and {} at once", other.frame, job.frame);
            return Err(WorkerError::BadMessage(ProtocolError::Unexpected(why)));
        }
        let sorter = job.sorter as usize;
        if self.shares[sorter].replace(job).is_some() {
            let why = format!("sorter {sorter}'s share twice");
            return Err(WorkerError::BadMessage(ProtocolError::Unexpected(why)));
        }
        if self.shares.iter().any(Option::is_none) {
            return Ok(None);
        }
        let jobs: Vec<FrameJob> = self.shares.iter_mut().map(|s| s.take().expect("every share")).collect();
        self.chunks.resize_with(n, ChunkCache::default);
        // The first tile in order that fails is the one reported.
        let meshes = tile_meshes(&jobs, &mut self.chunks, &mut self.decoded).map_err(|(index, e)| e.at(index))?;
        let prepared_ms = unix_ms();
        let mut tiles = Vec::with_capacity(meshes.len());
        for mesh in meshes {
            tiles.push(render_tile(renderer, &jobs[0], &mesh).map_err(|e| e.at(mesh.index))?);
        }
        Ok(Some(Rendered { frame: jobs[0].frame, tiles, memory: PmMemory::default(), prepared_ms: Some(prepared_ms) }))
    }
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
fn tile_meshes(
    jobs: &[FrameJob],
    chunks: &mut [ChunkCache<KeptChunk>],
    cache: &mut DecodedCache,
) -> Result<Vec<TileMesh>, (u32, TileError)> {
    let mut tiles: Vec<(u32, [u32; 4])> = Vec::new();
    let mut slot_of: HashMap<u32, usize> = HashMap::new();
    // (tile slot, chunk, stream), tile by tile in the order of first appearance.
    // A stream is read from the message where it came in it, else from the cache.
    enum Source<'a> {
        Sent(&'a [u8], &'a [(u32, [f32; 3])]),
        Kept(KeptChunk),
    }
    impl Source<'_> {
        /// The stream and its border normals.
        fn parts(&self) -> (&[u8], &[(u32, [f32; 3])]) {
            match self {
                Source::Sent(b, n) => (b, n),
                Source::Kept(k) => (&k.0, &k.1),
            }
        }
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
    // Streams the frame before decoded are taken from the cache; the rest decode in
    // parallel.
    let keys: Vec<u64> = streams.par_iter().map(|(_, _, source)| DecodedCache::key(source.parts())).collect();
    let hits: Vec<Option<Arc<Part>>> =
        streams.iter().zip(&keys).map(|((_, _, source), &key)| cache.get(key, source.parts())).collect();
    type Decoded1 = Result<(Arc<Part>, usize, f64, bool), (u32, TileError)>;
    let decoded: Vec<Decoded1> = streams
        .par_iter()
        .zip(&hits)
        .map(|((slot, chunk, source), hit)| {
            let index = tiles[*slot].0;
            if let Some(mesh) = hit {
                return Ok((mesh.clone(), mesh.mesh.triangle_count(), 0.0, true));
            }
            let (bft, normals) = source.parts();
            let (mesh, ms) = decode_stream(bft, normals).map_err(|e| match (e, chunk) {
                (TileError::Decode(e), Some(c)) => (index, TileError::ChunkDecode(*c, e)),
                (e, _) => (index, e),
            })?;
            let triangles = mesh.triangle_count();
            Ok((Arc::new(Part { mesh, gpu: OnceLock::new() }), triangles, ms, false))
        })
        .collect();
    // The cache keeps this frame's meshes (reused or new) within the bound, in stream
    // order, and forgets the rest: a reused mesh keeps its entry, a new one copies its
    // stream to compare with the next frame's.
    let limit = jobs.iter().map(|j| j.chunk_cache).max().unwrap_or(0);
    let mut before = std::mem::take(cache);
    let mut held = 0u64;
    for ((((_, _, source), &key), d), hit) in streams.iter().zip(&keys).zip(&decoded).zip(&hits) {
        let Ok((mesh, ..)) = d else { continue };
        let size = mesh.bytes(!decode_only);
        if held + size > limit || cache.entries.contains_key(&key) {
            continue;
        }
        held += size;
        let entry = hit.as_ref().and_then(|_| before.entries.remove(&key)).unwrap_or_else(|| {
            let (bft, normals) = source.parts();
            Decoded { bft: bft.to_vec(), normals: normals.to_vec(), mesh: mesh.clone() }
        });
        cache.entries.insert(key, entry);
    }
    let mut out: Vec<TileMesh> = tiles
        .iter()
        .map(|&(index, rect)| TileMesh { index, rect, parts: Vec::new(), triangles: 0, reused: 0, decode_ms: 0.0 })
        .collect();
    for ((slot, _, _), d) in streams.iter().zip(decoded) {
        let (mesh, n, ms, reused) = d?;
        out[*slot].decode_ms += ms;
        out[*slot].triangles += n as u32;
        if reused {
            out[*slot].reused += n as u32;
        }
        // With --decode-only nothing is drawn: the tile holds no mesh.
        if !decode_only {
            out[*slot].parts.push((mesh, reused));
        }
    }
    Ok(out)
}

/// A tile's streams decoded, in order (none with `--decode-only`), its triangles, and the
/// milliseconds its streams took to decode.
struct TileMesh {
    index: u32,
    rect: [u32; 4],
    /// Each with whether the frame before had it too.
    parts: Vec<(Arc<Part>, bool)>,
    triangles: u32,
    /// Of them, those taken from the frame before's meshes.
    reused: u32,
    decode_ms: f64,
}

/// Decodes one stream and applies the border normals the master sent; returns the mesh and
/// the milliseconds it took.
fn decode_stream(bft: &[u8], normals: &[(u32, [f32; 3])]) -> Result<(RenderMesh, f64), TileError> {
    let start = Instant::now();
    let decoded = codec::bft::decode(bft).map_err(TileError::Decode)?;
    // A stream with the file's normals shades with them; border normals are for computed ones.
    let file_normals = RenderMesh::has_file_normals(&decoded);
    let mut mesh = RenderMesh::from_decoded(decoded);
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
    let TileMesh { index, rect, parts, triangles, reused, decode_ms } = tile_mesh;
    let (index, rect, decode_ms) = (*index, *rect, *decode_ms);
    let (rgba, times) = if job.decode_only {
        let [x0, y0, x1, y1] = rect.map(|v| v as usize);
        (vec![0; (x1.saturating_sub(x0)) * (y1.saturating_sub(y0)) * 4], Default::default())
    } else {
        // A kept mesh gets buffers of its own on its second frame; new ones are joined.
        let (mut upload_ms, mut at) = (0.0, 0);
        let mut new: Vec<&RenderMesh> = Vec::new();
        let mut draws: Vec<Draw> = Vec::new();
        for (part, reused) in parts {
            if *reused && part.gpu.get().is_none() {
                let (gpu, ms) = renderer.upload(&part.mesh)?;
                upload_ms += ms;
                let _ = part.gpu.set(gpu);
            }
            if let Some(gpu) = part.gpu.get() {
                draws.extend(gpu.as_ref().map(Draw::Resident));
                continue;
            }
            let n = part.mesh.indices.len() as u32;
            new.push(&part.mesh);
            match draws.last_mut() {
                Some(Draw::Joined(run)) => run.end += n,
                _ => draws.push(Draw::Joined(at..at + n)),
            }
            at += n;
        }
        let joined = match new[..] {
            [one] => std::borrow::Cow::Borrowed(one),
            _ => std::borrow::Cow::Owned(RenderMesh::concat(&new)),
        };
        let view_proj = Mat4::from_cols_array(&job.view_proj);
        let (rgba, mut times) = renderer.render_parts(&joined, &draws, view_proj, (job.width, job.height), rect)?;
        times.upload_ms += upload_ms;
        (rgba, times)
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
            encode_ms: 0.0,
        },
        triangles: *triangles,
        reused: *reused,
        codec: PixelCodec::Raw,
        coded_bytes: rgba.len() as u32,
        pixels: rgba,
    })
}
