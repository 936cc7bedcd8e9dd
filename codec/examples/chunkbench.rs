//! Chunked against single-stream sorting of one model, in one process, alternating runs:
//! per chunk size, the file's bytes, the frame's tile bytes (verbatim chunks counted whole,
//! with their border normals excluded as for the single stream) and the median sort time
//! with a warm cache, beside the single stream's.
//! `cargo run --release -p tessera-codec --example chunkbench -- MESH [COLSxROWS] [RUNS] [CHUNK ...]`
use std::time::Instant;

use codec::bft::chunked::sort::{ChunkedModel, PieceKind};
use codec::bft::chunked::{encode_mesh_chunked, ChunkOptions, ChunkedFile};
use codec::bft::tile_sort::{self, Sorter, TileModel};
use codec::bft::{self, Coding, EncodeOptions};
use codec::view::{Camera, TileGrid};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("usage: chunkbench MESH [COLSxROWS] [RUNS] [CHUNK ...]");
    let grid_arg = args.next().unwrap_or_else(|| "8x8".into());
    let runs: usize = args.next().map_or(11, |r| r.parse().expect("RUNS is a number"));
    let mut sizes: Vec<u32> = args.map(|a| a.parse().expect("CHUNK is a number")).collect();
    if sizes.is_empty() {
        sizes = vec![4096, 8192, 16384, 32768, 65536];
    }
    let (c, r) = grid_arg.split_once('x').expect("COLSxROWS");
    let grid = TileGrid::new(1920, 1080, c.parse().unwrap(), r.parse().unwrap()).expect("grid");
    let mesh = codec::load_path(std::path::Path::new(&path)).expect("a mesh");
    let bits = 14;
    let single = bft::encode(&mesh, EncodeOptions { quant_bits: bits, ..Default::default() }).unwrap();
    let model = TileModel::from_bytes(&single.bytes).unwrap();
    let h = model.decoded.header;
    let vp = Camera::framing(h.bbox_min, h.bbox_max, grid.aspect()).view_proj(grid.aspect());
    let chunked: Vec<(u32, ChunkedModel<Vec<u8>>)> = sizes
        .iter()
        .map(|&s| {
            let opts = ChunkOptions { quant_bits: bits, chunk_triangles: s, ..Default::default() };
            let (bytes, _) = encode_mesh_chunked(&mesh, &opts).unwrap();
            // Sorts of the same view time the sort, tables cached, not the reuse of the last.
            let mut m = ChunkedModel::new(ChunkedFile::open(bytes).unwrap(), 1 << 30);
            m.keep_sorts = false;
            (s, m)
        })
        .collect();
    for coding in [Coding::Prefix, Coding::Range] {
        let (mut sorter, mut b) = (Sorter::new(coding), tile_sort::Boxes::default());
        let mut single_ms = vec![];
        let mut chunk_ms = vec![vec![]; chunked.len()];
        let mut single_bytes = 0;
        let mut chunk_bytes = vec![(0usize, Default::default()); chunked.len()];
        for _ in 0..runs {
            let t = Instant::now();
            tile_sort::boxes_into(&model, vp, &grid, &mut b);
            let tiles = sorter.sort(&model, &b, &grid).unwrap();
            single_ms.push(t.elapsed().as_secs_f64() * 1e3);
            single_bytes = tiles.iter().map(|t| t.bytes.len()).sum::<usize>();
            for (k, (_, m)) in chunked.iter().enumerate() {
                let t = Instant::now();
                let (tiles, counts) = m.sort(vp, &grid, coding).unwrap();
                chunk_ms[k].push(t.elapsed().as_secs_f64() * 1e3);
                let bytes = tiles
                    .iter()
                    .flat_map(|t| &t.pieces)
                    .map(|p| match &p.kind {
                        PieceKind::Verbatim => m.file.entries[p.chunk as usize].bft_len as usize,
                        PieceKind::Sorted { bytes, .. } => bytes.len(),
                    })
                    .sum();
                chunk_bytes[k] = (bytes, counts);
            }
        }
        let s = median(single_ms);
        println!(
            "{path} {grid_arg} {coding:?}: single stream {} file bytes, {single_bytes} tile bytes, sort {s:.1} ms",
            single.bytes.len()
        );
        for (k, (size, m)) in chunked.iter().enumerate() {
            let ms = median(chunk_ms[k].clone());
            let (bytes, c) = chunk_bytes[k];
            println!(
                "  chunks of {size}: {} chunks, {} file bytes ({:.3}x), {bytes} tile bytes ({:.3}x), sort {ms:.1} ms ({:.2}x); \
                 verbatim {} straddling {} ({} triangles) culled {}",
                m.chunks(),
                m.file.bytes().len(),
                m.file.bytes().len() as f64 / single.bytes.len() as f64,
                bytes as f64 / single_bytes as f64,
                ms / s,
                c.verbatim,
                c.straddling,
                c.straddling_triangles,
                c.culled
            );
        }
    }
}
