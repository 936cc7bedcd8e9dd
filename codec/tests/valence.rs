//! Linear time whatever the valence (issue 12): the BFT encoder and the progressive-mesh
//! builder on a fan of 20k triangles around one vertex and on 20k-sided polygons (loaded from
//! OBJ, so the loader triangulates them), bounded by their operation counts, not by the clock
//! ([`codec::bft::EncodeStats::work`], [`codec::pm::BuildStats::work`]). Before the fix the
//! same counts were about 10,000 steps per triangle for the encoder on the 20k fan (a linear
//! scan of the centre's half-edges per lookup) and 50,000 for the builder (every collapse into
//! the centre read and re-offered all of its edges); now they are 19 and 13 (30 for the
//! builder on ordinary meshes). The timings at
//! 200k: `cargo run --release -p tessera-codec --example valence`.

use std::path::Path;

use codec::load::{load_bytes, Format};
use codec::pm::{build_with_stats, format, refine_all};
use codec::Mesh;
use testkit::{assert_round_trip, sorted_canonical};

/// Steps per triangle the encoder may take (a binary search of a long half-edge list is
/// counted as its `log2` steps: 15 for the fan's centre here).
const ENCODE_STEPS_PER_TRIANGLE: u64 = 32;
/// Steps per triangle the builder may take: about 13 on the fan and the convex polygon, 30 on
/// the shared meshes, 100 on the star, which is planar (every collapse costs nothing, so ties
/// let one vertex absorb its neighbours, up to `HUB_FACES` faces).
const BUILD_STEPS_PER_TRIANGLE: u64 = 160;

fn fan(n: usize) -> Mesh {
    let mut positions = vec![[0.0, 0.0, 0.0]];
    for i in 0..=n {
        let a = i as f32 / (n + 1) as f32 * std::f32::consts::TAU;
        positions.push([a.cos(), a.sin(), 0.05 * (7.0 * a).sin()]);
    }
    Mesh::new(positions, (1..=n as u32).map(|i| [0, i, i + 1]).collect())
}

/// One polygon face of `n` corners on a circle, every other one at `inner` times the radius.
fn polygon(n: usize, inner: f64) -> Mesh {
    let mut obj = String::new();
    for i in 0..n {
        let a = i as f64 / n as f64 * std::f64::consts::TAU;
        let r = if i % 2 == 1 { inner } else { 1.0 };
        obj.push_str(&format!("v {} {} 0\n", r * a.cos(), r * a.sin()));
    }
    obj.push('f');
    for i in 1..=n {
        obj.push_str(&format!(" {i}"));
    }
    load_bytes(Path::new("polygon.obj"), obj.as_bytes(), Format::Obj).expect("loads")
}

/// Encodes and builds `mesh`, checks both round trips and bounds both operation counts.
fn check_linear(name: &str, mesh: &Mesh) -> codec::pm::BuildStats {
    let t = mesh.triangles.len() as u64;
    let enc = assert_round_trip(mesh, 16);
    println!(
        "{name}: {t} triangles, encoder {} steps ({:.1} per triangle)",
        enc.stats.work,
        enc.stats.work as f64 / t as f64
    );
    assert!(
        enc.stats.work <= ENCODE_STEPS_PER_TRIANGLE * t,
        "{name}: the encoder took {} steps for {t} triangles",
        enc.stats.work
    );

    let (pm, stats) = build_with_stats(mesh, &mut |_, _| {}).expect("builds");
    println!(
        "{name}: builder {} steps ({:.1} per triangle), {} hubs",
        stats.work,
        stats.work as f64 / t as f64,
        stats.hubs
    );
    assert!(
        stats.work <= BUILD_STEPS_PER_TRIANGLE * t,
        "{name}: the builder took {} steps for {t} triangles",
        stats.work
    );
    // Every face comes back, and every split creates one.
    let input_of_fvid = {
        let mut v = vec![u32::MAX; pm.positions.len()];
        for (i, &f) in pm.fvid_of_input.iter().enumerate() {
            if f != u32::MAX {
                v[f as usize] = i as u32;
            }
        }
        v
    };
    let back = refine_all(&pm).into_iter().map(|t| t.map(|f| input_of_fvid[f as usize]));
    assert!(sorted_canonical(back) == sorted_canonical(mesh.triangles.iter().copied()), "{name}: refinement differs");
    assert!(pm.splits.iter().all(|s| !s.faces.is_empty()), "{name}: a split without faces");
    let dpm = format::encode(&pm, Default::default()).expect("compresses");
    let decoded = format::decode(&dpm.bytes).expect("decodes");
    assert_eq!(decoded.pm.splits.len(), pm.splits.len());
    stats
}

#[test]
fn a_fan_encodes_and_builds_in_linear_steps() {
    assert_eq!(check_linear("fan", &fan(20_000)).hubs, 1, "the centre is a hub");
}

#[test]
fn large_polygons_triangulate_encode_and_build_in_linear_steps() {
    let convex = polygon(20_000, 1.0);
    assert_eq!(convex.triangles.len(), 19_998);
    assert!(convex.triangles.iter().all(|t| t[0] == 0), "a convex polygon is fanned from its first corner");
    check_linear("convex polygon", &convex);
    let star = polygon(20_000, 0.5);
    assert_eq!(star.triangles.len(), 19_998);
    check_linear("star polygon", &star);
}

#[test]
fn repeated_triangles_encode_and_build_in_linear_steps() {
    // 10k copies of one triangle each way, and a fan on its edge: every lookup on the edge
    // (0, 1) sees the copies (the encoder skips visited ones for good, the builder's three
    // vertices are hubs).
    let mut mesh = fan(10_000);
    let rim = mesh.positions.len() as u32;
    mesh.positions.push([0.5, 0.5, 1.0]);
    for _ in 0..10_000 {
        mesh.triangles.push([0, 1, rim]);
        mesh.triangles.push([1, 0, rim]);
    }
    check_linear("repeated triangles", &mesh);
}
