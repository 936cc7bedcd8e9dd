//! Out-of-core `.dpm` files (sections 4.1, 4.2.1 and 5.7): the hierarchy's nodes hold the
//! operations within their size, decode to the same progressive mesh as the in-core file,
//! every operation alone from its node; node boxes and errors bound their operations, so the
//! priority `d_n / d_v` never misses a node the view needs; corrupt nodes are named.

use codec::pm::format::{self, decode, encode, Dpm, DpmStats, EncodeOptions, NodeFile, NODE_BYTES};
use codec::pm::{build, ProgressiveMesh, SplitTree, Viewpoint, NONE};
use codec::view::Camera;
use codec::Mesh;
use glam::Vec3;
use testkit::shared_meshes;

fn load(rel: &str) -> Mesh {
    codec::load_path(&shared_meshes().join(rel)).unwrap()
}

fn out_of_core(node_bytes: u32) -> EncodeOptions {
    EncodeOptions { node_bytes, ..EncodeOptions::default() }
}

/// The out-of-core file decodes to the in-core file's mesh, every node within its size, every
/// operation alone from its address, its children in its node or a later one.
fn check(pm: &ProgressiveMesh, node_bytes: u32) -> format::Encoded {
    let incore = encode(pm, EncodeOptions::default()).unwrap();
    let enc = encode(pm, out_of_core(node_bytes)).unwrap();
    let (a, b) = (decode(&incore.bytes).unwrap().pm, decode(&enc.bytes).unwrap().pm);
    assert_eq!(a.positions, b.positions);
    assert_eq!(a.normals, b.normals);
    assert_eq!(a.base_vertices, b.base_vertices);
    assert_eq!(a.base_faces, b.base_faces);
    assert_eq!(a.splits, b.splits);
    assert_eq!(a.criteria, b.criteria);
    let dpm = Dpm::parse(&enc.bytes).unwrap();
    assert_eq!(dpm.nodes.len(), enc.header.nodes as usize);
    assert!(dpm.out_of_core() && !pm.splits.is_empty() || pm.splits.is_empty());
    for (i, n) in dpm.nodes.iter().enumerate() {
        assert!(n.len as usize <= node_bytes as usize, "node {i}: {} bytes", n.len);
        assert!(n.parent.is_none_or(|p| (p as usize) < i));
        n.check(i as u32, dpm.node_bytes(i as u32)).unwrap();
    }
    let tree = SplitTree::new(pm);
    let node = |a: usize| a / NODE_BYTES;
    for s in 0..pm.splits.len() {
        let op = dpm.decode_op(enc.addresses[s], &enc.contexts[s]).unwrap();
        assert_eq!(op.split.v_u, pm.splits[s].v_u);
        let [l, r] = tree.children[s];
        let address = |c: u32| (c != NONE).then(|| enc.addresses[c as usize]);
        assert_eq!((op.left, op.right), (address(l), address(r)), "children of split {s}");
        for c in [op.left, op.right].into_iter().flatten() {
            assert!(node(c) >= node(enc.addresses[s]));
            // A child's node descends from its parent's.
            let mut up = Some(node(c) as u32);
            while up.is_some_and(|u| u as usize != node(enc.addresses[s])) {
                up = dpm.nodes[up.unwrap() as usize].parent;
            }
            assert!(up.is_some(), "split {s}: a child's node does not descend from its node");
        }
        // The operations decode the same from their node's bytes alone.
        let n = node(enc.addresses[s]) as u32;
        assert_eq!(dpm.decode_in(dpm.node_bytes(n), enc.addresses[s], &enc.contexts[s]).unwrap(), op);
    }
    enc
}

#[test]
fn out_of_core_files_decode_as_the_in_core_ones() {
    for rel in
        ["odedstein/cube.obj", "classic/teapot.obj", "degenerate/non_manifold_face_graph.obj", "classic/spot.obj"]
    {
        let pm = build(&load(rel)).unwrap();
        for node_bytes in [256, 1024, 65536] {
            let enc = check(&pm, node_bytes);
            eprintln!("{rel}, nodes of {node_bytes} bytes: {} nodes", enc.header.nodes);
        }
    }
    let empty = build(&Mesh::default()).unwrap();
    let enc = encode(&empty, out_of_core(65536)).unwrap();
    assert_eq!(decode(&enc.bytes).unwrap().pm.splits.len(), 0);
}

#[test]
fn inner_nodes_hold_the_coarse_operations() {
    let pm = build(&load("classic/spot.obj")).unwrap();
    let enc = check(&pm, 2048);
    let dpm = Dpm::parse(&enc.bytes).unwrap();
    assert!(dpm.nodes.len() > 8, "{} nodes", dpm.nodes.len());
    // A node's greatest error is at most its parent's (children hold what is left below it)
    // in most of the hierarchy: the operations are taken by error from the subtrees' roots.
    let below = dpm
        .nodes
        .iter()
        .filter(|n| n.parent.is_some_and(|p| n.geometric_error <= dpm.nodes[p as usize].geometric_error))
        .count();
    assert!(below * 10 >= (dpm.nodes.len() - 1) * 9, "{below} of {} nodes", dpm.nodes.len() - 1);
}

/// Every split the view asks for is in a node whose priority is at least 1 (section 5.7's
/// "the data of the bounding volume is only required if its priority is at least one"), and
/// some nodes are not needed.
#[test]
fn priorities_never_miss_a_needed_node() {
    let pm = build(&load("classic/spot.obj")).unwrap();
    let enc = encode(&pm, out_of_core(1024)).unwrap();
    let dec = decode(&enc.bytes).unwrap();
    let dpm = Dpm::parse(&enc.bytes).unwrap();
    let (lo, hi) = pm.positions.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(a, b), &p| {
        (a.min(Vec3::from(p)), b.max(Vec3::from(p)))
    });
    let (center, size) = ((lo + hi) * 0.5, (hi - lo).length());
    let mut unneeded = 0;
    for k in 0..12 {
        let a = k as f32 * 0.5;
        // Orbits at growing distances, and close looks at one part of the model.
        let (target, dist) = if k % 2 == 0 {
            (center + Vec3::new(0.1 * size * a.sin(), 0.0, 0.0), size * (0.4 + 0.3 * k as f32))
        } else {
            (Vec3::from(pm.positions[pm.positions.len() / 3]), size * 0.1 * k as f32 / 6.0)
        };
        let eye = target + Vec3::new(a.cos() * dist, 0.2 * dist, a.sin() * dist);
        let base = Camera::framing(lo.to_array(), hi.to_array(), 640.0 / 480.0);
        let camera = Camera { eye, target, near: size * 0.01, far: size * 20.0, ..base };
        let view = Viewpoint::new(&camera, 640, 480, 0.5);
        let planes = view.planes();
        let priority: Vec<f32> = dpm.nodes.iter().map(|n| n.priority(&view, &planes)).collect();
        for (s, &addr) in dec.addresses.iter().enumerate() {
            if view.needs_split(&dec.pm, s) {
                let n = addr / NODE_BYTES;
                assert!(priority[n] >= 1.0, "view {k}: split {s} needed in node {n} of priority {}", priority[n]);
            }
        }
        unneeded += priority.iter().filter(|&&p| p < 1.0).count();
    }
    assert!(unneeded > 0, "every node was needed in every view");
}

#[test]
fn node_files_read_and_check_their_nodes() {
    let pm = build(&load("classic/teapot.obj")).unwrap();
    let enc = encode(&pm, out_of_core(512)).unwrap();
    let dpm = Dpm::parse(&enc.bytes).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("teapot.dpm");
    std::fs::write(&path, &enc.bytes).unwrap();
    let file = NodeFile::open(&path).unwrap();
    let prefix = Dpm::parse_prefix(file.prefix()).unwrap();
    assert_eq!(prefix.nodes, dpm.nodes);
    assert_eq!(prefix.roots, dpm.roots);
    for i in 0..dpm.nodes.len() as u32 {
        assert_eq!(file.read_node(i).unwrap(), dpm.node_bytes(i));
    }
    assert!(file.read_node(dpm.nodes.len() as u32).unwrap_err().to_string().contains("past the last node"));
    // A byte of node 3 flipped: that node's checksum names it; the others still read.
    let mut bad = enc.bytes.clone();
    let at = file.prefix().len() + dpm.nodes[3].offset as usize + 1;
    bad[at] ^= 0x10;
    std::fs::write(&path, &bad).unwrap();
    let file = NodeFile::open(&path).unwrap();
    assert_eq!(file.read_node(3).unwrap_err().to_string(), "corrupt .dpm data: node 3: checksum mismatch");
    assert!(file.read_node(2).is_ok());
    // A corrupt operation decoded from its node names the node and the local address.
    let mut node = dpm.node_bytes(0).to_vec();
    node.truncate(1);
    let (addr, ctx) = (enc.addresses[0], enc.contexts[0]);
    let e = dpm.decode_in(&node, addr, &ctx).unwrap_err().to_string();
    assert!(e.starts_with(&format!("corrupt .dpm data: node 0: operation at byte {}: ", addr % NODE_BYTES)), "{e}");
    // Truncated, longer and in-core files are refused at open, in one line.
    std::fs::write(&path, &enc.bytes[..enc.bytes.len() - 10]).unwrap();
    assert_eq!(NodeFile::open(&path).unwrap_err().to_string(), "file is truncated: operations section");
    std::fs::write(&path, [&enc.bytes[..], &[0]].concat()).unwrap();
    assert_eq!(NodeFile::open(&path).unwrap_err().to_string(), "1 trailing bytes after the last section");
    std::fs::write(&path, encode(&pm, EncodeOptions::default()).unwrap().bytes).unwrap();
    let e = NodeFile::open(&path).unwrap_err().to_string();
    assert!(e.contains("in-core file"), "{e}");
    std::fs::write(&path, &enc.bytes[..30]).unwrap();
    assert!(NodeFile::open(&path).is_err());
}

/// The stats of an out-of-core file read node by node equal those of the file read whole (the
/// same walk decodes every operation: the same bits per kind), every node read at least
/// once; a corrupt node is an error naming it.
#[test]
fn out_of_core_stats_read_node_by_node_equal_the_whole_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.dpm");
    for (rel, node_bytes) in [("classic/teapot.obj", 512), ("classic/spot.obj", 1024), ("classic/spot.obj", 65536)] {
        let pm = build(&load(rel)).unwrap();
        let enc = encode(&pm, out_of_core(node_bytes)).unwrap();
        std::fs::write(&path, &enc.bytes).unwrap();
        let file = NodeFile::open(&path).unwrap();
        let (streamed, reads) = DpmStats::of_out_of_core(&file).unwrap();
        assert_eq!(streamed, DpmStats::of(&enc.bytes).unwrap(), "{rel} in nodes of {node_bytes} bytes");
        let nodes = enc.header.nodes as u64;
        assert!(reads >= nodes, "{rel}: {reads} node reads of {nodes} nodes");
        eprintln!("{rel} in nodes of {node_bytes} bytes: {reads} node reads of {nodes} nodes");
        let mut bad = enc.bytes.clone();
        let dpm = Dpm::parse(&enc.bytes).unwrap();
        let last = dpm.nodes.len() - 1;
        bad[file.prefix().len() + dpm.nodes[last].offset as usize] ^= 0x01;
        std::fs::write(&path, &bad).unwrap();
        let file = NodeFile::open(&path).unwrap();
        let e = DpmStats::of_out_of_core(&file).unwrap_err().to_string();
        assert_eq!(e, format!("corrupt .dpm data: node {last}: checksum mismatch"));
    }
}

/// A cache of fixed slots (what a GPU pool holds) never holds more nodes than its slots, even
/// when the view moves on faster than the loader thread reads: nodes that arrive no longer
/// wanted are dropped, and a wanted one evicts the worst unwanted one.
#[test]
fn a_cache_of_slots_never_overflows_while_views_move_on() {
    use codec::pm::NodeCache;
    use std::sync::Arc;
    let pm = build(&load("classic/spot.obj")).unwrap();
    let enc = encode(&pm, out_of_core(1024)).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("spot.dpm");
    std::fs::write(&path, &enc.bytes).unwrap();
    let file = Arc::new(NodeFile::open(&path).unwrap());
    let dpm = Dpm::parse_prefix(file.prefix()).unwrap();
    let (lo, hi) = pm.positions.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(a, b), &p| {
        (a.min(Vec3::from(p)), b.max(Vec3::from(p)))
    });
    let size = (hi - lo).length();
    let slots = dpm.nodes.len() as u64 / 3;
    let mut cache = NodeCache::with_slots(&dpm, file.clone(), slots, 1024, true);
    let (mut discarded, mut evicted) = (0, 0);
    for k in 0..40 {
        // Close looks at parts of the model far apart, one after the other.
        let target = Vec3::from(pm.positions[(k * 7919) % pm.positions.len()]);
        let a = k as f32 * 1.3;
        let eye = target + Vec3::new(a.cos(), 0.3, a.sin()) * 0.3 * size;
        let base = Camera::framing(lo.to_array(), hi.to_array(), 640.0 / 480.0);
        let camera = Camera { eye, target, near: size * 0.001, far: size * 20.0, ..base };
        let st = cache.schedule(&Viewpoint::new(&camera, 640, 480, 0.5)).unwrap();
        if k % 3 == 2 {
            cache.wait().unwrap();
        } else {
            cache.install().unwrap();
        }
        let resident = cache.resident_nodes().count() as u64;
        assert!(resident <= slots, "view {k}: {resident} nodes resident in {slots} slots");
        (discarded, evicted) = (discarded + st.discarded, evicted + st.evicted);
    }
    eprintln!("{slots} slots of {} nodes: {evicted} evicted, {discarded} dropped on arrival", dpm.nodes.len());
    assert!(evicted > 0, "no node was ever evicted");
}

/// The cost of the out-of-core layout per operation in 64 kB nodes (the paper: about 1 byte;
/// here 0.31 on the bunny and 0.46 on the dragon with a node's bytes estimated from its
/// pointers (0.87 and 0.49 before, when nodes came out a fifth smaller than asked), both
/// children in one other node coded as a pair (1.03 and 0.55 without), up to four children
/// per node and a last halving into leaves (0.70 on the dragon without it); 1.18 and 1.39
/// with two, see `hierarchy.rs`):
/// `cargo test -p tessera-codec --release --test pm_ooc -- --ignored --nocapture`.
#[test]
#[ignore = "builds the bunny and the 871k-triangle dragon; run in release"]
fn out_of_core_sizes() {
    for (rel, bound) in [("stanford/bunny_zipper_c3d.obj.gz", 1.0), ("stanford/dragon_vrip.ply.gz", 0.6)] {
        let pm = build(&load(rel)).unwrap();
        let incore = encode(&pm, EncodeOptions::default()).unwrap();
        let t = std::time::Instant::now();
        let enc = encode(&pm, out_of_core(65536)).unwrap();
        let secs = t.elapsed().as_secs_f64();
        let (a, b) = (DpmStats::of(&incore.bytes).unwrap(), DpmStats::of(&enc.bytes).unwrap());
        let ops = pm.splits.len().max(1) as f64;
        eprintln!(
            "{rel}: in core {} bytes ({:.2}/vertex), out of core {} bytes ({:.2}/vertex) in {} nodes, encoded in \
             {secs:.2}s: {:.3} bytes more per operation (pointers {:.3}, padding {:.3}, node table {:.3})",
            a.bytes,
            a.bytes_per_vertex(),
            b.bytes,
            b.bytes_per_vertex(),
            b.header.nodes,
            (b.bytes as f64 - a.bytes as f64) / ops,
            (b.tree_pointer_bytes - a.tree_pointer_bytes) / ops,
            (b.padding_bytes - a.padding_bytes) / ops,
            b.node_table_bytes as f64 / ops,
        );
        assert!((b.bytes as f64 - a.bytes as f64) / ops <= bound);
    }
}

/// Inner nodes split what is left below them into up to four children (eight where a last
/// halving makes them leaves), so fewer operations
/// sit in inner nodes, where nearly every pointer leaves the node: the bunny in 4 kB nodes
/// costs at most 1.1 bytes per operation more than in core (1.33 with two children).
#[test]
fn inner_nodes_have_up_to_four_children_and_the_layout_costs_about_a_byte_per_operation() {
    let pm = build(&load("stanford/bunny_zipper_c3d.obj.gz")).unwrap();
    let incore = encode(&pm, EncodeOptions::default()).unwrap();
    let enc = check(&pm, 4096);
    let dpm = Dpm::parse(&enc.bytes).unwrap();
    let mut children = vec![0usize; dpm.nodes.len()];
    for n in &dpm.nodes {
        if let Some(p) = n.parent {
            children[p as usize] += 1;
        }
    }
    // Up to four children; up to eight where the last halving makes them all leaves.
    for (i, n) in dpm.nodes.iter().enumerate() {
        if let Some(p) = n.parent.filter(|&p| children[p as usize] > 4) {
            assert!(
                children[i] == 0,
                "node {i}, a child of node {p} with {} children, is not a leaf",
                children[p as usize]
            );
        }
    }
    let most = children.iter().max().copied().unwrap_or(0);
    assert!(most <= 8 && children.contains(&4), "at most {most} children a node");
    let more = (enc.bytes.len() as f64 - incore.bytes.len() as f64) / pm.splits.len() as f64;
    eprintln!("{} nodes, {more:.3} bytes more per operation", dpm.nodes.len());
    assert!(more <= 1.1, "{more:.3} bytes more per operation");
}
