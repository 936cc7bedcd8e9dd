//! Truncated and corrupted `.bft` files get an error, never a panic or a wrong mesh.

mod common;

use codec::bft::tile_sort::{self, Sorter, TileModel};
use codec::bft::{self, BftError, Coding, EncodeOptions};
use codec::view::{Camera, TileGrid};

fn encoded(rel: &str) -> Vec<u8> {
    let mesh = codec::load_path(&common::shared_meshes().join(rel)).unwrap();
    bft::encode(&mesh, EncodeOptions::default()).unwrap().bytes
}

#[test]
fn every_truncation_of_a_small_file_is_an_error() {
    let bytes = encoded("odedstein/cube.obj");
    assert!(bft::decode(&bytes).is_ok());
    for len in 0..bytes.len() {
        match bft::decode(&bytes[..len]) {
            Err(BftError::Truncated(_)) => {}
            Err(BftError::BadMagic) if len == 0 => panic!("empty input must read as truncated"),
            other => panic!("truncated to {len} of {} bytes: {other:?}", bytes.len()),
        }
    }
    let mut longer = bytes.clone();
    longer.push(0);
    assert_eq!(bft::decode(&longer).unwrap_err(), BftError::TrailingBytes(1));
}

#[test]
fn random_byte_flips_are_detected() {
    let bytes = encoded("classic/teapot.obj");
    let reference = bft::decode(&bytes).unwrap();
    for b in common::bit_flipped_copies(&bytes, 2000) {
        if b == bytes {
            continue;
        }
        // CRC-32 detects every 1- to 3-bit error in a section; the magic and version are
        // checked field by field.
        match bft::decode(&b) {
            Err(_) => {}
            Ok(d) => {
                panic!("a corrupted file decoded ({} triangles vs {})", d.triangles.len(), reference.triangles.len())
            }
        }
    }
}

#[test]
fn wrong_magic_and_version_are_named() {
    let mut b = encoded("odedstein/cube.obj");
    b[8] = 9;
    assert_eq!(bft::decode(&b).unwrap_err(), BftError::UnsupportedVersion(9));
    b[0] = b'X';
    assert_eq!(bft::decode(&b).unwrap_err(), BftError::BadMagic);
    assert_eq!(bft::decode(b"ply\nformat ascii").unwrap_err(), BftError::BadMagic);
}

/// Sections whose checksums are recomputed after corruption reach the stream decoders:
/// they must reject garbage with an error, not a panic, and in bounded time.
#[test]
fn forged_checksums_reach_the_stream_decoders_safely() {
    forge_sections(&encoded("classic/suzanne.obj"));
}

/// The same for a prefix-coded stream: a tile of the sort's fast coding holding the whole
/// model, whose truncations are all errors too.
#[test]
fn corrupt_prefix_coded_streams_are_errors() {
    let model = TileModel::from_bytes(&encoded("classic/suzanne.obj")).unwrap();
    let grid = TileGrid::new(64, 64, 1, 1).unwrap();
    let h = model.decoded.header;
    let vp = Camera::framing(h.bbox_min, h.bbox_max, 1.0).view_proj(1.0);
    let tiles = Sorter::new(Coding::Prefix).sort(&model, &tile_sort::boxes(&model, vp, &grid), &grid).unwrap();
    let bytes = &tiles[0].bytes;
    assert_eq!(bft::decode(bytes).unwrap().triangles.len(), model.triangles().len());
    for len in 0..bytes.len() {
        assert!(bft::decode(&bytes[..len]).is_err(), "truncated to {len}");
    }
    forge_sections(bytes);
}

fn forge_sections(bytes: &[u8]) {
    let header_len = u16::from_le_bytes([bytes[10], bytes[11]]) as usize;
    let sections_start = 12 + header_len + 4;
    let mut state = 12345u64;
    let mut next = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        state >> 33
    };
    let mut rejected = 0;
    for _ in 0..500 {
        let mut b = bytes.to_vec();
        let i = sections_start + 8 + (next() as usize % (b.len() - sections_start - 8));
        b[i] = next() as u8;
        refresh_checksums(&mut b, sections_start);
        if bft::decode(&b).is_err() {
            rejected += 1;
        }
    }
    assert!(rejected > 0);
}

fn refresh_checksums(b: &mut [u8], mut pos: usize) {
    while pos + 8 <= b.len() {
        let n = u32::from_le_bytes(b[pos + 4..pos + 8].try_into().unwrap()) as usize;
        let start = pos + 8;
        if start + n + 4 > b.len() {
            return;
        }
        let crc = crc32fast::hash(&b[start..start + n]);
        b[start + n..start + n + 4].copy_from_slice(&crc.to_le_bytes());
        pos = start + n + 4;
    }
}

/// The fuzz target's input path, run on a fixed set of pseudo-random inputs so the suite
/// exercises it without a fuzzer: errors are fine, panics are not.
#[test]
fn arbitrary_streams_behind_a_valid_container_never_panic() {
    let mut rng = common::XorShift(0xDEADBEEF);
    for len in (0..4000).step_by(7) {
        let data = rng.bytes(len);
        let _ = bft::decode(&data);
        let _ = bft::decode(&bft::wrap_for_fuzzing(&data));
    }
}
