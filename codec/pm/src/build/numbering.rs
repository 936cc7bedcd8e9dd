//! The FVID numbering of section 3.2 (Figure 4) and the splits of section 4, from the
//! simplification's log: leaves numbered left to right over the collapse forest, the
//! positions and faces moved into that order, and one split per collapse, coarse to fine.

use std::borrow::Cow;

use super::options::PmError;
use super::simplify::Log;
use crate::pm::format::MAX_OP_FACES;
use crate::pm::order::place;
use crate::pm::{ProgressiveMesh, Split};

/// What the numbering makes of a simplification, and what the criteria read.
pub(super) struct Numbered {
    /// The progressive mesh without its normals and criteria.
    pub(super) pm: ProgressiveMesh,
    /// The triangles in split order as FVIDs: removed faces first, base faces after them.
    pub(super) triangles: Vec<[u32; 3]>,
    /// Each collapse's geometric error, in collapse order.
    pub(super) collapse_error: Vec<f64>,
}

/// The progressive mesh of a simplification's `log` over `model` (`n` input vertices, the
/// survivors `alive`).
pub(super) fn number(log: Log, alive: Vec<bool>, model: Model, n: usize) -> Result<Numbered, PmError> {
    crate::pm::trace("numbering");
    let Log { collapses, removed, removed_end, error: collapse_error } = log;
    // Faces that gathered on an edge during the simplification: refused here, before the
    // numbering and the encoding, where the format's check would find them.
    let mut from = 0;
    for (&(u, t), &end) in collapses.iter().zip(&removed_end) {
        let faces = (end - from) as usize;
        if faces > MAX_OP_FACES as usize {
            return Err(PmError::OpFaces { a: t.min(u), b: t.max(u), faces });
        }
        from = end;
    }

    // Leaves left to right = pre-order of the forest whose vertices' children are the
    // vertices they absorbed, chronologically, roots in ascending input index. Numbered
    // without building the forest: the subtree of a vertex `u` that `t` absorbs comes right
    // after what `t` had gathered, so `u`'s FVID is `t`'s plus `t`'s subtree size just before
    // (and `u`'s subtree is whole then: a dead vertex absorbs nothing). So each collapse
    // records an offset, and the FVIDs follow from the roots' down, latest collapse first
    // (what numbering per chunk needs: docs/design.md, "Builder memory").
    let mut size = vec![1u32; n];
    let offset: Vec<u32> = collapses
        .iter()
        .map(|&(u, t)| {
            let o = size[t as usize];
            size[t as usize] += size[u as usize];
            o
        })
        .collect();
    let mut fvid_of_input = vec![u32::MAX; n];
    let mut base_vertices = Vec::new();
    let mut numbered = 0u32;
    for root in (0..n).filter(|&v| alive[v]) {
        base_vertices.push(numbered);
        fvid_of_input[root] = numbered;
        numbered += size[root];
    }
    drop((size, alive));
    for (&(u, t), &o) in collapses.iter().zip(&offset).rev() {
        fvid_of_input[u as usize] = fvid_of_input[t as usize] + o;
    }
    drop(offset);
    crate::pm::trace("positions into FVID order");
    let Model { positions: model_positions, input_id, mut triangles, input_face } = model;
    // Per vertex of the model its FVID (`u32::MAX`: none), read in its order below.
    let fvid: Cow<[u32]> = if input_id.is_empty() {
        Cow::Borrowed(&fvid_of_input)
    } else {
        Cow::Owned(input_id.iter().map(|&v| fvid_of_input[v as usize]).collect())
    };
    drop(input_id);
    let mut positions = vec![[0.0f32; 3]; numbered as usize];
    for (&f, &p) in fvid.iter().zip(&model_positions) {
        if f != u32::MAX {
            positions[f as usize] = p;
        }
    }
    drop(model_positions);

    crate::pm::trace("base faces and splits");
    // The triangles moved into the order they are read in: each removed face's to its place
    // in the log, the base faces (never removed) after them in input order, in bucket passes
    // ([`place`]). Gathered through the log, they were read at random (the log runs chunk by
    // chunk, the faces' ids in input order): the 13.9M build in 200 MB spent 31 s here.
    let removed_faces = removed.len();
    let mut dest = vec![u32::MAX; triangles.len()];
    for (k, &f) in removed.iter().enumerate() {
        debug_assert_eq!(dest[f as usize], u32::MAX, "a face removed twice");
        dest[f as usize] = k as u32;
    }
    drop(removed);
    base_faces_after(&mut dest, &input_face, removed_faces as u32);
    drop(input_face);
    place(&mut triangles, &mut dest, 0);
    drop(dest);
    // The corners as FVIDs, in place (what the splits, the base mesh and the criteria read).
    triangles.iter_mut().for_each(|t| *t = t.map(|v| fvid[v as usize]));
    drop(fvid);
    let base_faces = triangles[removed_faces..].to_vec();
    let splits = collapses
        .iter()
        .enumerate()
        .rev()
        .map(|(i, &(u, t))| {
            let start = if i == 0 { 0 } else { removed_end[i - 1] as usize };
            Split {
                v: fvid_of_input[t as usize],
                v_u: fvid_of_input[u as usize],
                faces: triangles[start..removed_end[i] as usize].iter().copied().collect(),
            }
        })
        .collect();
    drop((collapses, removed_end));
    let pm = ProgressiveMesh { base_vertices, base_faces, splits, positions, fvid_of_input, ..Default::default() };
    Ok(Numbered { pm, triangles, collapse_error })
}

/// The model as the steps after the simplification read it: in the input's order after a
/// whole-model simplification, in leaf order after a chunked one (see [`Chunker`]). The log's
/// removed faces are indices into its `triangles`; the log's collapses, and the numbering,
/// use input vertex ids.
pub(super) struct Model {
    /// Per vertex: its position.
    pub(super) positions: Vec<[f32; 3]>,
    /// Per vertex: its input id (empty: the ids are the input's).
    pub(super) input_id: Vec<u32>,
    /// The faces, their corners in this model's vertex ids; the log's removed faces are
    /// indices here.
    pub(super) triangles: Vec<[u32; 3]>,
    /// Per face: its input id (empty: the ids are the input's).
    pub(super) input_face: Vec<u32>,
}

/// Gives the faces not yet placed in `dest` (`u32::MAX`, the base faces: never removed) their
/// places from `first` on, in input order: by their index where `input_face` is empty, else by
/// their input ids there (ranked with a bit per input face, so that no array of the faces'
/// size is read at random).
fn base_faces_after(dest: &mut [u32], input_face: &[u32], first: u32) {
    if input_face.is_empty() {
        for (next, d) in (first..).zip(dest.iter_mut().filter(|d| **d == u32::MAX)) {
            *d = next;
        }
        return;
    }
    let mut base = vec![0u64; dest.len().div_ceil(64)];
    for (&d, &f) in dest.iter().zip(input_face) {
        if d == u32::MAX {
            base[f as usize / 64] |= 1 << (f % 64);
        }
    }
    let mut before = Vec::with_capacity(base.len());
    let mut count = first;
    for w in &base {
        before.push(count);
        count += w.count_ones();
    }
    for (d, &f) in dest.iter_mut().zip(input_face) {
        if *d == u32::MAX {
            let (w, b) = (f as usize / 64, f % 64);
            *d = before[w] + (base[w] & ((1u64 << b) - 1)).count_ones();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::base_faces_after;

    /// The base faces (those `dest` leaves unplaced) take the places after `first` in the
    /// order of their input ids, whatever order the faces are in: against sorting them.
    #[test]
    fn base_faces_are_placed_in_input_order() {
        let mut rng = testkit::XorShift(0x9e37_79b9_7f4a_7c15);
        let mut next = || rng.next_u64();
        for len in [0usize, 1, 63, 64, 65, 1000, 4099] {
            // A permutation of the input ids (Fisher-Yates), about every third face removed.
            let mut input_face: Vec<u32> = (0..len as u32).collect();
            for i in (1..len).rev() {
                input_face.swap(i, next() as usize % (i + 1));
            }
            let removed: Vec<usize> = (0..len).filter(|_| next() % 3 == 0).collect();
            let mut dest = vec![u32::MAX; len];
            for (place, &k) in removed.iter().enumerate() {
                dest[k] = place as u32;
            }
            let first = removed.len() as u32;
            let mut expected = dest.clone();
            let mut base: Vec<usize> = (0..len).filter(|&k| dest[k] == u32::MAX).collect();
            base.sort_by_key(|&k| input_face[k]);
            for (place, k) in (first..).zip(base) {
                expected[k] = place;
            }
            let mut identity = dest.clone();
            base_faces_after(&mut dest, &input_face, first);
            assert_eq!(dest, expected, "{len} faces");
            // In input order already (no permutation): the places by index.
            let mut by_index = identity.clone();
            for (place, k) in (first..).zip((0..len).filter(|&k| identity[k] == u32::MAX)) {
                by_index[k] = place;
            }
            base_faces_after(&mut identity, &[], first);
            assert_eq!(identity, by_index, "{len} faces in input order");
        }
    }
}
