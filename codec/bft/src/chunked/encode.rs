//! The chunked encoder, out of core: it holds the positions (12 bytes a vertex) and a few
//! bytes of bookkeeping per vertex, never the triangles.
//!
//! 1. **Partition.** One pass over the triangles marks the used vertices and writes each
//!    triangle to a spatial bucket (a cell of a coarse grid over the model's box, by its
//!    centroid), in temporary files when the model is large. A bucket is then read back and
//!    cut by a kd-tree on the centroids (median splits on the longest axis) into chunks of at
//!    most `chunk_triangles`, each keeping its triangles in input order. The chunks of a
//!    bucket follow its kd-tree's leaves; buckets follow each other in grid order. Which
//!    chunks use each vertex is noted on the way (first chunk, and whether another does).
//!    With `lod`, the hierarchy is built above the chunks from that spill, level by level
//!    ([`super::lod::build`]), each level spilled in turn.
//! 2. **Encode.** Batches of chunks are encoded in parallel (rayon) with the ordinary encoder
//!    on the whole model's quantization; the encoder keeps the triangles in the order a
//!    decoder will have them, in which the face normals of the border vertices are summed;
//!    the streams go to a temporary file in chunk order.
//! 3. **Write.** The header, the directory, and each chunk's stream followed by its border
//!    table, whose normals are now complete.
//!
//! Peak memory: the positions, 6 bytes per vertex of bookkeeping, the border vertices'
//! tables, and one bucket or one batch of chunks at a time; with `lod`, 4 bytes per vertex
//! more (its normal, or a level's chunk numbers while its shared vertices are found) and a
//! batch of groups.

use std::collections::HashMap;
use std::io::{self, Read, Write};
use std::path::PathBuf;

use glam::Vec3;
use rayon::prelude::*;
use thiserror::Error;

use super::border::{oct_decode, oct_encode, Border};
use super::header::{head_len, write_head, ChunkEntry, ChunkedHeader};
use super::partition::{centroid, localize, split};
use super::spill::{batches, read_triangles, ChunkWriter, Chunks, Spill};
use super::DEFAULT_CHUNK_TRIANGLES;
use crate::bft::encode::{encode_quantized, EncodeOptions};
use crate::bft::format::Header;
use crate::bft::normals::{add_face_normals, face_normal_sums, unit};
use crate::load::LoadError;
use crate::mesh::{bounding_box, Mesh, MeshError, Quantization};

/// Chunked encoder settings.
#[derive(Clone, Debug)]
pub struct ChunkOptions {
    /// Bits per quantized coordinate, 8 to 24.
    pub quant_bits: u8,
    /// Triangles per chunk at most. Smaller chunks let a frame skip and forward more of the
    /// model untouched, and cost more bytes at their borders (see the README's figures).
    pub chunk_triangles: u32,
    /// A model of at most this many triangles whose vertices fit one partition bucket (at
    /// most 4M) is written as one stream whatever `chunk_triangles` says (0: never).
    pub one_stream_up_to: u64,
    /// Where temporary files go (the system's temporary folder if `None`).
    pub temp_dir: Option<PathBuf>,
    /// Return the input vertex of every slot ([`ChunkedEncoded::slot_vertex`]), for tests.
    pub keep_slot_vertex: bool,
    /// Write a model that makes one chunk as a single-stream file (version 2), which it is
    /// (the default); else as a chunked file of one chunk.
    pub one_chunk_as_stream: bool,
    /// What each chunk's stream codes besides positions (its `quant_bits` is ignored).
    pub stream: EncodeOptions,
    /// Build a level-of-detail hierarchy above the chunks ([`super::lod`]): the file is
    /// version 5, and a model of one chunk is still one stream.
    pub lod: bool,
    /// The weight of normals in the hierarchy's simplification error
    /// ([`super::lod::NORMAL_WEIGHT`] by default; 0 for positions alone).
    pub lod_normal_weight: f32,
}

impl Default for ChunkOptions {
    fn default() -> Self {
        ChunkOptions {
            quant_bits: Quantization::DEFAULT_BITS,
            chunk_triangles: DEFAULT_CHUNK_TRIANGLES,
            one_stream_up_to: 0,
            temp_dir: None,
            keep_slot_vertex: false,
            one_chunk_as_stream: true,
            stream: EncodeOptions::default(),
            lod: false,
            lod_normal_weight: super::lod::NORMAL_WEIGHT,
        }
    }
}

/// Why the chunked encoder failed.
#[derive(Debug, Error)]
pub enum EncodeChunkError {
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error(transparent)]
    Load(#[from] LoadError),
    #[error("temporary or output file: {0}")]
    Io(#[from] io::Error),
    #[error("the model is too large for a chunked file: {0}")]
    TooLarge(String),
    #[error("chunk size must be at least 1 triangle")]
    ChunkSize,
}

/// What the chunked encoder wrote.
#[derive(Clone, Debug)]
pub struct ChunkedEncoded {
    pub header: ChunkedHeader,
    pub bytes: u64,
    /// The input vertex of each slot, when asked for.
    pub slot_vertex: Vec<u32>,
}

/// The stage [`encode_chunked`] reports progress of: `(stage, done, total)`, totals in
/// triangles (0 while unknown).
pub type Progress<'a> = &'a mut dyn FnMut(&'static str, u64, u64);

/// A sink for triangles, and a source that feeds every triangle of the model to a sink once.
pub type TriangleSink<'a> = &'a mut dyn FnMut([u32; 3]) -> Result<(), EncodeChunkError>;

/// Encodes an in-memory mesh as a chunked file, into memory.
pub fn encode_mesh_chunked(mesh: &Mesh, options: &ChunkOptions) -> Result<(Vec<u8>, ChunkedEncoded), EncodeChunkError> {
    let mut out = Vec::new();
    let enc = encode_chunked(
        mesh,
        &mut |sink: TriangleSink| mesh.triangles.iter().try_for_each(|&t| sink(t)),
        options,
        &mut |_, _, _| {},
        &mut out,
    )?;
    Ok((out, enc))
}

/// One encoded chunk, before its place in the file is known.
struct Encoded {
    bytes: Vec<u8>,
    triangles: u32,
    /// The input vertex of each slot.
    slot_vertex: Vec<u32>,
    qmin: [u32; 3],
    qmax: [u32; 3],
    /// `(input vertex, sum of its face normals in the chunk)` for the chunk's border
    /// vertices, one per vertex.
    partial_normals: Vec<(u32, Vec3)>,
    commands: u32,
}

/// Encodes one chunk of `vertices`' triangles; `normals`, where given, replace the model's
/// (a level-of-detail chunk's full-resolution normals).
fn encode_chunk(
    vertices: &Mesh,
    normals: Option<&(dyn Fn(u32) -> [f32; 3] + Sync)>,
    quant: Quantization,
    options: &EncodeOptions,
    multi: &(dyn Fn(u32) -> bool + Sync),
    tris: &[[u32; 3]],
) -> Result<Encoded, EncodeChunkError> {
    let (verts, local) = localize(tris);
    let pick = |values: &[[f32; 3]]| verts.iter().map(|&v| values[v as usize]).collect();
    let mesh = Mesh {
        positions: pick(&vertices.positions),
        triangles: local.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
        colors: if vertices.colors.is_empty() {
            Vec::new()
        } else {
            verts.iter().map(|&v| vertices.colors[v as usize]).collect()
        },
        normals: match (normals, &vertices.normals[..]) {
            (Some(normal), _) => verts.iter().map(|&v| normal(v)).collect(),
            (None, []) => Vec::new(),
            (None, n) => pick(n),
        },
    };
    let input = (&verts[..], vertices.positions.len() as u32);
    // A chunk with vertices that other chunks share sums their face normals in the decoded
    // triangle order, which is what a worker sums: the encoder keeps that order for it, so
    // the chunk is not decoded again (decoding every chunk was a tenth of a hierarchy's
    // build, in CPU time, on the 13.9M-triangle dragon).
    let sums = verts.iter().any(|&v| multi(v));
    let enc = encode_quantized(&mesh, &vec![true; verts.len()], quant, options, Some(input), sums, &mut |_, _| {})?;
    let slot_vertex: Vec<u32> = enc.slot_vertex.iter().map(|&l| verts[l as usize]).collect();
    // Every vertex of the chunk is a slot (a triangle uses it), so the slots' box is the
    // vertices' quantized box.
    let quantized: Vec<[u32; 3]> = mesh.positions.iter().map(|p| quant.quantize(*p)).collect();
    let mut qmin = [u32::MAX; 3];
    let mut qmax = [0u32; 3];
    for p in &quantized {
        for a in 0..3 {
            qmin[a] = qmin[a].min(p[a]);
            qmax[a] = qmax[a].max(p[a]);
        }
    }
    let partial_normals = if sums {
        let fp: Vec<[f32; 3]> = enc.slot_vertex.iter().map(|&l| quant.dequantize(quantized[l as usize])).collect();
        let (source, acc) = face_normal_sums(&fp, &enc.slot_triangles, &enc.duplicates);
        (0..fp.len())
            .filter(|&s| source[s] as usize == s && multi(slot_vertex[s]))
            .map(|s| (slot_vertex[s], acc[s]))
            .collect()
    } else {
        Vec::new()
    };
    Ok(Encoded {
        bytes: enc.bytes,
        triangles: tris.len() as u32,
        slot_vertex,
        qmin,
        qmax,
        partial_normals,
        commands: enc.header.commands,
    })
}

/// The model's vertex normals from level 0's chunks (`multi`: the vertices several chunks
/// use), as a worker computes them (face normals over rendered positions, summed), stored
/// octahedral in 4 bytes a vertex: each chunk's own vertices are complete when it is read,
/// the shared ones are summed in a map.
fn level0_normals(
    level0: &Chunks,
    vertices: usize,
    render: &(dyn Fn(u32) -> [f32; 3] + Sync),
    multi: &[bool],
) -> io::Result<Vec<[u16; 2]>> {
    let mut oct = vec![[0u16; 2]; vertices];
    let mut shared: rustc_hash::FxHashMap<u32, Vec3> = Default::default();
    for batch in batches(level0.len()) {
        let sums: Vec<(Vec<u32>, Vec<Vec3>)> = batch
            .into_par_iter()
            .map(|c| {
                let tris = level0.read(c)?;
                let (verts, local) = localize(&tris);
                let pos: Vec<[f32; 3]> = verts.iter().map(|&v| render(v)).collect();
                let mut acc = vec![Vec3::ZERO; verts.len()];
                let local: &[[u32; 3]] = bytemuck::cast_slice(&local);
                add_face_normals(&pos, local, |l| l, &mut acc);
                Ok((verts, acc))
            })
            .collect::<io::Result<_>>()?;
        for (verts, acc) in sums {
            for (v, sum) in verts.into_iter().zip(acc) {
                if multi[v as usize] {
                    *shared.entry(v).or_insert(Vec3::ZERO) += sum;
                } else {
                    oct[v as usize] = oct_encode(unit(sum));
                }
            }
        }
    }
    for (v, sum) in shared {
        oct[v as usize] = oct_encode(unit(sum));
    }
    Ok(oct)
}

/// Encodes a model as a chunked `.bft` file written to `out`. `vertices` holds all input
/// vertices (positions, and colours and normals if the model has them; its triangles are not
/// read); `triangles` feeds every triangle to the sink it is given, once, in input order.
pub fn encode_chunked(
    vertices: &Mesh,
    triangles: &mut dyn FnMut(TriangleSink) -> Result<(), EncodeChunkError>,
    options: &ChunkOptions,
    progress: Progress,
    out: &mut dyn Write,
) -> Result<ChunkedEncoded, EncodeChunkError> {
    let positions = &vertices.positions;
    let n = positions.len();
    if n > 1 << 31 {
        return Err(MeshError::TooManyVertices(n).into());
    }
    if options.chunk_triangles == 0 {
        return Err(EncodeChunkError::ChunkSize);
    }
    if !(8..=24).contains(&options.quant_bits) {
        return Err(MeshError::QuantBits(options.quant_bits).into());
    }
    let target = options.chunk_triangles as usize;

    // 1. Partition into buckets of a grid of 8^b cells, b from the expected triangle count
    //    (about twice the vertices) so that a bucket holds a few million triangles.
    let finite = positions.iter().filter(|p| p.iter().all(|c| c.is_finite()));
    let (lo, hi) = bounding_box(finite).unwrap_or(([0.0; 3], [1.0; 3]));
    let expected = 2 * n as u64;
    let bits = match expected {
        0..=8_000_000 => 0u32,
        8_000_001..=64_000_000 => 1,
        64_000_001..=512_000_000 => 2,
        _ => 3,
    };
    let cells = 1usize << (3 * bits);
    let mut buckets: Vec<Spill> =
        (0..cells).map(|_| Spill::new(bits > 0, &options.temp_dir)).collect::<Result<_, _>>()?;
    let mut counts = vec![0usize; cells];
    let mut used = vec![false; n];
    let mut total = 0u64;
    let side = (1u32 << bits) as f32;
    let cell_of = |c: [f32; 3]| -> usize {
        let k = |a: usize| {
            let e = hi[a] - lo[a];
            let f = if e > 0.0 { (c[a] - lo[a]) / e * side } else { 0.0 };
            // NaN (an unused vertex's) and out-of-range values clamp into the grid.
            (f.max(0.0) as u32).min((1 << bits) - 1) as usize
        };
        (k(2) << (2 * bits)) | (k(1) << bits) | k(0)
    };
    triangles(&mut |t: [u32; 3]| {
        if let Some(&bad) = t.iter().find(|&&v| v as usize >= n) {
            return Err(MeshError::IndexOutOfRange { triangle: total as usize, index: bad, vertices: n }.into());
        }
        for v in t {
            used[v as usize] = true;
        }
        let cell = if bits == 0 { 0 } else { cell_of(centroid(positions, t)) };
        let mut b = [0u8; 12];
        for (k, v) in t.iter().enumerate() {
            b[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
        }
        buckets[cell].write(&b)?;
        counts[cell] += 1;
        total += 1;
        if total.is_multiple_of(1 << 20) {
            progress("partitioning", total, 0);
        }
        Ok(())
    })?;
    if total >= u32::MAX as u64 {
        return Err(MeshError::TooManyTriangles(total as usize).into());
    }
    if let Some(v) = (0..n).find(|&v| used[v] && !positions[v].iter().all(|c| c.is_finite())) {
        return Err(MeshError::NonFinite { vertex: v, value: positions[v] }.into());
    }
    let quant = Quantization::fit(positions, Some(&used), options.quant_bits)?;
    let unique_vertices = used.iter().filter(|&&u| u).count() as u32;
    drop(used);
    // A model small enough for one stream is one chunk: the single-stream file, byte for byte.
    let target = if total <= options.one_stream_up_to && cells == 1 { usize::MAX } else { target };

    //    Buckets into chunks; chunk-ordered triangles into one spill, noting which vertices
    //    several chunks use.
    let mut owner = vec![u32::MAX; n];
    let mut multi = vec![false; n];
    let mut ordered = ChunkWriter::new(bits > 0, &options.temp_dir)?;
    for (bucket, &count) in buckets.drain(..).zip(&counts) {
        if count == 0 {
            continue;
        }
        let tris = read_triangles(&mut *bucket.reader()?, count)?;
        let (idx, leaves) = split(positions, &tris, target);
        for leaf in leaves {
            let chunk = ordered.len() as u32;
            let members = &idx[leaf];
            for &t in members.iter() {
                for v in tris[t as usize] {
                    let o = &mut owner[v as usize];
                    if *o == u32::MAX {
                        *o = chunk;
                    } else if *o != chunk {
                        multi[v as usize] = true;
                    }
                }
            }
            ordered.push(members.iter().map(|&t| tris[t as usize]))?;
        }
    }
    drop(owner);
    let ordered = ordered.finish()?;
    let level0 = ordered.len();

    //    The hierarchy above the chunks, out of core (`super::lod`). Above level 0 every
    //    chunk stores its vertices' full-resolution normals in its stream (the model's own,
    //    or those the worker computes from level 0), so that a coarse chunk shades as the
    //    surface it stands for, and its border table is empty.
    let render = |v: u32| quant.dequantize(quant.quantize(positions[v as usize]));
    let computed_normals = if options.lod && level0 > 1 && vertices.normals.is_empty() {
        Some(level0_normals(&ordered, n, &render, &multi)?)
    } else {
        None
    };
    let normal = |v: u32| match &computed_normals {
        Some(oct) => oct_decode(oct[v as usize]),
        None => vertices.normals[v as usize],
    };
    let built = if options.lod && level0 > 1 {
        let model = super::lod::Vertices { count: n, position: &render, normal: &normal };
        let spill = || ChunkWriter::new(bits > 0, &options.temp_dir);
        Some(super::lod::build(&model, &ordered, target, options.lod_normal_weight, &spill, &mut |done| {
            progress("simplifying", done, total)
        })?)
    } else {
        None
    };
    // Every chunk's store and its first chunk number.
    let mut stores: Vec<(usize, &Chunks)> = vec![(0, &ordered)];
    for level in built.iter().flat_map(|b| &b.levels) {
        let (start, last) = stores.last().unwrap();
        stores.push((start + last.len(), level));
    }
    let locate = |c: usize| {
        let (start, store) = stores[stores.partition_point(|s| s.0 <= c) - 1];
        (store, c - start)
    };
    let chunk_size = |c: usize| {
        let (store, k) = locate(c);
        store.size(k)
    };
    let chunks = stores.last().map(|(start, s)| start + s.len()).unwrap_or(0);
    let upper_stream = EncodeOptions { normals: true, ..options.stream };
    if chunks > u32::MAX as usize / 2 {
        return Err(EncodeChunkError::TooLarge(format!("{chunks} chunks")));
    }

    // 2. Encode in batches of chunks, in parallel; place them in order.
    let mut streams = Spill::new(bits > 0, &options.temp_dir)?;
    let mut entries: Vec<ChunkEntry> = Vec::with_capacity(chunks);
    let mut borders: Vec<(Border, Vec<u32>)> = Vec::with_capacity(chunks);
    let mut first_slot: HashMap<u32, u32> = HashMap::new();
    let mut normal_sums: HashMap<u32, Vec3> = HashMap::new();
    let mut slot_vertex = Vec::new();
    let (mut slots, mut tris_done, mut commands) = (0u64, 0u64, 0u64);
    let (mut model_slots, mut model_commands) = (0u64, 0u64);
    let batch_triangles = rayon::current_num_threads().saturating_mul(8).saturating_mul(target).max(1 << 20);
    let mut next = 0;
    while next < chunks {
        let mut end = next;
        let mut size = 0;
        while end < chunks && (end == next || size + chunk_size(end) <= batch_triangles) {
            size += chunk_size(end);
            end += 1;
        }
        let batch: Vec<Vec<[u32; 3]>> = (next..end)
            .map(|c| {
                let (store, k) = locate(c);
                store.read(k)
            })
            .collect::<Result<_, _>>()?;
        let upper = |c: usize| built.is_some() && c >= level0;
        let encoded: Vec<Encoded> = batch
            .par_iter()
            .enumerate()
            .with_max_len(1)
            .map(|(k, tris)| match upper(next + k) {
                true => encode_chunk(vertices, Some(&normal), quant, &upper_stream, &|_| false, tris),
                false => encode_chunk(vertices, None, quant, &options.stream, &|v| multi[v as usize], tris),
            })
            .collect::<Result<_, _>>()?;
        for (k, enc) in encoded.into_iter().enumerate() {
            let c = next + k;
            let upper = upper(c);
            let is_border = |v: u32| !upper && multi[v as usize];
            let base = slots;
            let n_slots = enc.slot_vertex.len() as u64;
            if base + n_slots >= u32::MAX as u64 {
                return Err(EncodeChunkError::TooLarge(format!("more than {} vertex slots", u32::MAX)));
            }
            let mut border = Border::default();
            let mut border_vertices = Vec::new();
            for (s, &v) in enc.slot_vertex.iter().enumerate() {
                if is_border(v) {
                    let global = (base + s as u64) as u32;
                    border.slots.push(s as u32);
                    border.links.push(match first_slot.entry(v) {
                        std::collections::hash_map::Entry::Occupied(o) => Some(*o.get()),
                        std::collections::hash_map::Entry::Vacant(e) => {
                            e.insert(global);
                            None
                        }
                    });
                    border_vertices.push(v);
                }
            }
            for (v, sum) in enc.partial_normals {
                *normal_sums.entry(v).or_insert(Vec3::ZERO) += sum;
            }
            if options.keep_slot_vertex {
                slot_vertex.extend_from_slice(&enc.slot_vertex);
            }
            streams.write(&enc.bytes)?;
            entries.push(ChunkEntry {
                offset: 0,
                bft_len: enc.bytes.len() as u32,
                border_len: 0,
                triangles: enc.triangles,
                slots: n_slots as u32,
                first_triangle: tris_done as u32,
                first_slot: base as u32,
                qmin: enc.qmin,
                qmax: enc.qmax,
            });
            borders.push((border, border_vertices));
            slots += n_slots;
            tris_done += enc.triangles as u64;
            commands += enc.commands as u64;
            if c < level0 {
                (model_slots, model_commands) = (slots, commands);
            }
        }
        progress("encoding", tris_done, total.max(tris_done));
        next = end;
    }
    drop(first_slot);

    // 3. Border normals are complete: lay the file out and write it.
    let mut border_slots = 0u64;
    let tables: Vec<Vec<u8>> = borders
        .into_iter()
        .enumerate()
        .map(|(c, (mut border, vertices))| {
            if c < level0 {
                border_slots += border.slots.len() as u64;
            }
            border.normals = vertices.iter().map(|v| oct_decode(oct_encode(unit(normal_sums[v])))).collect();
            border.to_bytes()
        })
        .collect();
    let hierarchy = built.map(|b| b.hierarchy);
    let mut offset = head_len(chunks, hierarchy.as_ref());
    for (e, t) in entries.iter_mut().zip(&tables) {
        e.offset = offset;
        e.border_len = t.len() as u32;
        offset += e.bft_len as u64 + e.border_len as u64;
    }
    let top = entries[..level0].iter().fold([0u32; 3], |m, e| [0, 1, 2].map(|a| m[a].max(e.qmax[a])));
    let header = ChunkedHeader {
        input_vertices: n as u32,
        slots: model_slots as u32,
        triangles: total as u32,
        chunks: chunks as u32,
        chunk_triangles: options.chunk_triangles,
        border_slots: border_slots as u32,
        unique_vertices,
        commands: model_commands.min(u32::MAX as u64) as u32,
        quant_bits: quant.bits,
        bbox_min: quant.min,
        step: quant.step,
        bbox_max: quant.dequantize(top),
    };
    if chunks == 1 && options.one_chunk_as_stream {
        // One chunk is today's model: its stream alone, as a single-stream file, with the
        // input's vertex count (unused vertices included) in its header, as `bft::encode`
        // writes it (the chunk numbers the used vertices in input order, so its traversal is
        // `bft::encode`'s, and so are its bytes).
        let mut stream = vec![0u8; entries[0].bft_len as usize];
        streams.reader()?.read_exact(&mut stream)?;
        let parts = crate::bft::format::parse(&stream).map_err(|e| io::Error::other(e.to_string()))?;
        let single = crate::bft::format::write(&Header { input_vertices: n as u32, ..parts.header }, parts.sections);
        out.write_all(&single)?;
        progress("writing", total, total);
        return Ok(ChunkedEncoded { header, bytes: single.len() as u64, slot_vertex });
    }
    out.write_all(&write_head(&header, &entries, hierarchy.as_ref()))?;
    let mut streams = streams.reader()?;
    let mut buf = Vec::new();
    for (e, table) in entries.iter().zip(&tables) {
        buf.resize(e.bft_len as usize, 0);
        streams.read_exact(&mut buf)?;
        out.write_all(&buf)?;
        out.write_all(table)?;
    }
    progress("writing", total, total);
    Ok(ChunkedEncoded { header, bytes: offset, slot_vertex })
}
