//! Tessera's benchmarks and experiments, which compare it with its peers in the same run:
//! the peers' set-up ([`peers`]: Draco and meshopt, once for every benchmark), the bandwidth
//! experiment of the BFT paper's Figure 8 ([`bandwidth`], run by the `bandwidth` binary),
//! the generator of large test models ([`subdivide`], the `subdivide` binary), and the
//! criterion benchmark of the codec (`benches/codec.rs`). None of it is compiled into
//! the `tessera` binary.

pub mod bandwidth;
pub mod peers;
pub mod subdivide;
