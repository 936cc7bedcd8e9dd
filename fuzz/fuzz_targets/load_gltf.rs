//! Fuzzes the glTF loader: any bytes, as a `.gltf` document or a `.glb` container, must load
//! or return a one-line error, never panic, hang, read a file outside the model's folder or
//! allocate without bound. Run: `cd fuzz && cargo fuzz run load_gltf`
//! (on stable Rust: `RUSTC_BOOTSTRAP=1 cargo fuzz run load_gltf`).
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

/// The model's folder does not exist: a buffer URI that names a file is an error, whatever
/// it names (and one outside the folder is refused before any read).
const MODEL: &str = "/nonexistent-tessera-fuzz/model.gltf";

fuzz_target!(|data: &[u8]| {
    // A cap of 64 MiB on what the loader may allocate for accessors, buffers and the mesh.
    codec::input::set_max_decompressed_bytes(64 << 20);
    check(data);
    // Most random bytes are no JSON: also wrap them in a GLB container, the first byte
    // splitting them into the JSON chunk and the binary chunk, so the fuzzer reaches the
    // container's and the accessors' checks.
    let split = (data.first().copied().unwrap_or(0) as usize).min(data.len().saturating_sub(1));
    let (json, bin) = data.get(1..).unwrap_or(&[]).split_at(split.min(data.len().saturating_sub(1)));
    check(&glb(json, bin));
});

fn check(bytes: &[u8]) {
    match codec::load::load_bytes(Path::new(MODEL), bytes, codec::load::Format::Gltf) {
        Ok(mesh) => {
            let n = mesh.positions.len();
            assert!(mesh.triangles.iter().flatten().all(|&i| (i as usize) < n));
            assert!(mesh.positions.iter().flatten().all(|c| c.is_finite()));
        }
        Err(e) => assert!(!e.to_string().contains('\n'), "{e}"),
    }
}

/// A GLB container (version 2) of a JSON chunk and a binary chunk, each padded to 4 bytes.
fn glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let pad = |b: &[u8], with: u8| {
        let mut v = b.to_vec();
        v.resize(b.len().div_ceil(4) * 4, with);
        v
    };
    let (json, bin) = (pad(json, b' '), pad(bin, 0));
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}
