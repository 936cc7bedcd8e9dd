//! Times PNG encoding of a frame at each of the png crate's compression levels (best of 5),
//! with the size each gives: `cargo run --release -p tessera --example pngbench -- FRAME.png`
//! (any PNG; a 1920x1080 render of the dragon is what the README's figures use).

use std::time::Instant;

fn main() {
    let path = std::env::args().nth(1).expect("a PNG file");
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).expect("open")));
    let mut reader = decoder.read_info().expect("a PNG");
    let mut pixels = vec![0; reader.output_buffer_size().expect("a size")];
    let info = reader.next_frame(&mut pixels).expect("a frame");
    pixels.truncate(info.buffer_size());
    let (w, h, color) = (info.width, info.height, info.color_type);
    println!("{path}: {w}x{h} {color:?}");
    for (name, level) in [
        ("balanced (the png crate's default)", png::Compression::Balanced),
        ("fast (fdeflate)", png::Compression::Fast),
        ("fastest", png::Compression::Fastest),
    ] {
        let mut best = f64::MAX;
        let mut size = 0;
        for _ in 0..5 {
            let t = Instant::now();
            let mut out = Vec::new();
            let mut e = png::Encoder::new(&mut out, w, h);
            e.set_color(color);
            e.set_depth(png::BitDepth::Eight);
            e.set_compression(level);
            let mut wr = e.write_header().expect("header");
            wr.write_image_data(&pixels).expect("data");
            wr.finish().expect("finish");
            best = best.min(t.elapsed().as_secs_f64());
            size = out.len();
        }
        println!("  {name}: {:.1} ms, {size} bytes", best * 1e3);
    }
}
