//! Prints BFT command counts and sizes for mesh files: `cargo run --release --example bftstat -- FILE...`
fn main() {
    for arg in std::env::args().skip(1) {
        let mesh = codec::load_path(std::path::Path::new(&arg)).expect("load");
        let t = std::time::Instant::now();
        let enc = codec::bft::encode(&mesh, codec::bft::EncodeOptions { quant_bits: 14, ..Default::default() })
            .expect("encode");
        let et = t.elapsed();
        let t = std::time::Instant::now();
        let dec = codec::bft::decode(&enc.bytes).expect("decode");
        let dt = t.elapsed();
        let s = codec::bft::Stats::of(&enc.bytes).unwrap();
        let names = ["NEW", "RF0", "LF0", "RF", "LF", "NULL", "DL", "DR", "ADDN", "ADDR", "SEED", "CLR"];
        let counts: Vec<String> = names
            .iter()
            .zip(enc.stats.command_counts)
            .filter(|(_, c)| *c > 0)
            .map(|(n, c)| format!("{n}={c}"))
            .collect();
        println!("{arg}\n  {} tris, {} bytes, conn {:.3} bits/tri, geom {:.2} bits/vert (14-bit)\n  encode {:.1} ms ({:.2} Mtri/s), decode {:.1} ms ({:.1} Mtri/s)\n  {}",
            mesh.triangles.len(), s.bytes, s.connectivity_bits_per_triangle(), s.geometry_bits_per_vertex(),
            et.as_secs_f64() * 1e3, mesh.triangles.len() as f64 / et.as_secs_f64() / 1e6,
            dt.as_secs_f64() * 1e3, dec.triangles.len() as f64 / dt.as_secs_f64() / 1e6, counts.join(" "));
        println!("  offsets 1,2,3,4-7,8+: {:?}", enc.stats.offset_histogram);
    }
}
