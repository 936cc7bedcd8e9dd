//! Fuzzes the `.bft` reader (single-stream and chunked); `codec::fuzzing::decode_bft` says what
//! must hold, and the workspace's test `fuzz_regressions` runs it on
//! `fuzz/regressions/decode_bft/`. Run: `cd fuzz && cargo fuzz run decode_bft` (on stable Rust:
//! `RUSTC_BOOTSTRAP=1 cargo fuzz run decode_bft`), or `scripts/dev/fuzz.sh`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| codec::fuzzing::decode_bft(data));
