//! Times the stages of an out-of-core `.nsp` build:
//! `cargo run --release -p tessera-codec --example nspooc -- MESH BITS N_MIN`.

use std::sync::Mutex;
use std::time::Instant;

use codec::nsp::{ooc, Params};

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let num = |i: usize, d: u32| a.get(i).map(|s| s.parse().unwrap()).unwrap_or(d);
    let params = Params { bits: num(2, 16) as u8, root_bits: 7, splits: 4, min_simplices: num(3, 8000), advance: 0 };
    let start = Instant::now();
    let stage = Mutex::new((String::new(), start));
    let report = |name: &str, _: u64, _: u64| {
        let mut s = stage.lock().unwrap();
        if s.0 != name {
            if !s.0.is_empty() {
                println!("{:<30} {:>7.2} s", s.0, s.1.elapsed().as_secs_f64());
            }
            *s = (name.to_string(), Instant::now());
        }
    };
    let mut out = Vec::new();
    let built = ooc::build_file(std::path::Path::new(&a[1]), params, None, &mut out, &report).unwrap();
    let s = stage.lock().unwrap();
    println!("{:<30} {:>7.2} s", s.0, s.1.elapsed().as_secs_f64());
    println!("total {:.2} s, {} bytes, {} cells", start.elapsed().as_secs_f64(), built.bytes, built.cells);
}
