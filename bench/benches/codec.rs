//! Tessera's BFT codec against meshopt and draco-core, on the same meshes, in one run.
//!
//! Every peer is set up the way its users would run it at 14-bit positions, as
//! `tessera_bench::peers` says (the bandwidth experiment uses the same set-up):
//! - BFT: `codec::bft::encode` with `quant_bits: 14`.
//! - meshopt: 14-bit quantized positions, vertex-cache then vertex-fetch optimised, then the
//!   index and vertex codecs. No general-purpose compressor on top.
//! - Draco: compression level 7 (the `draco_encoder` CLI default, speed 3), 14-bit positions.
//!
//! Beside the file, `bft-tile` decodes what a worker decodes: the whole mesh as one
//! prefix-coded tile stream (the tile sort's `--tile-coding prefix` output for a 1x1 grid
//! that sees every triangle), which must decode to exactly the file's slots and triangles.
//!
//! Criterion measures decode (and our encode) in triangles/s; afterwards a plain summary
//! table, timed here with `Instant`, gives sizes, rates and ratios against the targets.
//! `TESSERA_BENCH_QUICK=1` restricts the run to the bunny for a fast smoke test.

use std::hint::black_box;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use criterion::{Criterion, SamplingMode, Throughput};
use tessera_bench::peers::{draco_decode, draco_encode, Meshopt};

const QUANT_BITS: u8 = 14;
/// Runs per codec behind each median in the summary table.
const SUMMARY_RUNS: usize = 5;
const SUMMARY_RUN_MIN: Duration = Duration::from_millis(50);

/// Project targets, printed next to the measured values.
const TARGET_SIZE_VS_DRACO: f64 = 1.25;
const TARGET_DECODE_VS_MESHOPT: f64 = 0.5;
const TARGET_TILE_DECODE_VS_MESHOPT: f64 = 0.3;
const TARGET_ENCODE_MTRI_S: f64 = 2.0;
const TARGET_CONNECTIVITY_BITS_PER_TRIANGLE: f64 = 2.0;

/// (name in reports, path under the shared mesh folder)
const MESHES: [(&str, &str); 2] =
    [("dragon", "stanford/dragon_vrip.ply.gz"), ("bunny", "stanford/bunny_zipper_c3d.obj.gz")];

fn mesh_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/meshes"))
}

/// One mesh with every peer's encoding of it.
struct Prepared {
    name: &'static str,
    mesh: codec::Mesh,
    bft: Vec<u8>,
    /// The whole mesh as one prefix-coded tile stream.
    tile: Vec<u8>,
    meshopt: Meshopt,
    draco: Vec<u8>,
    /// Draco's EdgeBreaker leaves out triangles with a repeated vertex; BFT and meshopt keep them.
    draco_triangles: usize,
}

impl Prepared {
    fn new(name: &'static str, mesh: codec::Mesh) -> Prepared {
        let bft = codec::bft::encode(
            &mesh,
            codec::bft::EncodeOptions { quant_bits: QUANT_BITS, colors: false, normals: false, ..Default::default() },
        )
        .unwrap_or_else(|e| panic!("{name}: BFT encode failed: {e}"))
        .bytes;
        let tile = whole_tile(name, &bft);
        let meshopt = encode_meshopt(&mesh);
        let draco = encode_draco(name, &mesh);
        let draco_triangles = mesh.triangles.iter().filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2]).count();
        let prepared = Prepared { name, mesh, bft, tile, meshopt, draco, draco_triangles };
        prepared.check_round_trips();
        prepared
    }

    fn triangles(&self) -> usize {
        self.mesh.triangles.len()
    }

    /// Each peer must give back the mesh it was handed, or its speed means nothing.
    fn check_round_trips(&self) {
        let ours = decode_bft(&self.bft);
        assert_eq!(ours.triangles.len(), self.triangles(), "{}: BFT triangle count", self.name);
        let tile = decode_bft(&self.tile);
        assert!(
            tile.positions == ours.positions && tile.triangles == ours.triangles,
            "{}: the tile stream decodes to other slots or triangles than the file",
            self.name
        );

        let (indices, vertices) = decode_meshopt(&self.meshopt);
        assert_eq!(indices.len() / 3, self.triangles(), "{}: meshopt triangle count", self.name);
        assert_eq!(vertices.len(), self.meshopt.vertex_count, "{}: meshopt vertex count", self.name);

        let draco = decode_draco(&self.draco);
        assert_eq!(draco.num_faces(), self.draco_triangles, "{}: Draco triangle count", self.name);
    }
}

/// The mesh's whole tile stream, prefix-coded: one tile that sees every triangle.
fn whole_tile(name: &str, bft: &[u8]) -> Vec<u8> {
    use codec::bft::tile_sort::{boxes, Sorter, TileModel};
    let model = TileModel::from_bytes(bft).unwrap_or_else(|e| panic!("{name}: {e}"));
    let grid = codec::view::TileGrid::new(1920, 1080, 1, 1).expect("a 1x1 grid");
    let h = &model.decoded.header;
    let view_proj = codec::view::Camera::framing(h.bbox_min, h.bbox_max, grid.aspect()).view_proj(grid.aspect());
    let mut tiles = Sorter::new(codec::bft::Coding::Prefix)
        .sort(&model, &boxes(&model, view_proj, &grid), &grid)
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    assert!(
        tiles.len() == 1 && tiles[0].triangles as usize == model.triangles().len(),
        "{name}: a tile misses triangles"
    );
    tiles.remove(0).bytes
}

fn encode_meshopt(mesh: &codec::Mesh) -> Meshopt {
    let quant = codec::Quantization::fit(&mesh.positions, None, QUANT_BITS).expect("14 bits is a valid quantization");
    let quantized: Vec<[u32; 3]> = mesh.positions.iter().map(|&p| quant.quantize(p)).collect();
    Meshopt::encode_quantized(&mesh.triangles, &quantized, QUANT_BITS).expect("meshopt encode")
}

fn encode_draco(name: &str, mesh: &codec::Mesh) -> Vec<u8> {
    draco_encode(&mesh.positions, &mesh.triangles, QUANT_BITS)
        .unwrap_or_else(|e| panic!("{name}: Draco encode failed: {e}"))
}

fn decode_bft(bytes: &[u8]) -> codec::bft::Decoded {
    codec::bft::decode(bytes).expect("BFT decode")
}

fn decode_meshopt(m: &Meshopt) -> (Vec<u32>, Vec<[u16; 4]>) {
    m.decode::<[u16; 4]>().expect("meshopt decode")
}

fn decode_draco(bytes: &[u8]) -> draco_core::Mesh {
    draco_decode(bytes).expect("Draco decode")
}

fn bench_mesh(c: &mut Criterion, p: &Prepared) {
    let triangles = p.triangles() as u64;

    let mut group = c.benchmark_group(format!("decode/{}", p.name));
    group.throughput(Throughput::Elements(triangles));
    // A dragon decode takes tens of milliseconds or more: flat sampling keeps criterion from
    // asking for the 55x-sample iteration ramp that linear sampling would need.
    group.sampling_mode(SamplingMode::Flat);
    group.bench_function("bft", |b| b.iter(|| decode_bft(black_box(&p.bft))));
    group.bench_function("bft-tile", |b| b.iter(|| decode_bft(black_box(&p.tile))));
    group.bench_function("meshopt", |b| b.iter(|| decode_meshopt(black_box(&p.meshopt))));
    group.bench_function("draco", |b| b.iter(|| decode_draco(black_box(&p.draco))));
    group.finish();

    let mut group = c.benchmark_group(format!("encode/{}", p.name));
    group.throughput(Throughput::Elements(triangles));
    group.sampling_mode(SamplingMode::Flat);
    let options =
        codec::bft::EncodeOptions { quant_bits: QUANT_BITS, colors: false, normals: false, ..Default::default() };
    group.bench_function("bft", |b| b.iter(|| codec::bft::encode(black_box(&p.mesh), options).expect("BFT encode")));
    group.finish();
}

/// Median per-call wall time over `SUMMARY_RUNS` runs, independent of criterion's estimates.
/// Each run repeats the call enough times to last `SUMMARY_RUN_MIN`, so a bunny decode of a
/// few milliseconds is not at the mercy of timer and scheduler noise.
fn median_time<T>(mut f: impl FnMut() -> T) -> Duration {
    let start = Instant::now();
    black_box(f());
    let once = start.elapsed().max(Duration::from_micros(1));
    let calls = SUMMARY_RUN_MIN.as_nanos().div_ceil(once.as_nanos()).max(1) as u32;
    let mut times: Vec<Duration> = (0..SUMMARY_RUNS)
        .map(|_| {
            let start = Instant::now();
            for _ in 0..calls {
                black_box(f());
            }
            start.elapsed() / calls
        })
        .collect();
    times.sort();
    times[SUMMARY_RUNS / 2]
}

fn mtri_per_s(triangles: usize, t: Duration) -> f64 {
    triangles as f64 / t.as_secs_f64() / 1e6
}

fn verdict(ok: bool) -> &'static str {
    if ok {
        "ok"
    } else {
        "MISSED"
    }
}

fn print_summary(p: &Prepared) {
    let n = p.triangles();
    let stats = codec::bft::Stats::of(&p.bft).expect("BFT stats");
    let bft_t = median_time(|| decode_bft(&p.bft));
    let tile_t = median_time(|| decode_bft(&p.tile));
    let meshopt_t = median_time(|| decode_meshopt(&p.meshopt));
    let draco_t = median_time(|| decode_draco(&p.draco));
    let options =
        codec::bft::EncodeOptions { quant_bits: QUANT_BITS, colors: false, normals: false, ..Default::default() };
    let encode_t = median_time(|| codec::bft::encode(&p.mesh, options).expect("BFT encode"));

    let meshopt_bytes = p.meshopt.bytes();
    let bits_per_tri = |bytes: usize| bytes as f64 * 8.0 / n as f64;
    let (bft_rate, meshopt_rate, draco_rate) = (mtri_per_s(n, bft_t), mtri_per_s(n, meshopt_t), mtri_per_s(n, draco_t));
    let encode_rate = mtri_per_s(n, encode_t);
    let size_vs_draco = p.bft.len() as f64 / p.draco.len() as f64;
    let decode_vs_meshopt = bft_rate / meshopt_rate;
    let conn_bpt = stats.connectivity_bits_per_triangle();

    println!();
    println!(
        "== {}: {} triangles, {} vertices, {QUANT_BITS}-bit positions (medians of {SUMMARY_RUNS} runs) ==",
        p.name,
        n,
        p.mesh.positions.len()
    );
    println!("{:<9} {:>10} {:>10} {:>14}", "codec", "bytes", "bits/tri", "decode Mtri/s");
    let tile_rate = mtri_per_s(n, tile_t);
    for (codec, bytes, rate) in [
        ("bft", p.bft.len(), bft_rate),
        ("bft-tile", p.tile.len(), tile_rate),
        ("meshopt", meshopt_bytes, meshopt_rate),
        ("draco", p.draco.len(), draco_rate),
    ] {
        println!("{codec:<9} {bytes:>10} {:>10.3} {rate:>14.2}", bits_per_tri(bytes));
    }
    if p.draco_triangles != n {
        println!("(draco dropped {} degenerate triangles; its rates still count all {n})", n - p.draco_triangles);
    }
    println!(
        "size    ours/draco   {size_vs_draco:.3}  (target <= {TARGET_SIZE_VS_DRACO})  {}",
        verdict(size_vs_draco <= TARGET_SIZE_VS_DRACO)
    );
    println!("size    ours/meshopt {:.3}", p.bft.len() as f64 / meshopt_bytes as f64);
    println!(
        "decode  ours/meshopt {decode_vs_meshopt:.3}  (goal >= {TARGET_DECODE_VS_MESHOPT})  {}",
        verdict(decode_vs_meshopt >= TARGET_DECODE_VS_MESHOPT)
    );
    println!("decode  ours/draco   {:.3}", bft_rate / draco_rate);
    let tile_vs_meshopt = tile_rate / meshopt_rate;
    println!(
        "decode  tile/meshopt {tile_vs_meshopt:.3}  (target >= {TARGET_TILE_DECODE_VS_MESHOPT})  {}",
        verdict(tile_vs_meshopt >= TARGET_TILE_DECODE_VS_MESHOPT)
    );
    println!("decode  tile/draco   {:.3}", tile_rate / draco_rate);
    println!(
        "encode  ours         {encode_rate:.2} Mtri/s  (target >= {TARGET_ENCODE_MTRI_S})  {}",
        verdict(encode_rate >= TARGET_ENCODE_MTRI_S)
    );
    println!(
        "bft     connectivity {conn_bpt:.3} bits/tri  (target <= {TARGET_CONNECTIVITY_BITS_PER_TRIANGLE})  {}",
        verdict(conn_bpt <= TARGET_CONNECTIVITY_BITS_PER_TRIANGLE)
    );
    println!("bft     geometry     {:.3} bits/vertex", stats.geometry_bits_per_vertex());
}

fn main() {
    let quick = std::env::var("TESSERA_BENCH_QUICK").is_ok_and(|v| v == "1");
    let selected: Vec<_> = MESHES.iter().filter(|(name, _)| !quick || *name == "bunny").collect();

    let prepared: Vec<Prepared> = selected
        .iter()
        .map(|&&(name, file)| {
            let path = mesh_dir().join(file);
            let mesh = codec::load_path(&path).unwrap_or_else(|e| panic!("cannot load {}: {e}", path.display()));
            Prepared::new(name, mesh)
        })
        .collect();

    // Small samples and short windows: the dragon alone is ~1M triangles per iteration, and the
    // whole run has to fit in a few minutes on two cores.
    let mut c = Criterion::default()
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
        .without_plots()
        .configure_from_args();
    for p in &prepared {
        bench_mesh(&mut c, p);
    }
    c.final_summary();

    for p in &prepared {
        print_summary(p);
    }
}
