//! Times the BFT encoder and the progressive-mesh builder (build plus `.dpm` compression) on
//! the two shapes with one vertex of very high valence: a fan of N triangles `(0, i, i + 1)`
//! around one vertex, and one N-sided polygon face loaded from OBJ text (so the loader's
//! triangulation runs too), convex, as a concave star and as a comb (long thin teeth, the
//! hard case for ear clipping). All must take time close to linear in N, whatever the
//! valence (issue 12).
//!
//! `cargo run --release -p tessera-codec --example valence [N [encode|pm]]` (default 200000,
//! both).

use std::time::Instant;

use codec::load::{load_bytes, Format};
use codec::{bft, pm, Mesh};

/// A fan of `n` triangles around vertex 0, its rim an arc of a slightly wavy circle (so the
/// fan is not planar and the quadrics are not all zero).
fn fan(n: usize) -> Mesh {
    let mut positions = vec![[0.0, 0.0, 0.0]];
    for i in 0..=n {
        let a = i as f32 / (n + 1) as f32 * std::f32::consts::TAU;
        positions.push([a.cos(), a.sin(), 0.05 * (7.0 * a).sin()]);
    }
    let triangles = (1..=n as u32).map(|i| [0, i, i + 1]).collect();
    Mesh::new(positions, triangles)
}

/// The shapes of [`polygon_obj`].
#[derive(Clone, Copy, PartialEq)]
enum Shape {
    Convex,
    Star,
    Comb,
}

/// OBJ text of one polygon face with `n` corners: on a circle, every other one at half the
/// radius for a star, or a comb of `n / 4` teeth from the unit square's bottom to its top.
fn polygon_obj(n: usize, shape: Shape) -> String {
    let mut s = String::with_capacity(n * 40);
    let teeth = (n - 2) / 4;
    let n = if shape == Shape::Comb { 4 * teeth + 2 } else { n };
    for i in 0..n {
        let (x, y) = if shape == Shape::Comb {
            // Up and down each tooth left to right along y = 1 and y = 0.1, then back along y = 0.
            let w = 1.0 / (2 * teeth) as f64;
            match i {
                _ if i < 4 * teeth => {
                    let (t, k) = (i / 4, i % 4);
                    let x = (2 * t + usize::from(k >= 2)) as f64 * w;
                    (x, if k == 1 || k == 2 { 1.0 } else { 0.1 })
                }
                _ if i == 4 * teeth => (1.0, 0.0),
                _ => (0.0, 0.0),
            }
        } else {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            let r = if shape == Shape::Star && i % 2 == 1 { 0.5 } else { 1.0 };
            (r * a.cos(), r * a.sin())
        };
        s.push_str(&format!("v {x} {y} 0\n"));
    }
    s.push('f');
    for i in 1..=n {
        s.push_str(&format!(" {i}"));
    }
    s.push('\n');
    s
}

fn time<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let t = Instant::now();
    let r = f();
    (r, t.elapsed().as_secs_f64())
}

fn run(name: &str, mesh: &Mesh, what: &str) {
    if what != "pm" {
        let (enc, t) = time(|| bft::encode(mesh, bft::EncodeOptions::default()).expect("encodes"));
        println!(
            "{name:<16} {:>8} triangles  encode {t:>7.3} s ({} B, {} steps)",
            mesh.triangles.len(),
            enc.bytes.len(),
            enc.stats.work
        );
    }
    if what == "encode" {
        return;
    }
    let ((p, stats), t_build) = time(|| pm::build_with_stats(mesh, &mut |_, _| {}).expect("builds"));
    let (dpm, t_dpm) = time(|| pm::format::encode(&p, pm::DpmOptions::default()).expect("compresses"));
    println!(
        "{name:<16} {:>8} triangles  pm build {t_build:>7.3} s + .dpm {t_dpm:>7.3} s = {:>7.3} s ({} B, {} steps, {} hubs)",
        mesh.triangles.len(),
        t_build + t_dpm,
        dpm.bytes.len(),
        stats.work,
        stats.hubs,
    );
}

fn main() {
    let n: usize = std::env::args().nth(1).map_or(200_000, |a| a.parse().expect("N: a number of triangles or sides"));
    let what = std::env::args().nth(2).unwrap_or_default();
    run("fan", &fan(n), &what);
    for (name, shape) in
        [("convex polygon", Shape::Convex), ("star polygon", Shape::Star), ("comb polygon", Shape::Comb)]
    {
        let obj = polygon_obj(n, shape);
        let (mesh, t_load) =
            time(|| load_bytes(std::path::Path::new("polygon.obj"), obj.as_bytes(), Format::Obj).expect("loads"));
        println!("{name:<16} loaded and triangulated in {t_load:.3} s");
        run(name, &mesh, &what);
    }
}
