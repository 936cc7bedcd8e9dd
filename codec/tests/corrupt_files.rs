//! Truncated and corrupted `.bft` files get an error, never a panic or a wrong mesh.

use codec::bft::tile_sort::{self, Sorter, TileModel};
use codec::bft::{self, BftError, Coding, EncodeOptions};
use codec::view::{Camera, TileGrid};
use codec::{Format, FormatError};

fn encoded(rel: &str) -> Vec<u8> {
    let mesh = codec::load_path(&testkit::shared_meshes().join(rel)).unwrap();
    bft::encode(&mesh, EncodeOptions::default()).unwrap().bytes
}

#[test]
fn every_truncation_of_a_small_file_is_an_error() {
    let bytes = encoded("odedstein/cube.obj");
    assert!(bft::decode(&bytes).is_ok());
    for len in 0..bytes.len() {
        match bft::decode(&bytes[..len]) {
            Err(BftError::Truncated(_)) => {}
            Err(BftError::BadMagic(_)) if len == 0 => panic!("empty input must read as truncated"),
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
    for b in testkit::bit_flipped_copies(&bytes, 2000) {
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
    assert_eq!(u16::from_le_bytes([b[8], b[9]]), bft::VERSION);
    for v in [0u16, 7, 9, u16::MAX] {
        b[8..10].copy_from_slice(&v.to_le_bytes());
        let e = bft::decode(&b).unwrap_err();
        assert_eq!(e, FormatError::UnsupportedVersion { format: Format::Bft, found: v, known: bft::READS });
        assert_eq!(
            e.to_string(),
            format!("unsupported .bft version {v} (this build reads versions 1, 2, 3, 4, 5 and 6)")
        );
    }
    // Versions 4 and 6 have seven sections: a version 2 file relabelled is truncated; a
    // version 2 file whose attribute flags are set is corrupt.
    for v in [4u16, 6] {
        b[8..10].copy_from_slice(&v.to_le_bytes());
        assert!(matches!(bft::decode(&b).unwrap_err(), BftError::Truncated(_)));
    }
    b[8..10].copy_from_slice(&2u16.to_le_bytes());
    let flagged = with_header_byte(&b, 42, 1);
    let e = bft::decode(&flagged).unwrap_err().to_string();
    assert!(e.contains("version 2 file has non-zero reserved bytes 42 and 43"), "{e}");
    // Versions 3 and 5 are chunked files, whose header a single stream's is not.
    for v in [3u16, 5] {
        b[8..10].copy_from_slice(&v.to_le_bytes());
        let e = bft::decode(&b).unwrap_err().to_string();
        assert!(e.contains("chunked header is 72 bytes"), "{e}");
    }
    b[0] = b'X';
    assert_eq!(bft::decode(&b).unwrap_err(), BftError::BadMagic(Format::Bft));
    assert_eq!(bft::decode(b"ply\nformat ascii").unwrap_err(), BftError::BadMagic(Format::Bft));
}

/// Version 2 gave header byte 41 (the entropy coding) its meaning. A version 1 file, whose
/// byte 41 was reserved and zero, still reads as the range-coded file it is; a version 1
/// file that claims a prefix coding is corrupt, never misread.
#[test]
fn version_1_files_read_and_their_reserved_byte_stays_reserved() {
    let v2 = encoded("classic/suzanne.obj");
    let mut v1 = v2.clone();
    v1[8..10].copy_from_slice(&1u16.to_le_bytes());
    assert_eq!(bft::decode(&v1).unwrap(), bft::decode(&v2).unwrap());

    let mut prefix = whole_tile(&TileModel::from_bytes(&v2).unwrap(), Coding::Prefix);
    assert_eq!(bft::Stats::of(&prefix).unwrap().header.coding, Coding::Prefix);
    prefix[8..10].copy_from_slice(&1u16.to_le_bytes());
    let e = bft::decode(&prefix).unwrap_err().to_string();
    assert!(e.contains("version 1") && e.contains("byte 41"), "{e}");
}

/// Sections whose checksums are recomputed after corruption reach the stream decoders:
/// they must reject garbage with an error, not a panic, and in bounded time.
#[test]
fn forged_checksums_reach_the_stream_decoders_safely() {
    forge_sections(&encoded("classic/suzanne.obj"));
}

/// The same for prefix-coded streams (both codings): a tile of the sort's fast coding
/// holding the whole model, whose truncations are all errors too.
#[test]
fn corrupt_prefix_coded_streams_are_errors() {
    let model = TileModel::from_bytes(&encoded("classic/suzanne.obj")).unwrap();
    for coding in [Coding::Prefix, Coding::PrefixByDegree] {
        let bytes = &whole_tile(&model, coding);
        assert_eq!(bft::decode(bytes).unwrap().triangles.len(), model.triangles().len());
        for len in 0..bytes.len() {
            assert!(bft::decode(&bytes[..len]).is_err(), "{coding:?} truncated to {len}");
        }
        forge_sections(bytes);
    }
}

/// A prefix-coded stream's code tables are checked as they are read: a table of more
/// symbols than its alphabet, or lengths that are no prefix code, is named.
#[test]
fn corrupt_prefix_code_tables_are_named() {
    let bytes = whole_tile(&TileModel::from_bytes(&encoded("classic/suzanne.obj")).unwrap(), Coding::Prefix);
    // The first section is the connectivity, whose first table is the first command table:
    // 6 bits of symbol count, then 4 bits a length.
    let sections = testkit::sections_start(&bytes);
    let conn = sections + 8;
    for (first_bytes, error) in [
        ([0xff, 0xff], "a command code table of 63 symbols (at most 12)"),
        // Two symbols, of lengths 1 and 2: a code that leaves a quarter unused.
        ([0x08, 0x48], "invalid command code lengths"),
    ] {
        let mut b = bytes.clone();
        b[conn..conn + 2].copy_from_slice(&first_bytes);
        testkit::refresh_checksums(&mut b, sections);
        let e = bft::decode(&b).unwrap_err().to_string();
        assert!(e.contains(error), "{e}");
    }
}

/// Tiles of the first prefix coding, which chose a command's table by the left vertex's
/// degree, still read; and a stream whose coding byte names no coding is refused by name.
#[test]
fn the_first_prefix_coding_still_reads_and_unknown_codings_are_refused() {
    let model = TileModel::from_bytes(&encoded("stanford/bunny_zipper_c3d.obj.gz")).unwrap();
    let (by_degree, prefix) = (whole_tile(&model, Coding::PrefixByDegree), whole_tile(&model, Coding::Prefix));
    // The coding is byte 41 of the header, which starts at byte 12.
    assert_eq!((by_degree[12 + 41], prefix[12 + 41]), (1, 2));
    assert!(prefix.len() < by_degree.len(), "{} bytes against {}", prefix.len(), by_degree.len());
    let (old, new) = (bft::decode(&by_degree).unwrap(), bft::decode(&prefix).unwrap());
    assert_eq!((old.positions, old.triangles), (new.positions, new.triangles));

    let unknown = with_header_byte(&prefix, 41, 3);
    let e = bft::decode(&unknown).unwrap_err().to_string();
    assert!(e.contains("entropy coding 3"), "{e}");
}

/// The model's one tile in a 1x1 grid whose framing view sees all of it, coded as `coding`.
fn whole_tile(model: &TileModel, coding: Coding) -> Vec<u8> {
    let grid = TileGrid::new(64, 64, 1, 1).unwrap();
    let h = model.decoded.header;
    let vp = Camera::framing(h.bbox_min, h.bbox_max, 1.0).view_proj(1.0);
    Sorter::new(coding).sort(model, &tile_sort::boxes(model, vp, &grid), &grid).unwrap().remove(0).bytes
}

/// `bytes` with byte `i` of the header (which starts at byte 12) set to `v` and the header's
/// checksum made right again, so that the header's checks, not its checksum, answer.
fn with_header_byte(bytes: &[u8], i: usize, v: u8) -> Vec<u8> {
    let mut b = bytes.to_vec();
    b[12 + i] = v;
    let h = u16::from_le_bytes([b[10], b[11]]) as usize;
    let crc = crc32fast::hash(&b[12..12 + h]);
    b[12 + h..16 + h].copy_from_slice(&crc.to_le_bytes());
    b
}

fn forge_sections(bytes: &[u8]) {
    let sections_start = testkit::sections_start(bytes);
    let mut rng = testkit::XorShift(12345);
    let mut rejected = 0;
    for _ in 0..500 {
        let mut b = bytes.to_vec();
        let i = sections_start + 8 + (rng.next_u64() as usize % (b.len() - sections_start - 8));
        b[i] = rng.next_u64() as u8;
        testkit::refresh_checksums(&mut b, sections_start);
        if bft::decode(&b).is_err() {
            rejected += 1;
        }
    }
    assert!(rejected > 0);
}

/// The fuzz target's input path, run on a fixed set of pseudo-random inputs so the suite
/// exercises it without a fuzzer: errors are fine, panics are not.
#[test]
fn arbitrary_streams_behind_a_valid_container_never_panic() {
    let mut rng = testkit::XorShift(0xDEADBEEF);
    for len in (0..4000).step_by(7) {
        let data = rng.bytes(len);
        let _ = bft::decode(&data);
        let _ = bft::decode(&bft::wrap_for_fuzzing(&data));
    }
}
