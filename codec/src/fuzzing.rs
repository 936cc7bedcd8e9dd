//! What the fuzz targets in `fuzz/` check, one function each, so that the fuzzer and the
//! workspace's regression test (`tests/fuzz_regressions.rs`, over `fuzz/regressions/`) run
//! the same code: any bytes must decode or be refused with an error, never panic, hang or
//! allocate without bound, and what decodes must be consistent.

use std::path::Path;

/// `fuzz/fuzz_targets/decode_bft.rs`: single-stream and chunked `.bft` files.
pub fn decode_bft(data: &[u8]) {
    if let Ok(decoded) = crate::bft::decode(data) {
        // A successful decode is internally consistent.
        let n = decoded.positions.len() as u32;
        assert!(decoded.triangles.iter().flatten().all(|&s| s < n));
        let _ = decoded.to_mesh();
    }
    // The checksums stop most random inputs early; also feed the bytes to the stream
    // decoders behind a valid container, so the fuzzer explores them.
    let _ = crate::bft::decode(&crate::bft::wrap_for_fuzzing(data));
    // Chunked files: the directory's checks, each chunk's stream and border table, and the
    // tables a frame builds for a straddling chunk.
    let chunked = crate::bft::chunked::wrap_for_fuzzing(data);
    let _ = crate::bft::decode(&chunked);
    if let Ok(file) = crate::bft::chunked::ChunkedFile::open(chunked) {
        let mut model = crate::bft::chunked::sort::ChunkedModel::new(file, 1 << 20);
        for i in 0..model.chunks() {
            let _ = model.file.border(i);
            let _ = model.straddler(i);
        }
        // A hierarchy that opened is consistent: its levels and cuts are defined.
        if let Some(h) = &model.file.lod {
            let _ = h.levels();
            let _ = model.file.levels();
            let grid = crate::view::TileGrid::new(64, 48, 4, 3).expect("a grid");
            let vp = crate::view::Camera::framing([-1.0; 3], [1.0; 3], grid.aspect()).view_proj(grid.aspect());
            for error_px in [None, Some(0.5), Some(1e6)] {
                model.error_px = error_px;
                let _ = model.classify_all(vp, &grid);
            }
        }
    }
}

/// `fuzz/fuzz_targets/decode_dpm.rs`: `.dpm` progressive meshes.
pub fn decode_dpm(data: &[u8]) {
    if let Ok(decoded) = crate::pm::format::decode(data) {
        // A successful decode is internally consistent.
        let n = decoded.pm.positions.len() as u32;
        assert!(decoded.pm.splits.iter().all(|s| s.v < s.v_u && s.v_u < n));
        assert!(decoded.pm.splits.iter().flat_map(|s| s.faces.iter().flatten()).all(|&f| f < n));
        let _ = crate::pm::refine_all(&decoded.pm);
    }
    // The checksums stop most random inputs early; also feed the bytes to the operation
    // decoder behind a valid container, so the fuzzer explores it.
    let _ = crate::pm::format::decode(&crate::pm::format::wrap_for_fuzzing(data));
}

/// `fuzz/fuzz_targets/decode_nsp.rs`: the `.nsp` reader and its cell decoder.
pub fn decode_nsp(data: &[u8]) {
    use crate::nsp::{format, view, NspFile};
    // As a whole file (headers, tables, tree shape).
    if let Ok(file) = NspFile::from_bytes(data.to_vec()) {
        let _ = view::decode_all(&file);
    }
    // As one cell's stream behind valid tables, at every precision.
    if let Ok(file) = NspFile::from_bytes(format::wrap_for_fuzzing(data)) {
        for bits in [3u8, 10] {
            if let Ok(d) = view::decode_uniform(&file, bits) {
                let n = d.positions.len() as u32;
                assert!(d.triangles.iter().flatten().all(|&v| v < n));
            }
        }
    }
}

/// The model path [`load_gltf`] reads as: its folder does not exist, so a buffer URI that
/// names a file is an error, whatever it names (and one outside the folder is refused
/// before any read).
const GLTF_MODEL: &str = "/nonexistent-tessera-fuzz/model.gltf";

/// `fuzz/fuzz_targets/load_gltf.rs`: the glTF loader, on the bytes as a `.gltf` file and
/// wrapped in a GLB container (the first byte splitting the rest into the JSON chunk and the
/// binary chunk, so that random bytes reach the container's and the accessors' checks), with
/// a cap of 64 MiB on what the loader may allocate.
pub fn load_gltf(data: &[u8]) {
    crate::input::set_max_decompressed_bytes(64 << 20);
    gltf_loads_or_refuses(data);
    let split = (data.first().copied().unwrap_or(0) as usize).min(data.len().saturating_sub(1));
    let (json, bin) = data.get(1..).unwrap_or(&[]).split_at(split.min(data.len().saturating_sub(1)));
    gltf_loads_or_refuses(&glb(json, bin));
}

fn gltf_loads_or_refuses(bytes: &[u8]) {
    match crate::load::load_bytes(Path::new(GLTF_MODEL), bytes, crate::load::Format::Gltf) {
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
