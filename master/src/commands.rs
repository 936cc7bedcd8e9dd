//! The file commands of `tessera`: `encode`, `decode` and `stats`.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use codec::bft::chunked::{encode_chunked, ChunkOptions, EncodeChunkError, TriangleSink};
use codec::bft::{self, Stats};
use codec::input::ModelKind;
use codec::load::stream;
use codec::Mesh;
use serde::Serialize;

use crate::cli::EncodeArgs;
use crate::output::{check_distinct, check_extension, write_atomic};
use crate::progress;

/// Prints a command's summary line: on stdout, unless the output itself goes there (`-o -`).
pub fn summary(output: &Path, line: std::fmt::Arguments) -> std::io::Result<()> {
    if output.as_os_str() == "-" {
        eprintln!("{line}");
        Ok(())
    } else {
        crate::outln!("{line}")
    }
}

/// Checks, before any work, a mesh output (`.ply`, `.obj`, or `-` for PLY on stdout) that
/// must not be `input`, and returns its writer.
pub fn mesh_output(input: &Path, output: &Path, what: &str) -> Result<codec::save::WriteMesh> {
    check_extension(output, &["ply", "obj"], what)?;
    check_distinct(&[input], &[output])?;
    Ok(codec::save::writer_for(output).unwrap_or(|m, w| codec::save::write_ply(m, w)))
}

/// The kind of the file at `path` by its content alone: a Tessera model by its magic number,
/// a mesh file by [`codec::load::Format::of_file`]; `None` if it is neither (its reader
/// then says what is wrong).
fn content_kind(path: &Path) -> Option<ModelKind> {
    let mut magic = Vec::with_capacity(8);
    let file = std::fs::File::open(path).ok()?;
    std::io::Read::read_to_end(&mut std::io::Read::take(file, 8), &mut magic).ok()?;
    ModelKind::by_magic(&magic).or_else(|| codec::load::Format::of_file(path).ok().map(|_| ModelKind::Mesh))
}

/// Refuses, before any work, an input whose content is another kind of file than `want`,
/// saying which command takes it: `verb` is what the user asked for (`stats`, `adapt`,
/// `decode`), `command` the command that refuses.
pub fn expect_kind(path: &Path, want: ModelKind, command: &str, verb: &str) -> Result<()> {
    let Some(kind) = content_kind(path) else { return Ok(()) };
    if kind == want {
        return Ok(());
    }
    let what = |k: ModelKind| match k {
        ModelKind::Bft => "a .bft model",
        ModelKind::Dpm => "a .dpm progressive mesh",
        ModelKind::Nsp => "an .nsp model",
        ModelKind::Mesh => "a mesh file",
    };
    let instead = match (kind, verb) {
        (ModelKind::Bft, "stats") => "tessera stats",
        (ModelKind::Bft, _) => "tessera decode",
        (ModelKind::Dpm, "stats") => "tessera pm stats",
        (ModelKind::Dpm, _) => "tessera pm adapt",
        (ModelKind::Nsp, "stats") => "tessera nsp stats",
        (ModelKind::Nsp, _) => "tessera nsp adapt",
        (ModelKind::Mesh, _) => "tessera encode, pm build or nsp build to make a model of it",
    };
    anyhow::bail!("{}: this is {}; tessera {command} reads {}: use {instead}", path.display(), what(kind), what(want))
}

/// Reads an input file whole: regular files only (see [`codec::input::read_file`]).
pub fn read_input(path: &Path) -> Result<Vec<u8>> {
    codec::input::read_file(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

/// Loads a mesh file (OBJ, PLY, STL, glTF, optionally gzipped), with a spinner while it parses;
/// points and lines it skipped are reported on stderr.
pub fn load_mesh(path: &Path) -> Result<Mesh> {
    load_with(path, codec::load::load_path_counted)
}

/// As [`load_mesh`], reading a PLY or OBJ file in two streaming passes instead of whole into
/// memory (for the large models `pm build` takes: the memory then follows the mesh), calling
/// `between` with the vertex count before the triangles are read
/// ([`codec::load::load_path_streamed_between`]).
pub fn load_mesh_streamed(path: &Path, between: &mut dyn FnMut(usize)) -> Result<Mesh> {
    load_with(path, |p| codec::load::load_path_streamed_between(p, between))
}

fn load_with(path: &Path, load: impl FnOnce(&Path) -> Result<codec::load::Loaded, codec::LoadError>) -> Result<Mesh> {
    let pb = progress::spinner(format!("loading {}", path.display()));
    let loaded = load(path);
    pb.finish_and_clear();
    let loaded = loaded?;
    note_ignored(path, loaded.ignored);
    Ok(loaded.mesh)
}

/// Says on stderr how many points and lines a mesh file held that were skipped.
fn note_ignored(path: &Path, ignored: u64) {
    if ignored > 0 {
        eprintln!("note: {}: {ignored} point and line elements skipped (only triangles are kept)", path.display());
    }
}

/// `tessera encode IN -o OUT.bft [--quant-bits N] [--chunk-triangles N] [--temp-dir DIR]`.
///
/// A model of more than `chunk_triangles` triangles becomes a chunked file
/// (`codec::bft::chunked`), encoded out of core: the positions are read in one pass, the
/// triangles in another, and partitioned through temporary files, so memory follows the
/// vertex count, not the file. Fewer triangles give today's single-stream file, byte for
/// byte what `bft::encode` writes. The output is written to a temporary file and renamed.
pub fn encode(input: &Path, output: &Path, options: &EncodeArgs) -> Result<()> {
    check_extension(output, &["bft"], "the output of encode")?;
    check_distinct(&[input], &[output])?;
    let start = Instant::now();
    let opts = ChunkOptions {
        quant_bits: options.quant_bits,
        chunk_triangles: if options.chunk_triangles == 0 { u32::MAX } else { options.chunk_triangles },
        temp_dir: options.temp_dir.clone(),
        stream: bft::EncodeOptions {
            quant_bits: options.quant_bits,
            normal_bits: options.normal_bits,
            colors: !options.no_colors,
            normals: !options.no_normals,
            keep_order: options.keep_order,
        },
        ..Default::default()
    };
    let streamed = stream::can_stream(input);
    // PLY and OBJ are streamed: the positions in one pass, the triangles in another (inside
    // the encoder's partition pass); STL is loaded whole.
    let mesh = if streamed {
        let pb = progress::bytes(std::fs::metadata(input).map_or(0, |m| m.len()), "reading vertices");
        let vertices = stream::read_vertices(input, &mut |done| pb.set_position(done))?;
        pb.finish_and_clear();
        vertices
    } else {
        load_mesh(input)?
    };
    let positions = &mesh.positions;
    let mut ignored = 0;
    let mut source = |sink: TriangleSink| -> Result<(), EncodeChunkError> {
        if !streamed {
            return mesh.triangles.iter().try_for_each(|&t| sink(t));
        }
        // The encoder's error travels through the reader's callback and comes back as it was.
        let mut failed = None;
        let read = stream::for_each_triangle(
            input,
            positions,
            &mut |t| {
                sink(t).map_err(|e| {
                    let message = e.to_string();
                    failed = Some(e);
                    codec::LoadError { path: input.to_path_buf(), message }
                })
            },
            &mut |_| {},
        );
        match (read, failed) {
            (_, Some(e)) => Err(e),
            (Err(e), None) => Err(e.into()),
            (Ok(counts), None) => {
                ignored = counts.ignored;
                Ok(())
            }
        }
    };
    let pb = progress::bar(0, "encoding");
    let mut report = |stage: &'static str, done: u64, total: u64| {
        pb.set_message(stage);
        pb.set_length(total.max(done));
        pb.set_position(done);
    };
    let mut encoded = None;
    // An error of the input (or the encoder) is reported as itself, not as one of writing.
    let mut failed = None;
    let written = write_atomic(output, |w| match encode_chunked(&mesh, &mut source, &opts, &mut report, w) {
        Ok(e) => {
            encoded = Some(e);
            Ok(())
        }
        Err(e) => {
            let io = std::io::Error::other(e.to_string());
            failed = Some(e);
            Err(io)
        }
    });
    if let Some(e) = failed {
        return Err(anyhow::Error::new(e).context(format!("cannot encode {}", input.display())));
    }
    written.with_context(|| format!("cannot encode {}", input.display()))?;
    pb.finish_and_clear();
    note_ignored(input, ignored);
    let enc = encoded.expect("written");
    let secs = start.elapsed().as_secs_f64();
    let h = &enc.header;
    let chunks = if h.chunks > 1 { format!(" in {} chunks", h.chunks) } else { String::new() };
    summary(
        output,
        format_args!(
            "{} -> {}: {} triangles, {} vertices, {} bytes{chunks} ({:.3} bits/triangle at {} bits), {:.0} ms",
            input.display(),
            output.display(),
            h.triangles,
            h.unique_vertices,
            enc.bytes,
            enc.bytes as f64 * 8.0 / h.triangles.max(1) as f64,
            h.quant_bits,
            secs * 1e3
        ),
    )?;
    Ok(())
}

/// `tessera decode IN.bft -o OUT.ply|OUT.obj`.
pub fn decode(input: &Path, output: &Path) -> Result<()> {
    let writer = mesh_output(input, output, "the output of decode")?;
    expect_kind(input, ModelKind::Bft, "decode", "decode")?;
    let bytes = read_input(input)?;
    let start = Instant::now();
    let decoded = bft::decode(&bytes).with_context(|| format!("{}", input.display()))?;
    let mesh = decoded.to_mesh();
    let secs = start.elapsed().as_secs_f64();
    write_atomic(output, |w| writer(&mesh, w))?;
    summary(
        output,
        format_args!(
            "{} -> {}: {} triangles, {} vertices, decoded in {:.1} ms",
            input.display(),
            output.display(),
            mesh.triangles.len(),
            mesh.positions.len(),
            secs * 1e3
        ),
    )?;
    Ok(())
}

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
            color_bytes: s.color_bytes,
            color_bits_per_vertex: s.per_vertex(s.color_bytes),
            color_alpha: h.attributes.alpha,
            normal_bytes: s.normal_bytes,
            normal_bits_per_vertex: s.per_vertex(s.normal_bytes),
            normal_bits: h.attributes.normal_bits,
            order_bytes: s.order_bytes,
            order_bits_per_vertex: s.per_vertex(s.order_bytes),
        })
    }
}

/// `tessera stats IN.bft [--json]`. The whole file is decoded too, so a file whose
/// sections pass their checksums but whose streams are inconsistent is reported as corrupt.
pub fn stats(input: &Path, json: bool) -> Result<()> {
    expect_kind(input, ModelKind::Bft, "stats", "stats")?;
    let bytes = read_input(input)?;
    let mut report = StatsReport::of(&bytes).with_context(|| format!("{}", input.display()))?;
    let decoded = bft::decode(&bytes).with_context(|| format!("{}", input.display()))?;
    if report.chunks > 1 {
        // The chunks' own counts add up to more components than the model has.
        report.components = decoded.to_mesh().components() as u32;
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
    }
    Ok(())
}
