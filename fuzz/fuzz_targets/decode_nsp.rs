//! Fuzzes the `.nsp` reader and its cell decoder; `codec::fuzzing::decode_nsp` says what must
//! hold, and the workspace's test `fuzz_regressions` runs it on `fuzz/regressions/decode_nsp/`.
//! Run: `cd fuzz && cargo fuzz run decode_nsp` (on stable Rust: `RUSTC_BOOTSTRAP=1 cargo fuzz
//! run decode_nsp`), or `scripts/dev/fuzz.sh`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| codec::fuzzing::decode_nsp(data));
