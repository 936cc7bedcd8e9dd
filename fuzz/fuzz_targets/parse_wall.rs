//! Fuzzes the wall-file parser (`render --wall`); `master::wall::fuzz_wall` says what must
//! hold, and the workspace's test `fuzz_regressions` runs it on `fuzz/regressions/parse_wall/`.
//! Run: `cd fuzz && cargo fuzz run parse_wall` (on stable Rust: `RUSTC_BOOTSTRAP=1 cargo fuzz
//! run parse_wall`), or `scripts/dev/fuzz.sh`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| master::wall::fuzz_wall(data));
