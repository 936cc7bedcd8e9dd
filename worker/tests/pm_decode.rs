//! The WGSL `.dpm` decoder (`worker/src/pm_adapt/shaders/decode.wgsl`) against the CPU decoder
//! (`Dpm::decode_op`): every operation of real meshes decoded on the GPU from its address and
//! context gives the CPU's operation bit for bit (criteria values included), and damaged
//! operations are refused by the GPU exactly where the CPU refuses them, with no read out of
//! bounds and no hang. Needs a wgpu adapter; without a GPU that is Mesa's lavapipe.

use codec::pm::build;
use codec::pm::format::{decode, encode, Dpm, EncodeOptions, OpContext};
use worker::gpu::Gpu;
use worker::pm_adapt::decoder::{DecodeFailure, GpuOpDecoder};

fn dpm_bytes(rel: &str) -> Vec<u8> {
    let pm = build(&testkit::load_mesh(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"));
    encode(&pm, EncodeOptions::default()).unwrap().bytes
}

/// Decodes `jobs` on both and compares: the same refusals, the same operations.
fn compare(gpu: &Gpu, dpm: &Dpm, jobs: &[(usize, OpContext)], what: &str) -> (usize, usize) {
    let decoder = GpuOpDecoder::new(gpu, dpm).expect("decoder");
    compare_with(&decoder, dpm, jobs, what)
}

/// As [`compare`] with `decoder`; an operation it answers [`DecodeFailure::Absent`] is not
/// compared (out of core, its node is not resident) and counts as neither.
fn compare_with(decoder: &GpuOpDecoder, dpm: &Dpm, jobs: &[(usize, OpContext)], what: &str) -> (usize, usize) {
    let (got, _) = decoder.decode(jobs).expect("GPU decode");
    assert_eq!(got.len(), jobs.len());
    let (mut ok, mut refused) = (0, 0);
    for (i, ((addr, ctx), g)) in jobs.iter().zip(&got).enumerate() {
        if g == &Err(DecodeFailure::Absent) {
            continue;
        }
        match (dpm.decode_op(*addr, ctx), g) {
            (Ok(c), Ok(g)) => {
                let ctx_s = format!("{what}: operation {i} at {addr} ({ctx:?})");
                assert_eq!(g.v_u, c.split.v_u, "{ctx_s}: v_u");
                assert_eq!(g.faces[..], c.split.faces[..], "{ctx_s}: faces");
                assert_eq!(g.criteria_q, c.criteria_q, "{ctx_s}: criteria codes");
                let cf =
                    [c.criteria.sin_alpha, c.criteria.geometric_error, c.criteria.attribute_error, c.criteria.radius];
                assert_eq!(g.criteria.map(f32::to_bits), cf.map(f32::to_bits), "{ctx_s}: criteria values");
                assert_eq!((g.position_u, g.normal_u), (c.position_u, c.normal_u), "{ctx_s}: attributes");
                assert_eq!((g.left, g.right, g.swapped, g.end), (c.left, c.right, c.swapped, c.end), "{ctx_s}: tree");
                ok += 1;
            }
            (Err(_), Err(_)) => refused += 1,
            (c, g) => panic!("{what}: operation {i} at {addr} ({ctx:?}): CPU {c:?}, GPU {g:?}"),
        }
    }
    (ok, refused)
}

/// Every operation of the file, with its address and context as the runtime has them.
fn all_jobs(bytes: &[u8]) -> Vec<(usize, OpContext)> {
    let d = decode(bytes).unwrap();
    d.addresses.into_iter().zip(d.contexts).collect()
}

#[test]
fn every_operation_of_real_meshes_decodes_on_the_gpu_as_on_the_cpu() {
    let gpu = Gpu::new().expect("a wgpu adapter");
    for rel in ["stanford/bunny_zipper_c3d.obj.gz", "classic/horse.ply.gz", "classic/teapot.obj"] {
        let bytes = dpm_bytes(rel);
        let dpm = Dpm::parse(&bytes).unwrap();
        let jobs = all_jobs(&bytes);
        let (ok, refused) = compare(&gpu, &dpm, &jobs, rel);
        assert_eq!((ok, refused), (jobs.len(), 0), "{rel}");
        // What stays in graphics memory: the operations and the tables, not decoded records.
        // The distinct tables (80 to 120 of them, 1 kB each with their lookups) take 85 to
        // 125 kB whatever the model, so the bound is for models (the teapot's 44 kB file
        // takes 2.9x).
        let decoder = GpuOpDecoder::new(&gpu, &dpm).unwrap();
        let ratio = decoder.static_bytes() as f64 / bytes.len() as f64;
        eprintln!("{rel}: {ok} operations; {} static GPU bytes, {ratio:.2}x the file", decoder.static_bytes());
        assert!(ratio <= 1.5 || bytes.len() < 1 << 18, "{rel}: {ratio:.2}x the file in graphics memory");
    }
}

/// xorshift64*.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
}

#[test]
fn damaged_operations_are_refused_where_the_cpu_refuses_them() {
    let gpu = Gpu::new().expect("a wgpu adapter");
    let bytes = dpm_bytes("stanford/bunny_zipper_c3d.obj.gz");
    let dpm = Dpm::parse(&bytes).unwrap();
    let jobs = all_jobs(&bytes);
    let mut rng = Rng(0x5eed);
    let mut totals = (0, 0);
    // Flipped bits, overwritten bytes, and a section cut short, each decoded at every
    // operation's address with its true context.
    for round in 0..6 {
        let mut ops = dpm.ops.to_vec();
        match round {
            0..=2 => {
                for _ in 0..ops.len() / 64 {
                    let i = rng.below(ops.len() as u64) as usize;
                    ops[i] ^= 1 << rng.below(8);
                }
            }
            3 | 4 => {
                for _ in 0..ops.len() / 256 {
                    let i = rng.below(ops.len() as u64) as usize;
                    ops[i] = rng.next() as u8;
                }
            }
            _ => ops.truncate(ops.len() * 2 / 3),
        }
        let mut damaged = dpm.clone();
        damaged.ops = &ops;
        let (ok, refused) = compare(&gpu, &damaged, &jobs, &format!("round {round}"));
        totals = (totals.0 + ok, totals.1 + refused);
    }
    // Random addresses with contexts of other operations, and contexts out of range.
    let mut odd = Vec::new();
    for k in 0..20_000 {
        let (_, mut ctx) = jobs[rng.below(jobs.len() as u64) as usize];
        let addr = rng.below(dpm.ops.len() as u64 + 8) as usize;
        match k % 8 {
            0 => ctx.v_end = ctx.v_end.wrapping_add(rng.below(4) as u32),
            1 => ctx.normal[rng.below(2) as usize] = 1 << rng.below(17),
            2 => ctx.position[rng.below(3) as usize] = rng.next() as u32 >> rng.below(32),
            3 => ctx.parent_criteria = [0, 1, 2, 3].map(|_| rng.next() as u32 >> rng.below(32)),
            _ => {}
        }
        odd.push((addr, ctx));
    }
    let (ok, refused) = compare(&gpu, &dpm, &odd, "random addresses");
    totals = (totals.0 + ok, totals.1 + refused);
    eprintln!("damaged: {} operations decoded alike, {} refused by both", totals.0, totals.1);
    assert!(totals.0 > 1000 && totals.1 > 1000, "both outcomes exercised: {totals:?}");
}

/// Out-of-core files: every operation decodes on the GPU from its node's slot in the pool as
/// on the CPU; with half of the nodes resident, exactly the operations of the others are
/// absent; damaged nodes and random node addresses are refused where the CPU refuses them.
#[test]
fn out_of_core_operations_decode_on_the_gpu_as_on_the_cpu() {
    let gpu = Gpu::new().expect("a wgpu adapter");
    let mut rng = Rng(0x00c0);
    for (rel, node_bytes) in [("stanford/bunny_zipper_c3d.obj.gz", 4096), ("classic/teapot.obj", 1024)] {
        let pm = build(&testkit::load_mesh(rel)).unwrap();
        let bytes = encode(&pm, EncodeOptions { node_bytes, ..EncodeOptions::default() }).unwrap().bytes;
        let dpm = Dpm::parse(&bytes).unwrap();
        let nodes = dpm.nodes.len() as u32;
        assert!(dpm.out_of_core() && nodes > 2, "{rel}: {nodes} nodes");
        let jobs = all_jobs(&bytes);
        assert_eq!(compare(&gpu, &dpm, &jobs, rel), (jobs.len(), 0), "{rel}");
        // Every other node resident.
        let even: Vec<u32> = (0..nodes).filter(|i| i % 2 == 0).collect();
        let decoder = GpuOpDecoder::with_nodes(&gpu, &dpm, &even).unwrap();
        let (got, _) = decoder.decode(&jobs).unwrap();
        let absent = got.iter().filter(|g| **g == Err(DecodeFailure::Absent)).count();
        let odd_ops = jobs.iter().filter(|(a, _)| Dpm::node_of(*a) % 2 == 1).count();
        assert_eq!(absent, odd_ops, "{rel}: the operations of the absent nodes");
        assert_eq!(compare_with(&decoder, &dpm, &jobs, rel), (jobs.len() - odd_ops, 0), "{rel}");
        // Damaged nodes (flipped bits, overwritten bytes), decoded at every operation's address.
        let mut totals = (0, 0);
        for round in 0..4 {
            let mut ops = dpm.ops.to_vec();
            for _ in 0..ops.len() / if round < 2 { 64 } else { 256 } {
                let i = rng.below(ops.len() as u64) as usize;
                if round < 2 {
                    ops[i] ^= 1 << rng.below(8);
                } else {
                    ops[i] = rng.next() as u8;
                }
            }
            let mut damaged = dpm.clone();
            damaged.ops = &ops;
            let (ok, refused) = compare(&gpu, &damaged, &jobs, &format!("{rel}: round {round}"));
            totals = (totals.0 + ok, totals.1 + refused);
        }
        // Random addresses in and past the nodes, with other operations' contexts.
        let odd: Vec<(usize, OpContext)> = (0..5000)
            .map(|_| {
                let node = rng.below(nodes as u64 + 2) as usize;
                let span = if rng.below(4) == 0 { 1 << 16 } else { node_bytes as u64 };
                let local = rng.below(span) as usize;
                (node * codec::pm::format::NODE_BYTES + local, jobs[rng.below(jobs.len() as u64) as usize].1)
            })
            .collect();
        let (ok, refused) = compare(&gpu, &dpm, &odd, &format!("{rel}: random addresses"));
        totals = (totals.0 + ok, totals.1 + refused);
        eprintln!("{rel}, {nodes} nodes: damaged, {} decoded alike, {} refused by both", totals.0, totals.1);
        assert!(totals.0 > 100 && totals.1 > 1000, "{rel}: both outcomes exercised: {totals:?}");
    }
}

/// The dragon (871k triangles): every operation on both, the static memory, and the GPU's
/// decoding rate: `cargo test --release -p tessera-worker --test pm_decode -- --ignored --nocapture`.
#[test]
#[ignore = "builds the 871k-triangle dragon; run in release"]
fn the_dragon_decodes_on_the_gpu_as_on_the_cpu() {
    let gpu = Gpu::new().expect("a wgpu adapter");
    let bytes = dpm_bytes("stanford/dragon_vrip.ply.gz");
    let dpm = Dpm::parse(&bytes).unwrap();
    let jobs = all_jobs(&bytes);
    let (ok, refused) = compare(&gpu, &dpm, &jobs, "dragon");
    assert_eq!((ok, refused), (jobs.len(), 0));
    let decoder = GpuOpDecoder::new(&gpu, &dpm).unwrap();
    let ratio = decoder.static_bytes() as f64 / bytes.len() as f64;
    let mut best = f64::MAX;
    for _ in 0..3 {
        best = best.min(decoder.decode(&jobs).unwrap().1);
    }
    let start = std::time::Instant::now();
    for (addr, ctx) in &jobs {
        dpm.decode_op(*addr, ctx).unwrap();
    }
    let cpu = start.elapsed().as_secs_f64();
    eprintln!(
        "dragon on {}: {ok} operations, {} static GPU bytes ({ratio:.2}x the {}-byte file); GPU decode {:.1} ms \
         ({:.2}M operations/s), one CPU core {:.1} ms",
        gpu.adapter_name(),
        decoder.static_bytes(),
        bytes.len(),
        best * 1e3,
        ok as f64 / best / 1e6,
        cpu * 1e3
    );
    assert!(ratio <= 1.5, "{ratio:.2}x the file in graphics memory");
}
