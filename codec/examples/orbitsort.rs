//! Rank 0's sort of a chunked model along an orbit, in one process: frames turning DEGREES
//! about the model's up axis from the framing camera, 1920x1080 in 8x8 prefix-coded tiles;
//! the median and fastest sort of frames 3 to 23 (the tables cached, the frame before's
//! pieces kept) and the share of the straddling chunks' pieces' triangles (once per tile a
//! triangle is in) taken from the frame before; and the median time to decode each frame's
//! sorted pieces one after another on one thread, as a worker decodes what it is sent.
//! With ERROR_PX, a level-of-detail file draws the cut of that many pixels (`render
//! --error-px`).
//! With CLOSE=1 in the environment, the camera is `bench/scripts/scale.sh`'s close-up (the eye
//! 0.3 model sizes outside the box's +Z face, looking at its centre, 12 degrees), orbiting
//! its target.
//! `cargo run --release -p tessera-codec --example orbitsort -- MODEL.bft [DEGREES] [ERROR_PX]`
use codec::bft::chunked::sort::{ChunkedModel, PieceKind};
use codec::bft::chunked::ChunkedFile;
use codec::bft::Coding;
use codec::view::{Camera, TileGrid};

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("usage: orbitsort MODEL.bft [DEGREES] [ERROR_PX]");
    let degrees: f32 = args.next().map_or(1.0, |s| s.parse().expect("DEGREES is a number"));
    let file = ChunkedFile::open(std::fs::read(&path).expect("readable")).expect("a chunked .bft");
    let mut model = ChunkedModel::new(file, 1 << 30);
    model.error_px = args.next().map(|s| s.parse().expect("ERROR_PX is a number"));
    let grid = TileGrid::new(1920, 1080, 8, 8).expect("grid");
    let h = &model.file.header;
    let mut cam = Camera::framing(h.bbox_min, h.bbox_max, grid.aspect());
    if std::env::var_os("CLOSE").is_some_and(|v| v == "1") {
        let (lo, hi) = (glam::Vec3::from(h.bbox_min), glam::Vec3::from(h.bbox_max));
        let (c, s) = ((lo + hi) / 2.0, (hi - lo).max_element());
        cam = Camera {
            eye: glam::Vec3::new(c.x, c.y, hi.z + 0.3 * s),
            target: c,
            fovy: 12.0,
            near: 0.01 * s,
            far: 4.0 * s,
            ..cam
        };
    }
    let (mut times, mut reused, mut in_pieces) = (Vec::new(), 0, 0);
    let (mut decode_ms, mut decoded) = (Vec::new(), 0u64);
    for k in 0..24 {
        let turn = glam::Quat::from_axis_angle(cam.up.normalize(), (degrees * k as f32).to_radians());
        let c = Camera { eye: cam.target + turn * (cam.eye - cam.target), ..cam };
        let t = std::time::Instant::now();
        let (tiles, counts) = model.sort(c.view_proj(grid.aspect()), &grid, Coding::Prefix).expect("sorts");
        if k >= 3 {
            times.push(t.elapsed().as_secs_f64() * 1e3);
            reused += counts.reused_triangles;
            let sorted = tiles.iter().flat_map(|t| &t.pieces).filter(|p| matches!(p.kind, PieceKind::Sorted { .. }));
            in_pieces += sorted.map(|p| p.triangles as u64).sum::<u64>();
            let t = std::time::Instant::now();
            for p in tiles.iter().flat_map(|t| &t.pieces) {
                if let PieceKind::Sorted { bytes, .. } = &p.kind {
                    decoded += codec::bft::decode(bytes).expect("a piece decodes").triangles.len() as u64;
                }
            }
            decode_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    times.sort_by(f64::total_cmp);
    let decode_total: f64 = decode_ms.iter().sum();
    decode_ms.sort_by(f64::total_cmp);
    println!(
        "{path}, {degrees} degrees a frame: sort median {:.1} ms, fastest {:.1} ms; {:.1}% of the straddling chunks' piece triangles reused; the pieces decoded on one thread in {:.1} ms a frame (median), {:.2}M triangles/s",
        times[times.len() / 2],
        times[0],
        100.0 * reused as f64 / in_pieces.max(1) as f64,
        decode_ms[decode_ms.len() / 2],
        decoded as f64 / decode_total / 1e3
    );
}
