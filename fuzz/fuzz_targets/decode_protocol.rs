//! Fuzzes the protocol between ranks; `protocol::fuzz_round_trip` says what must hold, and the
//! workspace's test `fuzz_regressions` runs it on `fuzz/regressions/decode_protocol/`. Run: `cd
//! fuzz && cargo fuzz run decode_protocol` (on stable Rust: `RUSTC_BOOTSTRAP=1 cargo fuzz run
//! decode_protocol`), or `scripts/dev/fuzz.sh`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| protocol::fuzz_round_trip(data));
