//! `tessera encode`: a mesh file into a `.bft` (one stream, or chunks out of core).

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use codec::bft;
use codec::bft::chunked::{encode_chunked, ChunkOptions, EncodeChunkError, TriangleSink};
use codec::load::stream;

use crate::cli::EncodeArgs;
use crate::model::{load_mesh, note_ignored};
use crate::output::{check_distinct, check_extension, summary, write_atomic};
use crate::progress;

/// `tessera encode IN -o OUT.bft [--quant-bits N] [--chunk-triangles N] [--temp-dir DIR]`.
///
/// A model of more than `--chunk-triangles` triangles becomes a chunked file
/// (`codec::bft::chunked`), encoded out of core: the positions are read in one pass, the
/// triangles in another, and partitioned through temporary files, so memory follows the
/// vertex count, not the file. Fewer triangles give the single-stream file, byte for byte
/// what `bft::encode` writes; so does, without the flag, a model of at most
/// `ONE_STREAM_MAX_TRIANGLES`. The output is written to a temporary file and renamed.
pub fn run(input: &Path, output: &Path, options: &EncodeArgs) -> Result<()> {
    check_extension(output, &["bft"], "the output of encode")?;
    check_distinct(&[input], &[output])?;
    let start = Instant::now();
    // Without --chunk-triangles, chunks only for a model too large for one stream.
    let (chunk_triangles, one_stream_up_to) = match options.chunk_triangles {
        // A hierarchy is built over chunks, whatever the model's size.
        None if options.lod => (bft::chunked::DEFAULT_CHUNK_TRIANGLES, 0),
        None => (bft::chunked::DEFAULT_CHUNK_TRIANGLES, bft::chunked::ONE_STREAM_MAX_TRIANGLES),
        Some(0) => (u32::MAX, 0),
        Some(n) => (n, 0),
    };
    let opts = ChunkOptions {
        quant_bits: options.quant_bits,
        chunk_triangles,
        one_stream_up_to,
        temp_dir: options.temp_dir.clone(),
        lod: options.lod,
        lod_normal_weight: options.lod_normal_weight,
        stream: bft::EncodeOptions {
            quant_bits: options.quant_bits,
            normal_bits: options.normal_bits,
            colors: !options.no_colors,
            normals: !options.no_normals,
            keep_order: options.keep_order,
            coding: options.coding.into(),
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
