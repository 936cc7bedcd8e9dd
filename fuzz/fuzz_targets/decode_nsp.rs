//! Fuzzes the `.nsp` reader and its cell decoder: any bytes must open and decode or return an
//! error, never panic, hang or allocate without bound. Run: `cd fuzz && cargo fuzz run
//! decode_nsp` (on stable Rust: `RUSTC_BOOTSTRAP=1 cargo fuzz run decode_nsp`).
#![no_main]

use codec::nsp::{decode, format, NspFile};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // As a whole file (headers, tables, tree shape).
    if let Ok(file) = NspFile::from_bytes(data.to_vec()) {
        let _ = decode::decode_all(&file);
    }
    // As one cell's stream behind valid tables, at every precision.
    if let Ok(file) = NspFile::from_bytes(format::wrap_for_fuzzing(data)) {
        for bits in [3u8, 10] {
            if let Ok(d) = decode::decode_uniform(&file, bits) {
                let n = d.positions.len() as u32;
                assert!(d.triangles.iter().flatten().all(|&v| v < n));
            }
        }
    }
});
