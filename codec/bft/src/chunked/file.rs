//! A chunked file opened on its source: the header and directory, each chunk read, checked
//! and decoded on use.

use std::borrow::Cow;

use super::border::Border;
use super::error::{chunk_err, corrupt, in_chunk};
use super::header::{head_len, write_head, ChunkEntry, ChunkedHeader, ENTRY_LEN};
use super::lod::Hierarchy;
use super::source::ChunkSource;
use super::{LOD_VERSION, VERSION};
use crate::bft::decode::Decoded;
use crate::bft::format::{Header, MAGIC};
use crate::container::{Format, FormatError};

/// A chunked file opened on its source (bytes in memory, or a file read by positioned reads:
/// only the header and the directory are read here).
pub struct ChunkedFile<B: ChunkSource> {
    bytes: B,
    pub header: ChunkedHeader,
    pub entries: Vec<ChunkEntry>,
    /// The level-of-detail hierarchy of a version 5 file.
    pub lod: Option<Hierarchy>,
}

impl<B: AsRef<[u8]> + Sync> ChunkedFile<B> {
    /// The file's bytes, for a file held in memory.
    pub fn bytes(&self) -> &[u8] {
        self.bytes.as_ref()
    }
}

impl<B: ChunkSource> ChunkedFile<B> {
    /// Reads and checks the header and the directory: entries contiguous and in order from the
    /// end of the directory to the end of the file, running sums and totals that agree with
    /// the header, boxes inside the quantization grid. Chunks are checked when read.
    pub fn open(bytes: B) -> Result<Self, FormatError> {
        let len = bytes.len();
        // The fixed head (magic, version, header length, and a header of at most 64 KiB with
        // its checksum), as much of it as the file has.
        let head = bytes.read_at(0, len.min(16 + u16::MAX as u64) as usize, "the header")?;
        let b = &head[..];
        if b.len() < 8 || b[..8] != MAGIC {
            return Err(if MAGIC.starts_with(b) {
                FormatError::Truncated("magic number")
            } else {
                FormatError::BadMagic(Format::Bft)
            });
        }
        let take =
            |from: usize, n: usize, what: &'static str| b.get(from..from + n).ok_or(FormatError::Truncated(what));
        let version = u16::from_le_bytes(take(8, 2, "version")?.try_into().unwrap());
        if version != VERSION && version != LOD_VERSION {
            return Err(FormatError::UnsupportedVersion {
                format: Format::Bft,
                found: version,
                known: crate::bft::READS,
            });
        }
        let hlen = u16::from_le_bytes(take(10, 2, "header length")?.try_into().unwrap()) as usize;
        let hbytes = take(12, hlen, "header")?;
        let crc = u32::from_le_bytes(take(12 + hlen, 4, "header checksum")?.try_into().unwrap());
        if crc != crc32fast::hash(hbytes) {
            return Err(FormatError::Checksum("header"));
        }
        let header = ChunkedHeader::from_bytes(hbytes)?;
        let dir_start = 16 + hlen;
        let dir_len = header.chunks as usize * ENTRY_LEN;
        if (len - (dir_start as u64).min(len)) / (ENTRY_LEN as u64) < header.chunks as u64
            || len - ((dir_start + dir_len) as u64).min(len) < 4
        {
            return Err(FormatError::Truncated("chunk directory"));
        }
        // Read only now that the file is known to hold it: the directory's length is the
        // header's chunk count times 56 bytes.
        let dir_bytes = bytes.read_at(dir_start as u64, dir_len + 4, "the chunk directory")?;
        let (dir, crc) = dir_bytes.split_at(dir_len);
        let crc = u32::from_le_bytes(crc.try_into().unwrap());
        if crc != crc32fast::hash(dir) {
            return Err(FormatError::Checksum("chunk directory"));
        }
        let mut body = (dir_start + dir_len + 4) as u64;
        let lod = if version == LOD_VERSION {
            let chunks = header.chunks as usize;
            let head = bytes.read_at(body, 8.min(len - body.min(len)) as usize, "the level-of-detail hierarchy")?;
            if head.len() < 8 {
                return Err(FormatError::Truncated("level-of-detail hierarchy"));
            }
            let section = Hierarchy::section_len(chunks, Hierarchy::groups_in(&head) as usize) as u64;
            if len - body < section {
                return Err(FormatError::Truncated("level-of-detail hierarchy"));
            }
            let b = bytes.read_at(body, section as usize, "the level-of-detail hierarchy")?;
            body += section;
            Some(Hierarchy::from_bytes(&b, chunks)?)
        } else {
            None
        };
        let model_chunks = lod.as_ref().map_or(header.chunks as usize, |h| h.level0 as usize);
        let max_level = (1u32 << header.quant_bits) - 1;
        let mut entries = Vec::with_capacity(header.chunks as usize);
        let (mut offset, mut tris, mut slots) = (body, 0u64, 0u64);
        let (mut model_tris, mut model_slots) = (0, 0);
        for (i, raw) in dir.chunks_exact(ENTRY_LEN).enumerate() {
            let e = ChunkEntry::read(raw);
            if e.offset != offset {
                return Err(chunk_err(
                    i,
                    format!("its bytes start at {} but the previous chunk ends at {offset} (ranges overlap, leave gaps or are out of order)", e.offset),
                ));
            }
            let end = e.offset + e.bft_len as u64 + e.border_len as u64;
            if end > len {
                return Err(chunk_err(i, format!("its bytes end at {end}, past the end of the file ({len} bytes)")));
            }
            if e.first_triangle as u64 != tris || e.first_slot as u64 != slots {
                return Err(chunk_err(i, "its first triangle or slot disagrees with the chunks before it"));
            }
            if e.triangles == 0 || e.slots == 0 {
                return Err(chunk_err(i, "it holds no triangle"));
            }
            if (0..3).any(|a| e.qmin[a] > e.qmax[a] || e.qmax[a] > max_level) {
                return Err(chunk_err(i, "its bounding box is not ordered inside the quantization grid"));
            }
            offset = end;
            tris += e.triangles as u64;
            slots += e.slots as u64;
            if i + 1 == model_chunks {
                (model_tris, model_slots) = (tris, slots);
            }
            entries.push(e);
        }
        if model_tris != header.triangles as u64 || model_slots != header.slots as u64 {
            return Err(corrupt(format!(
                "the model's chunks hold {model_tris} triangles and {model_slots} slots, the header says {} and {}",
                header.triangles, header.slots
            )));
        }
        if offset != len {
            return Err(FormatError::TrailingBytes((len - offset) as usize));
        }
        Ok(ChunkedFile { bytes, header, entries, lod })
    }

    /// The chunks of the full-resolution model: all of them, or a hierarchy's level 0 (the
    /// first ones).
    pub fn model_chunks(&self) -> usize {
        self.lod.as_ref().map_or(self.entries.len(), |h| h.level0 as usize)
    }

    /// The file's length in bytes.
    pub fn file_len(&self) -> u64 {
        self.bytes.len()
    }

    /// The source the file is read from.
    pub fn source(&self) -> &B {
        &self.bytes
    }

    /// The whole file's sizes, as `tessera stats` reports them: the chunks' headers summed
    /// (their sections' bytes, and counts), the border tables apart. Every chunk's container
    /// and border table is parsed and checked (not decoded). Of a level-of-detail file, the
    /// sections and tables counted are the model's (level 0); [`Self::levels`] gives each
    /// level's.
    pub fn stats(&self) -> Result<crate::bft::Stats, FormatError> {
        let g = &self.header;
        // Every slot beyond the first of its vertex, in a chunk or across chunks.
        let mut header = Header { duplicates: g.slots - g.unique_vertices, ..g.model_header() };
        let (mut connectivity_bytes, mut geometry_bytes, mut border_bytes) = (0, 0, 0);
        let (mut border_entries, mut border_links) = (0, 0);
        let (mut color_bytes, mut normal_bytes, mut order_bytes) = (0, 0, 0);
        for i in 0..self.model_chunks() {
            let bft = self.chunk_bft(i)?;
            let p = crate::bft::format::parse(&bft).map_err(|e| in_chunk(i, e))?;
            connectivity_bytes += p.sections[0].len() + p.sections[2].len() + p.sections[3].len();
            geometry_bytes += p.sections[1].len();
            color_bytes += p.sections[4].len();
            normal_bytes += p.sections[5].len();
            order_bytes += p.sections[6].len();
            border_bytes += self.entries[i].border_len as usize;
            let border = self.border(i)?;
            border_entries += border.slots.len() as u64;
            border_links += border.links.iter().flatten().count() as u64;
            add_chunk_counts(&mut header, &p.header);
        }
        Ok(crate::bft::Stats {
            header,
            bytes: self.file_len() as usize,
            connectivity_bytes,
            geometry_bytes,
            color_bytes,
            normal_bytes,
            order_bytes,
            chunks: self.entries.len() as u32,
            border_bytes,
            border_entries,
            border_links,
        })
    }

    /// A level-of-detail file's levels: per level its chunks, triangles, bytes and their
    /// parts, and largest error (object units); empty for a file without a hierarchy. Every
    /// chunk's container is parsed and checked (not decoded).
    pub fn levels(&self) -> Result<Vec<super::lod::LevelSummary>, FormatError> {
        let Some(h) = &self.lod else { return Ok(Vec::new()) };
        let mut out: Vec<super::lod::LevelSummary> = Vec::new();
        for (i, l) in h.levels().into_iter().enumerate() {
            let l = l as usize;
            if out.len() <= l {
                out.resize(l + 1, Default::default());
            }
            let (e, s) = (&self.entries[i], &mut out[l]);
            s.chunks += 1;
            s.triangles += e.triangles as u64;
            s.bytes += e.bft_len as u64 + e.border_len as u64;
            s.border_bytes += e.border_len as u64;
            let bft = self.chunk_bft(i)?;
            let p = crate::bft::format::parse(&bft).map_err(|e| in_chunk(i, e))?;
            s.connectivity_bytes += (p.sections[0].len() + p.sections[2].len() + p.sections[3].len()) as u64;
            s.geometry_bytes += p.sections[1].len() as u64;
            s.attribute_bytes += (p.sections[4].len() + p.sections[5].len() + p.sections[6].len()) as u64;
            if let Some(g) = h.groups.get(h.producer[i] as usize) {
                s.max_error = s.max_error.max(g.error);
            }
        }
        Ok(out)
    }

    /// Chunk `i`'s `.bft` stream (not yet checked): borrowed from bytes in memory, read from a
    /// file (an error if the file no longer holds it).
    pub fn chunk_bft(&self, i: usize) -> Result<Cow<'_, [u8]>, FormatError> {
        let e = &self.entries[i];
        self.bytes.read_at(e.offset, e.bft_len as usize, &format!("chunk {i}"))
    }

    /// Chunk `i`'s border table, checked.
    pub fn border(&self, i: usize) -> Result<Border, FormatError> {
        let e = &self.entries[i];
        let r = e.border_range();
        let b = self.bytes.read_at(r.start as u64, r.len(), &format!("chunk {i}"))?;
        Border::from_bytes(&b, i, e)
    }

    /// The float bounding box of chunk `i`'s dequantized slots (dequantization is monotone,
    /// so it holds every slot's float position).
    pub fn chunk_box(&self, i: usize) -> ([f32; 3], [f32; 3]) {
        let q = self.header.quantization();
        (q.dequantize(self.entries[i].qmin), q.dequantize(self.entries[i].qmax))
    }

    /// Checks that a decoded chunk agrees with its entry and the file: the same
    /// quantization, counts and bounding box.
    pub fn check_chunk(&self, i: usize, h: &Header, positions: &[[u32; 3]]) -> Result<(), FormatError> {
        let (e, g) = (&self.entries[i], &self.header);
        if h.quant_bits != g.quant_bits || h.bbox_min != g.bbox_min || h.step.to_bits() != g.step.to_bits() {
            return Err(chunk_err(i, "its quantization differs from the file's"));
        }
        if h.triangles != e.triangles || h.slots != e.slots {
            return Err(chunk_err(
                i,
                format!(
                    "it holds {} triangles and {} slots, the directory says {} and {}",
                    h.triangles, h.slots, e.triangles, e.slots
                ),
            ));
        }
        if positions.iter().any(|p| (0..3).any(|a| p[a] < e.qmin[a] || p[a] > e.qmax[a])) {
            return Err(chunk_err(i, "a position lies outside the chunk's bounding box"));
        }
        Ok(())
    }

    /// Decodes chunk `i` with the ordinary decoder and checks it against the directory.
    pub fn decode_chunk(&self, i: usize) -> Result<Decoded, FormatError> {
        let d = crate::bft::decode::decode_stream(&self.chunk_bft(i)?).map_err(|e| in_chunk(i, e))?;
        self.check_chunk(i, &d.header, &d.positions)?;
        Ok(d)
    }

    /// Decodes and checks every chunk, a batch at a time (never the whole model at once), and
    /// counts the whole model's connected components, as [`Decoded::to_mesh`] would weld it:
    /// a slot joins its duplicate's source and its border link. With the input order kept,
    /// the chunks must place the header's input vertices (the largest index is the last).
    /// Memory: 6 bytes a slot, checked against `--max-decompressed` by the header's field.
    pub fn components(&self) -> Result<usize, FormatError> {
        use rayon::prelude::*;
        let g = &self.header;
        crate::input::check_decoded("header field slots", g.slots.into(), "slots", 6).map_err(FormatError::TooLarge)?;
        let mut sets = crate::mesh::Sets::new(g.slots as usize);
        let mut used = vec![false; g.slots as usize];
        let (mut order, mut placed) = (false, 0u64);
        let batch = rayon::current_num_threads() * 8;
        let model = self.model_chunks();
        for start in (0..model).step_by(batch) {
            let parts: Vec<(Decoded, Border)> = (start..(start + batch).min(model))
                .into_par_iter()
                .map(|i| Ok((self.decode_chunk(i)?, self.border(i)?)))
                .collect::<Result<_, FormatError>>()?;
            for (k, (d, border)) in parts.iter().enumerate() {
                let base = self.entries[start + k].first_slot;
                for t in &d.triangles {
                    for &s in t {
                        used[(s + base) as usize] = true;
                        sets.join(t[0] + base, s + base);
                    }
                }
                for &(s, src) in &d.duplicates {
                    sets.join(s + base, src + base);
                }
                for (&s, link) in border.slots.iter().zip(&border.links) {
                    if let Some(l) = link {
                        sets.join(s + base, *l);
                    }
                }
                order |= d.header.attributes.order;
                placed = placed.max(d.attributes.order.iter().map(|&i| i as u64 + 1).max().unwrap_or(0));
            }
        }
        if order && placed != g.input_vertices as u64 {
            return Err(corrupt(format!(
                "header field input_vertices: {} input vertices, where the chunks' input order places {placed}",
                g.input_vertices
            )));
        }
        // A vertex's slots are one set: count the sets a triangle uses.
        Ok(sets.count(&used))
    }

    /// The whole file as one decoded model: every chunk's slots and triangles renumbered
    /// after the chunks before it, and the duplicate table extended with the border links,
    /// so that [`Decoded::to_mesh`] welds each input vertex back into one.
    pub fn decode_all(&self) -> Result<Decoded, FormatError> {
        use rayon::prelude::*;
        // The whole model's arrays, refused by their header field before any chunk decodes: a
        // decoded model gives every input vertex a place (`Decoded::to_mesh`), 12 bytes each
        // at least, and holds every slot and triangle.
        let g = &self.header;
        for (field, count, unit) in [
            ("input_vertices", g.input_vertices, "input vertices"),
            ("slots", g.slots, "slots"),
            ("triangles", g.triangles, "triangles"),
        ] {
            crate::input::check_decoded(&format!("header field {field}"), count.into(), unit, 12)
                .map_err(FormatError::TooLarge)?;
        }
        let parts: Vec<(Decoded, Border)> = (0..self.model_chunks())
            .into_par_iter()
            .map(|i| Ok((self.decode_chunk(i)?, self.border(i)?)))
            .collect::<Result<_, FormatError>>()?;
        let mut out = Decoded {
            header: g.model_header(),
            positions: Vec::with_capacity(g.slots as usize),
            triangles: Vec::with_capacity(g.triangles as usize),
            duplicates: Vec::new(),
            attributes: Default::default(),
        };
        for (i, (e, (d, border))) in self.entries.iter().zip(parts).enumerate() {
            let base = e.first_slot;
            // Every chunk carries the model's attributes (alpha only where some is not 255).
            let (a, flags) = (&mut out.attributes, d.header.attributes);
            if i == 0 {
                a.normal_bits = flags.normal_bits;
                out.header.attributes.colors = flags.colors;
                out.header.attributes.order = flags.order;
            }
            if (flags.colors, flags.normal_bits) != (out.header.attributes.colors, a.normal_bits) {
                return Err(chunk_err(i, "its attributes differ from the first chunk's"));
            }
            a.alpha |= flags.alpha;
            if flags.order != out.header.attributes.order && i > 0 {
                return Err(chunk_err(i, "it keeps the input order and the first chunk does not, or the reverse"));
            }
            a.order.extend_from_slice(&d.attributes.order);
            a.colors.extend_from_slice(&d.attributes.colors);
            a.normals.extend_from_slice(&d.attributes.normals);
            out.positions.extend_from_slice(&d.positions);
            out.triangles.extend(d.triangles.iter().map(|t| t.map(|s| s + base)));
            // A slot's link to an earlier chunk replaces its duplicate entry inside the
            // chunk: both name the same input vertex.
            let mut links =
                border.slots.iter().zip(&border.links).filter_map(|(&s, l)| l.map(|l| (s + base, l))).peekable();
            let mut dups = d.duplicates.iter().map(|&(s, src)| (s + base, src + base)).peekable();
            loop {
                let next = match (dups.peek(), links.peek()) {
                    (None, None) => break,
                    (Some(&a), Some(&b)) if a.0 < b.0 => dups.next(),
                    (Some(&a), Some(&b)) if a.0 == b.0 => {
                        dups.next();
                        links.next()
                    }
                    (Some(_), None) => dups.next(),
                    _ => links.next(),
                };
                out.duplicates.push(next.expect("peeked"));
            }
            add_chunk_counts(&mut out.header, &d.header);
        }
        out.header.duplicates = out.duplicates.len() as u32;
        // The chunks' streams checked their own counts; with the input order kept, the whole
        // model's mesh gives every input vertex of the file's header a place.
        let a = out.header.attributes;
        if a.order {
            let each = 12 + if a.colors { 4 } else { 0 } + if a.normal_bits > 0 { 12 } else { 0 };
            crate::input::check_decoded("header field input_vertices", g.input_vertices.into(), "input vertices", each)
                .map_err(FormatError::TooLarge)?;
        }
        Ok(out)
    }
}

/// Adds a chunk's own counts (loose triangles, commands, seeds, tail slots, components) to
/// the whole model's header.
fn add_chunk_counts(model: &mut Header, chunk: &Header) {
    model.loose_triangles += chunk.loose_triangles;
    model.commands += chunk.commands;
    model.seeds += chunk.seeds;
    model.tail_slots += chunk.tail_slots;
    model.components += chunk.components;
    // The model has alpha where some chunk has it.
    let (m, c) = (&mut model.attributes, chunk.attributes);
    m.colors |= c.colors;
    m.alpha |= c.alpha;
    m.normal_bits = m.normal_bits.max(c.normal_bits);
    m.order |= c.order;
}

/// Wraps arbitrary bytes in a chunked file whose header and directory checksums are valid
/// (counts and directory entries taken from the bytes, the rest as chunk data), so that a
/// fuzzer reaches the directory's checks and the chunks' parsers instead of stopping at a
/// checksum. Not a file format.
#[doc(hidden)]
pub fn wrap_for_fuzzing(data: &[u8]) -> Vec<u8> {
    let byte = |i: usize| data.get(i).copied().unwrap_or(0);
    let chunks = (byte(0) % 5) as usize;
    let dir = data.get(1..).unwrap_or(&[]);
    let dir_len = (chunks * ENTRY_LEN).min(dir.len());
    let (raw_dir, rest) = dir.split_at(dir_len);
    let mut entries: Vec<ChunkEntry> = raw_dir.chunks_exact(ENTRY_LEN).map(ChunkEntry::read).collect();
    // Half the time a level-of-detail hierarchy (version 5), its values from the bytes:
    // groups' errors and spheres, each chunk's producer and consumer (255: none).
    let lod = (byte(3) & 1 == 1 && !entries.is_empty()).then(|| {
        let n = entries.len();
        let groups = (byte(4) % 6) as usize;
        let f = |i: usize| f32::from_le_bytes([byte(i), byte(i + 1), byte(i + 2), byte(i + 3)]);
        let group = |i: usize| {
            let o = 8 + 20 * i;
            super::lod::Group { error: f(o), center: [f(o + 4), f(o + 8), f(o + 12)], radius: f(o + 16) }
        };
        let link = |i: usize| match byte(i) {
            255 => super::lod::NONE,
            b => b as u32 % (groups as u32 + 1),
        };
        Hierarchy {
            level0: (byte(5) as u32) % (n as u32 + 1),
            groups: (0..groups).map(group).collect(),
            producer: (0..n).map(|i| link(6 + 2 * i)).collect(),
            consumer: (0..n).map(|i| link(7 + 2 * i)).collect(),
        }
    });
    // Half the time, lay the entries out consistently so that the chunks themselves are read.
    let body = head_len(entries.len(), lod.as_ref());
    if byte(1) & 1 == 0 && !entries.is_empty() {
        let per = rest.len() / entries.len();
        let (mut offset, mut tris, mut slots) = (body, 0u32, 0u32);
        for e in &mut entries {
            e.offset = offset;
            e.bft_len = e.bft_len.min(per as u32);
            e.border_len = per as u32 - e.bft_len;
            e.first_triangle = tris;
            e.first_slot = slots;
            offset += per as u64;
            tris = tris.wrapping_add(e.triangles);
            slots = slots.wrapping_add(e.slots);
        }
    }
    let header = ChunkedHeader {
        input_vertices: entries.iter().fold(0u32, |a, e| a.wrapping_add(e.slots)),
        slots: entries.iter().fold(0u32, |a, e| a.wrapping_add(e.slots)),
        triangles: entries.iter().fold(0u32, |a, e| a.wrapping_add(e.triangles)),
        chunks: entries.len() as u32,
        chunk_triangles: 1,
        border_slots: 0,
        unique_vertices: 0,
        commands: 0,
        quant_bits: 8 + byte(2) % 17,
        bbox_min: [0.0; 3],
        step: 1.0,
        bbox_max: [1.0; 3],
    };
    let mut out = write_head(&header, &entries, lod.as_ref());
    let used = entries.len() * (rest.len() / entries.len().max(1));
    out.extend_from_slice(&rest[..used.min(rest.len())]);
    out
}
