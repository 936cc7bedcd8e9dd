use codec::bft::tile_sort::{boxes, Sorter, TileModel};
use codec::bft::Coding;
use codec::view::{Camera, TileGrid};
use std::time::Instant;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let bytes = std::fs::read(&a[1]).unwrap();
    let model = TileModel::from_bytes(&bytes).unwrap();
    let grid = TileGrid::new(1920, 1080, 1, 1).unwrap();
    let h = &model.decoded.header;
    let cam = Camera::framing(h.bbox_min, h.bbox_max, grid.aspect());
    let vp = cam.view_proj(grid.aspect());
    let bx = boxes(&model, vp, &grid);
    let reps: usize = a.get(2).map_or(9, |s| s.parse().unwrap());
    for coding in [Coding::Prefix] {
        let tiles = Sorter::new(coding).sort(&model, &bx, &grid).unwrap();
        let t0 = &tiles[0];
        let mut ts = vec![];
        for _ in 0..reps {
            let t = Instant::now();
            let d = codec::bft::decode(&t0.bytes).unwrap();
            ts.push(t.elapsed().as_secs_f64());
            std::hint::black_box(d);
        }
        ts.sort_by(f64::total_cmp);
        println!(
            "{:?}: {} bytes, {} tri, {:.1} ms, {:.2} Mtri/s",
            coding,
            t0.bytes.len(),
            t0.triangles,
            ts[reps / 2] * 1e3,
            t0.triangles as f64 / ts[reps / 2] / 1e6
        );
    }
}
