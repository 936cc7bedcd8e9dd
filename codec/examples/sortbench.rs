//! Steady-state timing of the BFT tile sort against the independent-triangle sort, one
//! process, alternating runs, medians (and the fastest run of each pass, which machine noise
//! does not move):
//! `cargo run --release -p tessera-codec --example sortbench -- MODEL.bft [COLSxROWS] [RUNS] [range|prefixbydegree|prefix]`
//! Both sorts keep their buffers from run to run, as a frame loop does; the fastest runs'
//! ratio is printed beside the medians'.
use std::time::Instant;

use codec::bft::tile_sort::{self, Sorter, TileModel};
use codec::bft::Coding;
use codec::view::{Camera, TileGrid};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("usage: sortbench MODEL.bft [COLSxROWS] [RUNS] [range|prefix]");
    let grid_arg = args.next().unwrap_or_else(|| "8x8".into());
    let runs: usize = args.next().map_or(15, |r| r.parse().expect("RUNS is a number"));
    let only = args.next();
    let (c, r) = grid_arg.split_once('x').expect("COLSxROWS");
    let model = TileModel::from_bytes(&std::fs::read(&path).expect("readable")).expect("a .bft model");
    let grid = TileGrid::new(1920, 1080, c.parse().unwrap(), r.parse().unwrap()).expect("grid");
    let h = model.decoded.header;
    let vp = Camera::framing(h.bbox_min, h.bbox_max, grid.aspect()).view_proj(grid.aspect());
    for coding in [Coding::Range, Coding::PrefixByDegree, Coding::Prefix] {
        if only.as_deref().is_some_and(|o| !format!("{coding:?}").eq_ignore_ascii_case(o)) {
            continue;
        }
        run(&model, &path, &grid_arg, &grid, vp, runs, coding);
    }
}

fn run(model: &TileModel, path: &str, grid_arg: &str, grid: &TileGrid, vp: glam::Mat4, runs: usize, coding: Coding) {
    let (mut sorter, mut b) = (Sorter::new(coding), tile_sort::Boxes::default());
    let mut tri_buffers = codec::tri_sort::TriBuffers::default();
    let (mut pass1, mut pass2, mut tri) = (vec![], vec![], vec![]);
    let mut bytes = 0;
    for _ in 0..runs {
        let t = Instant::now();
        tile_sort::boxes_into(model, vp, grid, &mut b);
        let t1 = t.elapsed().as_secs_f64() * 1e3;
        let tiles = sorter.sort(model, &b, grid).expect("sorts");
        pass1.push(t1);
        pass2.push(t.elapsed().as_secs_f64() * 1e3 - t1);
        bytes = tiles.iter().map(|t| t.bytes.len()).sum::<usize>();
        let t = Instant::now();
        codec::tri_sort::sort_into(&model.positions, model.triangles(), vp, grid, &mut tri_buffers);
        std::hint::black_box(&tri_buffers.tiles);
        tri.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let fastest = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
    let (best1, best2, best_tri) = (fastest(&pass1), fastest(&pass2), fastest(&tri));
    let (p1, p2, tr) = (median(pass1), median(pass2), median(tri));
    println!(
        "{path} {grid_arg} {coding:?}: BFT sort {:.1} ms (pass 1 {p1:.1}, pass 2 {p2:.1}), Tri sort {tr:.1} ms, ratio {:.2}, \
         {bytes} tile bytes; fastest passes {best1:.1} + {best2:.1} ms, fastest Tri sort {best_tri:.1} ms, ratio {:.2}",
        p1 + p2,
        (p1 + p2) / tr,
        (best1 + best2) / best_tri
    );
}
