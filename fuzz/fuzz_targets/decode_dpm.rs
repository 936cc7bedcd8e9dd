//! Fuzzes the `.dpm` reader; `codec::fuzzing::decode_dpm` says what must hold, and the
//! workspace's test `fuzz_regressions` runs it on `fuzz/regressions/decode_dpm/`. Run: `cd fuzz
//! && cargo fuzz run decode_dpm` (on stable Rust: `RUSTC_BOOTSTRAP=1 cargo fuzz run
//! decode_dpm`), or `scripts/dev/fuzz.sh`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| codec::fuzzing::decode_dpm(data));
