//! Fuzzes the `.bft` decoder, single-stream and chunked: any bytes must decode or return an error, never panic, hang
//! or allocate without bound. Run: `cd fuzz && cargo fuzz run decode_bft`
//! (on stable Rust: `RUSTC_BOOTSTRAP=1 cargo fuzz run decode_bft`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(decoded) = codec::bft::decode(data) {
        // A successful decode is internally consistent.
        let n = decoded.positions.len() as u32;
        assert!(decoded.triangles.iter().flatten().all(|&s| s < n));
        let _ = decoded.to_mesh();
    }
    // The checksums stop most random inputs early; also feed the bytes to the stream
    // decoders behind a valid container, so the fuzzer explores them.
    let _ = codec::bft::decode(&codec::bft::wrap_for_fuzzing(data));
    // Chunked files: the directory's checks, each chunk's stream and border table, and the
    // tables a frame builds for a straddling chunk.
    let chunked = codec::bft::chunked::wrap_for_fuzzing(data);
    let _ = codec::bft::decode(&chunked);
    if let Ok(file) = codec::bft::chunked::ChunkedFile::open(chunked) {
        let model = codec::bft::chunked::sort::ChunkedModel::new(file, 1 << 20);
        for i in 0..model.chunks() {
            let _ = model.file.border(i);
            let _ = model.straddler(i);
        }
    }
});
