//! Fuzzes the glTF loader (as a `.gltf` document and wrapped in a GLB, with a 64 MiB cap and a
//! model folder that does not exist); `codec::fuzzing::load_gltf` says what must hold, and the
//! workspace's test `fuzz_regressions` runs it on `fuzz/regressions/load_gltf/`. Run: `cd fuzz
//! && cargo fuzz run load_gltf` (on stable Rust: `RUSTC_BOOTSTRAP=1 cargo fuzz run load_gltf`),
//! or `scripts/dev/fuzz.sh`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| codec::fuzzing::load_gltf(data));
