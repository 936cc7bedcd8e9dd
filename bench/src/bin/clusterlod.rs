//! `clusterlod`: the peer of `tessera encode --lod`'s build, in the same run on the same mesh:
//! meshoptimizer's clusterlod (`meshopt::clod_build`, the library behind the figure of
//! NVIDIA's 1.64-billion-triangle Zorah scene built in about 3 minutes that issue 51 cites),
//! in core and on one thread, as the library runs it.
//!
//! `/usr/bin/time -v cargo run --release -p tessera-bench --bin clusterlod -- MODEL [--max-triangles 128] [--normal-weight 2] [--bytes]`
//!
//! It loads the mesh, gives clusterlod the area-weighted vertex normals as attributes (the
//! ones `encode --lod` weighs in its simplifier, at the same weight unless told; clusterlod
//! scales positions to the whole model where ours scales them to each group), builds the
//! hierarchy with the library's default configuration for rasterization (clusters of
//! `--max-triangles`, groups of about 16 clusters simplified to half with their borders
//! locked, until one cluster is left), and prints the input, the groups, clusters, levels and
//! triangles it made, and the build's time and input triangles a second. Loading and the
//! normals are timed apart: the build's time is clusterlod's alone. Peak memory is the
//! process's (`/usr/bin/time -v`). With `--bytes`, it also prints what the hierarchy takes
//! stored as a cluster renderer stores it, coded with meshopt's codecs (`stored_bytes`), to
//! set beside the `--lod` file's bytes a triangle.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{ensure, Result};
use clap::Parser;
use codec::bft::chunked::lod::NORMAL_WEIGHT;
use codec::bft::normals::vertex_normals;

#[derive(Parser)]
#[command(name = "clusterlod", version)]
struct Args {
    /// A mesh file (OBJ, PLY, STL, optionally .gz).
    input: PathBuf,
    /// Triangles a cluster holds at most (clusterlod takes 4 to 256; Nanite's are 128).
    #[arg(long, default_value_t = 128, value_parser = clap::value_parser!(u16).range(4..=256))]
    max_triangles: u16,
    /// The normals' weight in the simplifier's error (0: positions alone).
    #[arg(long, default_value_t = NORMAL_WEIGHT, value_parser = master::cli::parse_non_negative)]
    normal_weight: f32,
    /// Also code the hierarchy's clusters with meshopt's codecs and print the bytes it would
    /// take stored (keeps every cluster's triangles in memory).
    #[arg(long)]
    bytes: bool,
}

fn main() -> ExitCode {
    match run(&Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(a: &Args) -> Result<()> {
    let start = Instant::now();
    let mesh = master::model::load_mesh(&a.input)?;
    let load_s = start.elapsed().as_secs_f64();
    ensure!(!mesh.triangles.is_empty(), "{}: no triangles", a.input.display());
    let start = Instant::now();
    let normals = vertex_normals(&mesh.positions, &mesh.triangles, &[]);
    let normals_s = start.elapsed().as_secs_f64();

    let indices: &[u32] = bytemuck::cast_slice(&mesh.triangles);
    let positions = meshopt::VertexDataAdapter::new(bytemuck::cast_slice(&mesh.positions), 12, 0)?;
    let weights = [a.normal_weight; 3];
    let mut input = meshopt::ClodMesh::new(indices, &positions);
    if a.normal_weight > 0.0 {
        input.vertex_attributes = bytemuck::cast_slice(&normals);
        input.vertex_attributes_stride = 12;
        input.attribute_weights = &weights;
    }
    let config = meshopt::clod_default_config(a.max_triangles as usize);
    let (mut groups, mut clusters, mut triangles, mut depth) = (0u64, 0u64, 0u64, 0i32);
    // With --bytes, each cluster's indices, copied as made (their coding waits until the
    // build is timed).
    let mut made_clusters: Vec<Vec<u32>> = Vec::new();
    let start = Instant::now();
    meshopt::clod_build(config, &input, |group, made| {
        groups += 1;
        depth = depth.max(group.depth);
        clusters += made.len() as u64;
        triangles += made.iter().map(|c| c.indices.len() as u64 / 3).sum::<u64>();
        if a.bytes {
            made_clusters.extend(made.iter().map(|c| c.indices.to_vec()));
        }
        groups as i32 - 1
    });
    let build_s = start.elapsed().as_secs_f64();
    let input_triangles = mesh.triangles.len() as f64;
    println!(
        "{}: {} triangles, {} vertices; loaded in {load_s:.1} s, normals in {normals_s:.1} s",
        a.input.display(),
        mesh.triangles.len(),
        mesh.positions.len()
    );
    println!(
        "clusterlod (clusters of at most {}, normal weight {}, one thread): {groups} groups, {clusters} clusters, \
         {} levels, {triangles} triangles in all levels ({:.2}x the input), in {build_s:.1} s: {:.3}M input triangles/s",
        a.max_triangles,
        a.normal_weight,
        depth + 1,
        triangles as f64 / input_triangles,
        input_triangles / build_s / 1e6
    );
    if a.bytes {
        let (positions_only, with_normals) = stored_bytes(&mesh.positions, &normals, &made_clusters, groups)?;
        println!(
            "stored as meshopt-coded clusters (16-bit positions; 10-bit octahedral normals): {positions_only} bytes \
             ({:.2} a triangle) without normals, {with_normals} ({:.2}) with them",
            positions_only as f64 / input_triangles,
            with_normals as f64 / input_triangles
        );
    }
    Ok(())
}

/// Bytes a cluster takes besides its coded triangles and vertices: its vertex and triangle
/// counts (a byte each), the two coded sizes (2 bytes each) and the group it refines (4).
const CLUSTER_HEADER: u64 = 10;
/// Bytes a group takes: its bounding sphere and error (5 floats).
const GROUP_HEADER: u64 = 20;

/// The bytes of the hierarchy stored as a cluster renderer stores it, each cluster's own
/// vertices beside its triangles, coded with meshopt's codecs: `encode_meshlet` for the
/// clusters' local triangles, `encode_vertex_buffer` for their vertices (positions at 16
/// bits over the model's box; with normals, octahedral at 10 bits, `encode --lod`'s
/// default), plus the headers above. Returns the bytes without and with normals.
fn stored_bytes(
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    clusters: &[Vec<u32>],
    groups: u64,
) -> Result<(u64, u64)> {
    let q = codec::Quantization::fit(positions, None, 16)?;
    let quantized = |v: u32| q.quantize(positions[v as usize]).map(|c| c as u16);
    let shift = 16 - codec::bft::attributes::DEFAULT_NORMAL_BITS;
    let headers = clusters.len() as u64 * CLUSTER_HEADER + groups * GROUP_HEADER;
    let (mut without, mut with) = (headers, headers);
    for indices in clusters {
        let (vertices, triangles) = meshopt::clod_local_indices(indices);
        let index_bytes =
            meshopt::encode_meshlet(meshopt::Meshlet { vertices: &[], triangles: &triangles })?.len() as u64;
        let bare: Vec<[u16; 4]> = vertices
            .iter()
            .map(|&v| {
                let [x, y, z] = quantized(v);
                [x, y, z, 0]
            })
            .collect();
        let full: Vec<[u16; 6]> = vertices
            .iter()
            .map(|&v| {
                let [x, y, z] = quantized(v);
                let [u, w] = codec::bft::chunked::oct_encode(normals[v as usize]).map(|c| c >> shift);
                [x, y, z, u, w, 0]
            })
            .collect();
        without += index_bytes + meshopt::encode_vertex_buffer(&bare)?.len() as u64;
        with += index_bytes + meshopt::encode_vertex_buffer(&full)?.len() as u64;
    }
    Ok((without, with))
}
