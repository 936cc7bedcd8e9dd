//! Decodes every non-empty leaf of an existing `.nsp` to full precision, ROUNDS times, and
//! reports vertex splits per second (the decoder alone, for profiling):
//! `RAYON_NUM_THREADS=1 cargo run --release -p tessera-codec --example nspdecode -- X.nsp [ROUNDS]`.

use std::time::Instant;

use codec::nsp::{self, NspFile};

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let file = NspFile::from_bytes(std::fs::read(&a[1]).expect("read the .nsp")).expect("a .nsp file");
    let rounds: usize = a.get(2).map(|s| s.parse().expect("ROUNDS")).unwrap_or(3);
    let bits = file.header.params.bits;
    let cut: Vec<(u32, u8)> = (0..file.tree.nodes.len() as u32)
        .filter(|&c| file.tree.is_leaf(c) && file.entries[c as usize].len > 0)
        .map(|c| (c, bits))
        .collect();
    let mut best = f64::MAX;
    for _ in 0..rounds {
        let t = Instant::now();
        let mut nav = nsp::view::Navigator::default();
        nav.update(&file, &cut).expect("decode");
        let secs = t.elapsed().as_secs_f64();
        best = best.min(secs);
        println!(
            "{} cells, {} vertex splits in {secs:.3}s: {:.2} M/s on {} threads",
            nav.cells(),
            nav.splits,
            nav.splits as f64 / secs / 1e6,
            rayon::current_num_threads()
        );
    }
    println!("best {best:.3}s");
}
