//! `tessera stats`: a `.bft`'s sizes, counts and bits per triangle, as text or JSON.

use std::path::Path;

use anyhow::{Context, Result};
use codec::bft::{self, Stats};
use codec::kind::ModelKind;
use serde::Serialize;

use crate::model::{expect_kind, read_input};

/// The numbers `tessera stats --json` prints.
#[derive(Debug, Serialize)]
pub struct StatsReport {
    pub triangles: u32,
    /// Distinct vertices after welding duplicate slots.
    pub vertices: u32,
    pub components: u32,
    pub bytes: usize,
    pub connectivity_bits_per_triangle: f64,
    pub geometry_bits_per_vertex: f64,
    pub quant_bits: u8,
    pub connectivity_bytes: usize,
    pub geometry_bytes: usize,
    pub input_vertices: u32,
    pub slots: u32,
    pub duplicate_slots: u32,
    pub loose_triangles: u32,
    pub seeds: u32,
    pub commands: u32,
    pub bbox_min: [f32; 3],
    pub bbox_max: [f32; 3],
    /// Chunks (1 for a single-stream file) and the bytes of their border tables.
    pub chunks: u32,
    pub border_bytes: usize,
    /// The border tables' entries, of which `border_links` link to an earlier slot, and the
    /// bytes of their normals (4 an entry).
    pub border_entries: u64,
    pub border_links: u64,
    pub border_normal_bytes: u64,
    /// Per-vertex attributes: bytes and bits per vertex (0 where absent), normal bits.
    pub color_bytes: usize,
    pub color_bits_per_vertex: f64,
    pub color_alpha: bool,
    pub normal_bytes: usize,
    pub normal_bits_per_vertex: f64,
    pub normal_bits: u8,
    /// The stored input vertex order (`encode --keep-order`): bytes and bits per vertex.
    pub order_bytes: usize,
    pub order_bits_per_vertex: f64,
    /// A level-of-detail file's levels (`encode --lod`), from the model (level 0) up; the
    /// counts above are the model's, `bytes` the whole file's.
    pub levels: Vec<LevelReport>,
}

/// One level of a level-of-detail file.
#[derive(Debug, Serialize)]
pub struct LevelReport {
    pub chunks: u32,
    pub triangles: u64,
    pub bytes: u64,
    /// Of `bytes`: the streams' connectivity, geometry and attributes, and the border tables
    /// (the rest: the streams' headers).
    pub connectivity_bytes: u64,
    pub geometry_bytes: u64,
    pub attribute_bytes: u64,
    pub border_bytes: u64,
    /// The largest object-space error of the level's chunks.
    pub max_error: f32,
}

impl StatsReport {
    pub fn of(bytes: &[u8]) -> Result<Self> {
        let s = Stats::of(bytes)?;
        let h = s.header;
        Ok(StatsReport {
            triangles: h.triangles,
            vertices: h.unique_vertices(),
            components: h.components,
            bytes: s.bytes,
            connectivity_bits_per_triangle: s.connectivity_bits_per_triangle(),
            geometry_bits_per_vertex: s.geometry_bits_per_vertex(),
            quant_bits: h.quant_bits,
            connectivity_bytes: s.connectivity_bytes,
            geometry_bytes: s.geometry_bytes,
            input_vertices: h.input_vertices,
            slots: h.slots,
            duplicate_slots: h.duplicates,
            loose_triangles: h.loose_triangles,
            seeds: h.seeds,
            commands: h.commands,
            bbox_min: h.bbox_min,
            bbox_max: h.bbox_max,
            chunks: s.chunks,
            border_bytes: s.border_bytes,
            border_entries: s.border_entries,
            border_links: s.border_links,
            border_normal_bytes: s.border_entries * 4,
            color_bytes: s.color_bytes,
            color_bits_per_vertex: s.per_vertex(s.color_bytes),
            color_alpha: h.attributes.alpha,
            normal_bytes: s.normal_bytes,
            normal_bits_per_vertex: s.per_vertex(s.normal_bytes),
            normal_bits: h.attributes.normal_bits,
            order_bytes: s.order_bytes,
            order_bits_per_vertex: s.per_vertex(s.order_bytes),
            levels: Vec::new(),
        })
    }
}

/// `tessera stats IN.bft [--json]`. The file is decoded too (a chunked one chunk by chunk),
/// so a file whose sections pass their checksums but whose streams are inconsistent is
/// reported as corrupt.
pub fn run(input: &Path, json: bool) -> Result<()> {
    expect_kind(input, ModelKind::Bft, "stats", "stats")?;
    let bytes = read_input(input)?;
    let mut report = StatsReport::of(&bytes).with_context(|| format!("{}", input.display()))?;
    if bft::chunked::is_chunked(&bytes) {
        // Chunk by chunk: a chunked model is larger than what decodes whole (the 223M
        // model's arrays would take gigabytes), and the chunks' own counts add up to more
        // components than the model has.
        let file = bft::chunked::ChunkedFile::open(&bytes[..]).with_context(|| format!("{}", input.display()))?;
        report.components = file.components().with_context(|| format!("{}", input.display()))? as u32;
        report.levels = file
            .levels()
            .with_context(|| format!("{}", input.display()))?
            .into_iter()
            .map(|l| LevelReport {
                chunks: l.chunks,
                triangles: l.triangles,
                bytes: l.bytes,
                connectivity_bytes: l.connectivity_bytes,
                geometry_bytes: l.geometry_bytes,
                attribute_bytes: l.attribute_bytes,
                border_bytes: l.border_bytes,
                max_error: l.max_error,
            })
            .collect();
    } else {
        bft::decode(&bytes).with_context(|| format!("{}", input.display()))?;
    }
    if json {
        crate::outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        let r = &report;
        crate::outln!("{}", input.display())?;
        crate::outln!(
            "  triangles      {:>12}   ({} components, {} loose)",
            r.triangles,
            r.components,
            r.loose_triangles
        )?;
        crate::outln!("  vertices       {:>12}   ({} slots, {} duplicated)", r.vertices, r.slots, r.duplicate_slots)?;
        crate::outln!("  bytes          {:>12}", r.bytes)?;
        if r.chunks > 1 {
            crate::outln!("  chunks         {:>12}   ({} bytes of border tables)", r.chunks, r.border_bytes)?;
            crate::outln!(
                "  border entries {:>12}   ({} linked to an earlier slot; {} bytes of normals)",
                r.border_entries,
                r.border_links,
                r.border_normal_bytes
            )?;
        }
        crate::outln!(
            "  connectivity   {:>12.3} bits/triangle ({} bytes)",
            r.connectivity_bits_per_triangle,
            r.connectivity_bytes
        )?;
        crate::outln!(
            "  geometry       {:>12.2} bits/vertex at {} bits ({} bytes)",
            r.geometry_bits_per_vertex,
            r.quant_bits,
            r.geometry_bytes
        )?;
        if r.color_bytes > 0 {
            let kind = if r.color_alpha { "RGBA" } else { "RGB" };
            crate::outln!(
                "  colours        {:>12.2} bits/vertex, 8-bit {kind} ({} bytes)",
                r.color_bits_per_vertex,
                r.color_bytes
            )?;
        }
        if r.normal_bytes > 0 {
            crate::outln!(
                "  normals        {:>12.2} bits/vertex, octahedral at {} bits ({} bytes)",
                r.normal_bits_per_vertex,
                r.normal_bits,
                r.normal_bytes
            )?;
        }
        if r.order_bytes > 0 {
            crate::outln!("  vertex order   {:>12.2} bits/vertex ({} bytes)", r.order_bits_per_vertex, r.order_bytes)?;
        }
        crate::outln!("  total          {:>12.2} bits/triangle", r.bytes as f64 * 8.0 / r.triangles.max(1) as f64)?;
        for (k, l) in r.levels.iter().enumerate() {
            crate::outln!(
                "  level {k:<2}       {:>12}   triangles in {} chunks, {} bytes ({:.2} bits/triangle), error {:.3e}",
                l.triangles,
                l.chunks,
                l.bytes,
                l.bytes as f64 * 8.0 / l.triangles.max(1) as f64,
                l.max_error
            )?;
            let bits = |b: u64| b as f64 * 8.0 / l.triangles.max(1) as f64;
            crate::outln!(
                "                 bits/triangle: connectivity {:.2}, geometry {:.2}, attributes {:.2}, border tables {:.2}, headers {:.2}",
                bits(l.connectivity_bytes),
                bits(l.geometry_bytes),
                bits(l.attribute_bytes),
                bits(l.border_bytes),
                bits(l.bytes - l.connectivity_bytes - l.geometry_bytes - l.attribute_bytes - l.border_bytes)
            )?;
        }
    }
    Ok(())
}
