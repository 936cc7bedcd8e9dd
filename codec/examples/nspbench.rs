//! Builds an `.nsp` from a mesh and reports size, cells, build and decode speed:
//! `cargo run --release -p tessera-codec --example nspbench -- MESH BITS ROOT_BITS SPLITS N_MIN`.

use std::time::Instant;

use codec::nsp::{self, Canonical, NspFile, Params};

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let path = std::path::Path::new(&a[1]);
    let num = |i: usize, d: u32| a.get(i).map(|s| s.parse().unwrap()).unwrap_or(d);
    let params = Params {
        bits: num(2, 16) as u8,
        root_bits: num(3, 7) as u8,
        splits: num(4, 4),
        min_simplices: num(5, 8000),
        advance: 0,
    };
    let t = Instant::now();
    let mesh = codec::load_path(path).unwrap();
    let load = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let canon = Canonical::of_mesh(&mesh, params.bits).unwrap();
    let t_canon = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let built = nsp::encode(&canon, params, &|_| {}).unwrap();
    let t_enc = t.elapsed().as_secs_f64();
    let bytes = built.bytes.len();
    let v = canon.points.len() as f64;
    println!(
        "{}: {} input triangles, {} canonical triangles, {} points; load {load:.2}s",
        path.display(),
        mesh.triangles.len(),
        canon.triangles(),
        canon.points.len()
    );
    println!(
        "p={} p_r={} n={} N_min={}: {} cells, {} bytes ({:.2} bpv), build {:.2}s + canonical {t_canon:.2}s = {:.0} tri/s",
        params.bits,
        params.root_bits,
        params.splits,
        params.min_simplices,
        built.tree.nodes.len(),
        bytes,
        bytes as f64 * 8.0 / v,
        t_enc,
        mesh.triangles.len() as f64 / (t_enc + t_canon)
    );
    println!(
        "decisions (bpv): geometry {} ({:.2}) connectivity {} ({:.2}) orientation {} ({:.2}); leaf duplication {:.3}",
        built.decisions[0],
        built.cost_bits[0] / v,
        built.decisions[1],
        built.cost_bits[1] / v,
        built.decisions[2],
        built.cost_bits[2] / v,
        built.leaf_simplices as f64 / canon.simplices.len() as f64
    );
    let file = NspFile::from_bytes(built.bytes).unwrap();
    // Every non-empty leaf at full precision through a navigator, which counts every vertex
    // split (ancestors' included).
    let cut: Vec<(u32, u8)> = (0..file.tree.nodes.len() as u32)
        .filter(|&c| file.tree.is_leaf(c) && file.entries[c as usize].len > 0)
        .map(|c| (c, params.bits))
        .collect();
    let t = Instant::now();
    let mut nav = nsp::view::Navigator::default();
    let states = nav.update(&file, &cut).unwrap();
    let t_dec = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let drawn = nsp::view::draw(&file, &cut, &states);
    println!(
        "full decode {t_dec:.2}s: {} cells decoded, {} vertex splits ({:.2} M/s on {} threads; RAYON_NUM_THREADS=1 for one core), draw {:.2}s: {} triangles",
        nav.cells(),
        nav.splits,
        nav.splits as f64 / t_dec / 1e6,
        rayon::current_num_threads(),
        t.elapsed().as_secs_f64(),
        drawn.triangles.len()
    );
}
