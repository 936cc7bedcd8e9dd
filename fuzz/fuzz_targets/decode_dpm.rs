//! Fuzzes the `.dpm` decoder: any bytes must decode or return an error, never panic, hang
//! or allocate without bound. Run: `cd fuzz && cargo fuzz run decode_dpm`
//! (on stable Rust: `RUSTC_BOOTSTRAP=1 cargo fuzz run decode_dpm`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(decoded) = codec::pm::format::decode(data) {
        // A successful decode is internally consistent.
        let n = decoded.pm.positions.len() as u32;
        assert!(decoded.pm.splits.iter().all(|s| s.v < s.v_u && s.v_u < n));
        assert!(decoded.pm.splits.iter().flat_map(|s| s.faces.iter().flatten()).all(|&f| f < n));
        let _ = codec::pm::refine_all(&decoded.pm);
    }
    // The checksums stop most random inputs early; also feed the bytes to the operation
    // decoder behind a valid container, so the fuzzer explores it.
    let _ = codec::pm::format::decode(&codec::pm::format::wrap_for_fuzzing(data));
});
