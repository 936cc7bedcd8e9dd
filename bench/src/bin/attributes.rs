//! `attributes`: the bytes of each per-vertex attribute in a `.bft` stream against Draco's
//! for the same attribute and quantization, in the same run (issue 17's target: Tessera's at
//! most Draco's).
//!
//! `cargo run --release -p tessera-bench --bin attributes -- MODEL... [--normal-bits N]`
//!
//! Each model is encoded as one `.bft` stream (no chunks) with positions at 16 bits; the
//! colour and normal sections' bytes are read from the file. Draco (level 7, positions at 16
//! bits) encodes the positions alone, then with the colours, then with the normals at the
//! same octahedral bits; an attribute's Draco bytes are the growth of the file it causes.

use anyhow::{bail, Context, Result};
use codec::bft::{self, EncodeOptions};
use tessera_bench::peers::{draco_encode, draco_encode_attributes, DracoAttributes};

fn main() -> Result<()> {
    let mut models = Vec::new();
    let mut normal_bits = bft::attributes::DEFAULT_NORMAL_BITS;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--normal-bits" => normal_bits = args.next().context("--normal-bits N")?.parse()?,
            _ => models.push(a),
        }
    }
    if models.is_empty() {
        bail!("usage: attributes MODEL... [--normal-bits N]");
    }
    println!("model,attribute,vertices,tessera_bytes,tessera_bits_per_vertex,draco_bytes,draco_bits_per_vertex,ratio");
    for path in &models {
        let mesh = codec::load_path(std::path::Path::new(path))?;
        let name = std::path::Path::new(path).file_name().unwrap().to_string_lossy().into_owned();
        let enc = bft::encode(&mesh, EncodeOptions { quant_bits: 16, normal_bits, ..Default::default() })?;
        let stats = bft::Stats::of(&enc.bytes)?;
        let vertices = stats.header.unique_vertices() as f64;
        let base = draco_encode(&mesh.positions, &mesh.triangles, 16)?.len();
        let report = |what: &str, ours: usize, extra: DracoAttributes| -> Result<()> {
            let with = draco_encode_attributes(&mesh.positions, &mesh.triangles, 16, &extra)?.len();
            let draco = with.saturating_sub(base);
            println!(
                "{name},{what},{vertices},{ours},{:.3},{draco},{:.3},{:.3}",
                ours as f64 * 8.0 / vertices,
                draco as f64 * 8.0 / vertices,
                ours as f64 / draco.max(1) as f64
            );
            Ok(())
        };
        if !mesh.colors.is_empty() {
            let alpha = enc.header.attributes.alpha;
            let what = if alpha { "rgba8" } else { "rgb8" };
            report(what, stats.color_bytes, DracoAttributes { colors: Some((&mesh.colors, alpha)), normals: None })?;
        }
        if !mesh.normals.is_empty() {
            let what = format!("normal{normal_bits}");
            let extra = DracoAttributes { colors: None, normals: Some((&mesh.normals, normal_bits)) };
            report(&what, stats.normal_bytes, extra)?;
        }
    }
    Ok(())
}
