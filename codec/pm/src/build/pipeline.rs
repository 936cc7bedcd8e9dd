//! The builder's entry points and its steps in order: the input checks, the simplification
//! (whole or in chunks), the FVID numbering and the splits, then the refinement criteria.

use std::borrow::Cow;

use super::chunks::simplify_chunked;
use super::criteria::criteria;
use super::numbering::{number, Model, Numbered};
use super::options::{BuildOptions, BuildStats, PmError};
use super::simplify::{distinct_corners, run, Ids, Log, Simplifier, VertexErrors};
use super::vec3::sub;
use crate::mesh::Mesh;
use crate::pm::format::MAX_OP_FACES;
use crate::progressive::ProgressiveMesh;

/// Refuses, before any work, a mesh with an edge of more than [`MAX_OP_FACES`] faces: the
/// collapse of such an edge (unless its faces went with other collapses first) makes an
/// operation the format cannot hold. A face counts once per pair of its distinct corners
/// (`[a, a, b]` holds the edge `a b`). Counts faces per vertex first (two bytes a vertex,
/// saturating) and pairs only among the vertices of that many faces, so a mesh without such
/// a vertex costs one pass.
pub fn check_op_faces(mesh: &Mesh) -> Result<(), PmError> {
    let max = MAX_OP_FACES as usize;
    let mut per_vertex = vec![0u16; mesh.positions.len()];
    for &t in &mesh.triangles {
        for v in distinct_corners(t) {
            if let Some(c) = per_vertex.get_mut(v as usize) {
                *c = c.saturating_add(1);
            }
        }
    }
    // Both ends of such an edge have more than `max` faces, so a saturated count.
    let hub = |v: u32| per_vertex.get(v as usize).is_some_and(|&c| c as usize >= max.min(u16::MAX as usize));
    let mut pairs: rustc_hash::FxHashMap<(u32, u32), usize> = Default::default();
    for &t in &mesh.triangles {
        let corners: smallvec::SmallVec<[u32; 3]> = distinct_corners(t).filter(|&v| hub(v)).collect();
        for i in 0..corners.len() {
            for j in i + 1..corners.len() {
                let (a, b) = (corners[i].min(corners[j]), corners[i].max(corners[j]));
                *pairs.entry((a, b)).or_default() += 1;
            }
        }
    }
    match pairs.into_iter().filter(|&(_, n)| n > max).max_by_key(|&((a, b), n)| (n, std::cmp::Reverse((a, b)))) {
        Some(((a, b), faces)) => Err(PmError::OpFaces { a, b, faces }),
        None => Ok(()),
    }
}

/// Builds the progressive mesh of `mesh`: collapses every edge, cheapest quadric error first,
/// numbers the vertices by the collapse forest and records the splits coarse to fine.
///
/// Any topology is accepted (see the module docs); the mesh must only pass
/// [`Mesh::validate`]: indices in range, finite positions for used vertices.
pub fn build(mesh: &Mesh) -> Result<ProgressiveMesh, PmError> {
    build_with_progress(mesh, &mut |_, _| {})
}

/// As [`build`], calling `progress(collapses_done, bound)` now and then; `bound` is the
/// number of used vertices, which the collapses (one per vertex that is not a base vertex)
/// approach but never reach.
pub fn build_with_progress(mesh: &Mesh, progress: &mut dyn FnMut(usize, usize)) -> Result<ProgressiveMesh, PmError> {
    build_with_stats(mesh, progress).map(|(pm, _)| pm)
}

/// As [`build_with_progress`], also returning what the builder did.
pub fn build_with_stats(
    mesh: &Mesh,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(ProgressiveMesh, BuildStats), PmError> {
    build_with_options(mesh, BuildOptions::default(), progress)
}

/// As [`build_with_stats`], with the chunk size of `opts`.
pub fn build_with_options(
    mesh: &Mesh,
    opts: BuildOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(ProgressiveMesh, BuildStats), PmError> {
    build_mesh(Cow::Borrowed(mesh), opts, progress)
}

/// As [`build_with_options`], taking the mesh so that its positions are freed once numbered
/// into the progressive mesh and its triangles once the normals are made from them (on a
/// large model 18 bytes a triangle less while the splits and criteria are made): what
/// `tessera pm build` runs. The progressive mesh is the same.
pub fn build_owned(
    mesh: Mesh,
    opts: BuildOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(ProgressiveMesh, BuildStats), PmError> {
    build_mesh(Cow::Owned(mesh), opts, progress)
}

/// [`build_with_options`] and [`build_owned`].
fn build_mesh(
    mesh: Cow<Mesh>,
    opts: BuildOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(ProgressiveMesh, BuildStats), PmError> {
    mesh.validate()?;
    check_op_faces(&mesh)?;
    let n = mesh.positions.len();
    let used = mesh.used_vertices();
    let bound = used.iter().filter(|&&u| u).count();
    // Positions relative to the centre of the used vertices' box (finite: `Mesh::validate`
    // ran), so the quadrics of a model far from the origin keep their precision.
    let used_positions = mesh.positions.iter().zip(&used).filter(|(_, &a)| a).map(|(p, _)| p);
    let centre: [f64; 3] = match crate::mesh::bounding_box(used_positions) {
        Some((lo, hi)) => std::array::from_fn(|a| 0.5 * (f64::from(lo[a]) + f64::from(hi[a]))),
        None => [0.0; 3],
    };
    let mut log = Log::default();
    let mut report = |done: usize| progress(done, bound);
    crate::pm::trace("simplifying");
    let (stats, alive, model) = if opts.chunk_faces > 0 && mesh.triangles.len() > opts.chunk_faces {
        let (stats, model) = simplify_chunked(mesh, centre, opts.chunk_faces, &mut log, &mut report);
        let mut alive = used;
        for &(u, _) in &log.collapses {
            alive[u as usize] = false;
        }
        (stats, alive, model)
    } else {
        drop(used);
        let pos = mesh.positions.iter().map(|p| sub(p.map(f64::from), centre)).collect();
        let mut s = Simplifier::new(pos, mesh.triangles.clone(), None, vec![false; n]);
        let (mut reach, mut error) = (vec![0.0f64; n], vec![0.0f64; n]);
        let ids = Ids { vertex: &[], face: &[] };
        run(
            &mut s,
            &mesh.positions,
            ids,
            VertexErrors { reach: &mut reach, error: &mut error },
            0,
            &mut log,
            &mut report,
        );
        // Only the survivors and the statistics are read from here on: free the working
        // state (quadrics, face lists, heap: most of the build's memory) before the forest is
        // numbered.
        let stats = BuildStats { collapses: log.collapses.len(), hubs: s.hubs, work: s.work, chunks: 1 };
        let alive = std::mem::take(&mut s.alive);
        drop(s);
        let (positions, triangles) = match mesh {
            Cow::Owned(m) => (m.positions, m.triangles),
            Cow::Borrowed(m) => (m.positions.clone(), m.triangles.clone()),
        };
        (stats, alive, Model { positions, input_id: Vec::new(), triangles, input_face: Vec::new() })
    };
    report(log.collapses.len());
    let Numbered { mut pm, triangles, collapse_error } = number(log, alive, model, n)?;
    // Splits run coarse to fine, the reverse of the collapses.
    let mut geometric = collapse_error;
    geometric.reverse();
    crate::pm::trace("criteria: normals");
    let (normals, criteria) = criteria(&pm, triangles, geometric);
    crate::pm::trace("criteria done");
    pm.normals = normals;
    pm.criteria = criteria;
    Ok((pm, stats))
}
