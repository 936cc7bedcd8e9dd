//! Round trips, the wire bytes of every message, and bad messages.
use super::*;

fn frame() -> ToWorker {
    ToWorker::Frame(FrameJob {
        frame: 7,
        width: 640,
        height: 480,
        view_proj: std::array::from_fn(|i| i as f32 * 0.5),
        decode_only: true,
        sorter: 1,
        sorters: 2,
        chunk_cache: 1 << 40,
        tiles: vec![
            TileJob {
                index: 3,
                rect: [0, 0, 80, 60],
                streams: vec![
                    TileStream { source: StreamSource::Bytes(vec![1, 2, 3]), normals: vec![(5, [0.0, 1.0, 0.0])] },
                    TileStream {
                        source: StreamSource::Keep { chunk: 7, bft: vec![4, 5] },
                        normals: vec![(0, [1.0, 0.0, 0.0])],
                    },
                    TileStream { source: StreamSource::Kept { chunk: 2 }, normals: vec![] },
                ],
            },
            TileJob { index: 9, rect: [80, 60, 160, 120], streams: vec![] },
        ],
    })
}

fn pixels() -> ToMaster {
    ToMaster::Pixels(Pixels {
        frame: 7,
        tiles: vec![TilePixels {
            index: 3,
            rect: [0, 0, 2, 1],
            times: TileTimes {
                decode_ms: 1.0,
                adapt_ms: 5.0,
                upload_ms: 2.0,
                render_ms: 3.0,
                readback_ms: 4.0,
                encode_ms: 0.5,
            },
            triangles: 12,
            reused: 0,
            codec: PixelCodec::Lz4,
            coded_bytes: 7,
            pixels: vec![9; 7],
        }],
        span: FrameSpan { start_ms: 1.5, prepared_ms: 2.5, end_ms: 4.0 },
        pm: PmMemory {
            gpu_bytes: 1 << 33,
            loaded_bytes: 65536,
            resident_nodes: 7,
            required_nodes: 9,
            slots: 8,
            error_scale: 2.25,
        },
    })
}

fn pm_frame() -> ToWorker {
    ToWorker::PmFrame(PmFrameJob {
        frame: 2,
        width: 640,
        height: 480,
        view_proj: std::array::from_fn(|i| i as f32 - 3.0),
        eye: [1.0, 2.0, 3.0],
        pixels_per_unit: 500.0,
        error_px: 0.5,
        c_lod: 100.0,
        attribute_scale: 0.01,
        max_passes: 64,
        occlusion: true,
        tiles: vec![(0, [0, 0, 320, 240]), (3, [320, 240, 640, 480])],
    })
}

fn nsp_frame() -> ToWorker {
    ToWorker::NspFrame(NspFrameJob {
        frame: 2,
        width: 64,
        height: 48,
        view_proj: std::array::from_fn(|i| i as f32 * 0.5),
        selection: vec![(3, 9), (70, 11)],
        draw: vec![70],
        cells: vec![(70, 0, vec![1, 2, 3]), (64, 9, vec![])],
        tiles: vec![(1, [32, 0, 64, 24])],
    })
}

#[test]
fn messages_round_trip() {
    let f = frame();
    assert_eq!(ToWorker::decode(&f.encode()), Ok(f));
    assert_eq!(ToWorker::decode(&ToWorker::Shutdown.encode()), Ok(ToWorker::Shutdown));
    let model = ToWorker::Model(PmModel { dpm: vec![4, 5, 6], gpu_budget: 3 << 30 });
    assert_eq!(ToWorker::decode(&model.encode()), Ok(model));
    let pm = pm_frame();
    assert_eq!(ToWorker::decode(&pm.encode()), Ok(pm));
    let nsp = nsp_frame();
    assert_eq!(ToWorker::decode(&nsp.encode()), Ok(nsp));
    let skeleton = ToWorker::NspModel(NspModel { skeleton: vec![7; 9] });
    assert_eq!(ToWorker::decode(&skeleton.encode()), Ok(skeleton));
    let sort = ToSorter::Sort(SortJob {
        frame: 3,
        view_proj: std::array::from_fn(|i| i as f32),
        error_px: 0.5,
        owners: vec![1, 2, 0],
    });
    assert_eq!(ToSorter::decode(&sort.encode()), Ok(sort));
    assert_eq!(ToSorter::decode(&ToSorter::Shutdown.encode()), Ok(ToSorter::Shutdown));
    assert_eq!(ToWorker::decode(&ToWorker::Unload.encode()), Ok(ToWorker::Unload));
    assert_eq!(ToWorker::decode(&ToWorker::KeepAlive.encode()), Ok(ToWorker::KeepAlive));
    for codec in [PixelCodec::Raw, PixelCodec::Lz4, PixelCodec::Jpeg { quality: 1 }, PixelCodec::Jpeg { quality: 100 }]
    {
        assert_eq!(ToWorker::decode(&ToWorker::PixelCodec(codec).encode()), Ok(ToWorker::PixelCodec(codec)));
    }
    assert_eq!(ToSorter::decode(&ToSorter::KeepAlive.encode()), Ok(ToSorter::KeepAlive));
    let p = pixels();
    assert_eq!(ToMaster::decode(&p.encode()), Ok(p));
    let file = ToWorker::DpmFile(DpmFile { path: "/data/é.dpm".into(), gpu_budget: 512 << 20, pool_bytes: 128 << 20 });
    assert_eq!(ToWorker::decode(&file.encode()), Ok(file));
    for m in [
        ToDisplay::DisplayFrame(DisplayFrameJob { view: 5, frame: 2, eye: 2, tiles: vec![0, 7, 9] }),
        ToDisplay::Swap(Swap { view: 5 }),
        ToDisplay::Shutdown,
    ] {
        assert_eq!(ToDisplay::decode(&m.encode()), Ok(m));
    }
    for m in [
        ToMaster::Ready(Ready { adapter: "llvmpipe".into(), max_texture_side: 16384 }),
        ToMaster::Failed(Failed { reason: "no adapter".into() }),
        ToMaster::Heartbeat,
        ToMaster::DisplayReady(DisplayReady { view: 3, ready: vec![(0, 1.5), (4, 2.5)], decode_ms: 0.25 }),
    ] {
        assert_eq!(ToMaster::decode(&m.encode()), Ok(m));
    }
}

#[test]
fn a_forged_rect_whose_area_overflows_is_an_error() {
    // The fuzzer's find: a Pixels tile whose rect area times 4 overflows 64 bits.
    // Found at protocol version 3: read at today's version, so the tile's rect is checked.
    let mut bytes = include_bytes!("../../fuzz/regressions/decode_protocol/pixels-rect-overflow").to_vec();
    bytes[4] = VERSION;
    assert!(matches!(ToMaster::decode(&bytes), Err(ProtocolError::Invalid(_)) | Err(ProtocolError::Truncated(_))));
}

#[test]
fn bad_messages_are_errors() {
    for msg in [frame(), pm_frame(), nsp_frame()] {
        let bytes = msg.encode();
        for len in 0..bytes.len() {
            assert!(ToWorker::decode(&bytes[..len]).is_err(), "truncated to {len}");
        }
    }
    let bytes = frame().encode();
    let mut extra = bytes.clone();
    extra.push(0);
    assert_eq!(ToWorker::decode(&extra), Err(ProtocolError::Trailing(1)));
    assert_eq!(ToWorker::decode(b"XXXX\x02\x01"), Err(ProtocolError::BadMagic));
    assert_eq!(ToMaster::decode(&[b"TSRM".as_slice(), &[VERSION, 9]].concat()), Err(ProtocolError::UnknownKind(9)));
    // Another build's message is refused by its version, before its kind is read.
    for v in [0u8, 1, 2, 255] {
        let mut b = frame().encode();
        b[4] = v;
        let e = ToWorker::decode(&b).unwrap_err();
        assert_eq!(e, ProtocolError::Version(v));
        assert!(e.to_string().contains("same build on every rank"), "{e}");
    }
    let wrong_size = ToMaster::Pixels(Pixels {
        frame: 1,
        tiles: vec![TilePixels {
            index: 0,
            rect: [0, 0, 2, 2],
            times: TileTimes::default(),
            triangles: 0,
            reused: 0,
            codec: PixelCodec::Raw,
            coded_bytes: 3,
            pixels: vec![0; 3],
        }],
        span: FrameSpan::default(),
        pm: PmMemory::default(),
    });
    assert!(matches!(ToMaster::decode(&wrong_size.encode()), Err(ProtocolError::Invalid(_))));
    // Coded pixels are at most the raw size (a worker sends raw what does not shrink), and
    // a codec is one of three.
    let coded = |codec: PixelCodec, n: usize| {
        let ToMaster::Pixels(mut p) = pixels() else { unreachable!() };
        p.tiles[0].codec = codec;
        p.tiles[0].pixels = vec![1; n];
        ToMaster::decode(&ToMaster::Pixels(p).encode())
    };
    assert!(coded(PixelCodec::Jpeg { quality: 90 }, 8).is_ok());
    assert!(matches!(coded(PixelCodec::Jpeg { quality: 90 }, 9), Err(ProtocolError::Invalid(_))));
    assert!(matches!(coded(PixelCodec::Jpeg { quality: 0 }, 4), Err(ProtocolError::Invalid(_))));
    assert!(matches!(coded(PixelCodec::Raw, 7), Err(ProtocolError::Invalid(_))));
}

/// Every message's bytes as this protocol version has them, so that moving the code cannot
/// change the wire (a change of layout moves [`VERSION`] and these bytes with it).
#[test]
fn the_wire_bytes_of_every_message() {
    let p = |m: ToMaster| m.encode();
    let encoded: Vec<(&str, Vec<u8>)> = vec![
        ("frame", frame().encode()),
        ("shutdown", ToWorker::Shutdown.encode()),
        ("model", ToWorker::Model(PmModel { dpm: vec![4, 5, 6], gpu_budget: 3 << 30 }).encode()),
        (
            "dpm_file",
            ToWorker::DpmFile(DpmFile { path: "/data/é.dpm".into(), gpu_budget: 512 << 20, pool_bytes: 128 << 20 })
                .encode(),
        ),
        ("pm_frame", pm_frame().encode()),
        ("nsp_model", ToWorker::NspModel(NspModel { skeleton: vec![7; 9] }).encode()),
        ("nsp_frame", nsp_frame().encode()),
        (
            "sort",
            ToSorter::Sort(SortJob {
                frame: 3,
                view_proj: std::array::from_fn(|i| i as f32),
                error_px: 0.5,
                owners: vec![1, 2, 0],
            })
            .encode(),
        ),
        (
            "display_frame",
            ToDisplay::DisplayFrame(DisplayFrameJob { view: 5, frame: 2, eye: 2, tiles: vec![0, 7, 9] }).encode(),
        ),
        ("swap", ToDisplay::Swap(Swap { view: 5 }).encode()),
        ("ready", p(ToMaster::Ready(Ready { adapter: "llvmpipe".into(), max_texture_side: 16384 }))),
        ("heartbeat", p(ToMaster::Heartbeat)),
        ("pixels", p(pixels())),
        ("failed", p(ToMaster::Failed(Failed { reason: "no adapter".into() }))),
        (
            "display_ready",
            p(ToMaster::DisplayReady(DisplayReady { view: 3, ready: vec![(0, 1.5), (4, 2.5)], decode_ms: 0.25 })),
        ),
        ("unload", ToWorker::Unload.encode()),
        ("keep_alive", ToWorker::KeepAlive.encode()),
        ("input", p(ToMaster::Input(Input { json: r#"{"cmd":"quit"}"#.into() }))),
        ("pixel_codec", ToWorker::PixelCodec(PixelCodec::Jpeg { quality: 85 }).encode()),
    ];
    let golden: [(&str, &str); 19] = [
        ("frame", "5453524d0a010700000080020000e0010000000000000000003f0000803f0000c03f0000004000002040000040400000604000008040000090400000a0400000b0400000c0400000d0400000e0400000f040010102000000000001000002000000030000000000000000000000500000003c0000000300000000030000000102030100000005000000000000000000803f00000000010700000002000000040501000000000000000000803f000000000000000002020000000000000009000000500000003c000000a00000007800000000000000"),
        ("shutdown", "5453524d0a02"),
        ("model", "5453524d0a0603000000040506000000c000000000"),
        ("dpm_file", "5453524d0a0f0c0000002f646174612fc3a92e64706d00000020000000000000000800000000"),
        ("pm_frame", "5453524d0a070200000080020000e0010000000040c0000000c0000080bf000000000000803f0000004000004040000080400000a0400000c0400000e04000000041000010410000204100003041000040410000803f00000040000040400000fa430000003f0000c8420ad7233c40000000010200000000000000000000000000000040010000f00000000300000040010000f000000080020000e0010000"),
        ("nsp_model", "5453524d0a0a09000000070707070707070707"),
        ("nsp_frame", "5453524d0a0b020000004000000030000000000000000000003f0000803f0000c03f0000004000002040000040400000604000008040000090400000a0400000b0400000c0400000d0400000e0400000f040020000000300000009460000000b010000004600000002000000460000000000000003000000010203400000000900000000000000010000000100000020000000000000004000000018000000"),
        ("sort", "5453524d0a0903000000000000000000803f0000004000004040000080400000a0400000c0400000e04000000041000010410000204100003041000040410000504100006041000070410000003f03000000010000000200000000000000"),
        ("display_frame", "5453524d0a0c05000000020000000203000000000000000700000009000000"),
        ("swap", "5453524d0a0d05000000"),
        ("ready", "5453524d0a03080000006c6c766d7069706500400000"),
        ("heartbeat", "5453524d0a08"),
        ("pixels", "5453524d0a0407000000010000000300000000000000000000000200000001000000000000000000f03f0000000000001440000000000000004000000000000008400000000000001040000000000000e03f0c000000000000000100070000000700000009090909090909000000000000f83f000000000000044000000000000010400000000002000000000001000000000007000000090000000800000000001040"),
        ("failed", "5453524d0a050a0000006e6f2061646170746572"),
        ("display_ready", "5453524d0a0e030000000200000000000000000000000000f83f040000000000000000000440000000000000d03f"),
        ("unload", "5453524d0a10"),
        ("keep_alive", "5453524d0a11"),
        ("input", "5453524d0a120e0000007b22636d64223a2271756974227d"),
        ("pixel_codec", "5453524d0a130255"),
    ];
    for ((name, bytes), (gname, hex)) in encoded.iter().zip(golden) {
        assert_eq!(*name, gname);
        let ours: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(ours, hex, "{name}");
    }
    // Shutdown is one message to every kind of rank, and KeepAlive to workers and sorters.
    assert_eq!(ToSorter::Shutdown.encode(), ToWorker::Shutdown.encode());
    assert_eq!(ToSorter::KeepAlive.encode(), ToWorker::KeepAlive.encode());
    assert_eq!(ToDisplay::Shutdown.encode(), ToWorker::Shutdown.encode());
    assert_eq!(ToDisplay::KeepAlive.encode(), ToWorker::KeepAlive.encode());
    assert_eq!(ToDisplay::decode(&ToDisplay::KeepAlive.encode()), Ok(ToDisplay::KeepAlive));
}
