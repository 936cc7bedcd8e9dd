//! The refinement criteria of section 4 and 4.2.3 ([`Criteria`]), bottom-up over the split
//! tree in `f64` (see the module docs of [`super`] for the bounds and the slack).

use super::simplify::distinct_corners;
use super::vec3::{angle, cross, norm, sub};
use crate::pm::order::{permute_in_place, place, preorder, sort_in_place_by_key};
use crate::progressive::{Criteria, ProgressiveMesh};

/// Relative slack of the nesting bounds (radius, cone angle) per level.
const SLACK: f64 = 1e-5;

/// The per-FVID normals and the per-split criteria (see the module docs) of the input
/// triangles `faces` (in FVIDs, in any order; sorted in place, and freed once the normals and
/// leaf cones are made).
pub(super) fn criteria(
    pm: &ProgressiveMesh,
    mut faces: Vec<[u32; 3]>,
    geometric: Vec<f64>,
) -> (Vec<[f32; 3]>, Vec<Criteria>) {
    let n = pm.positions.len();
    let pos = |f: usize| pm.positions[f].map(f64::from);
    // The finest faces (in FVIDs) sorted by their first FVID, so that the passes below read
    // and add to the per-FVID arrays in a sweep: in input order they went at random through
    // 44 bytes an FVID, and the 102M build in 1.5 GB spent 115 s in them.
    sort_in_place_by_key(&mut faces, &|t: &[u32; 3]| t[0].min(t[1]).min(t[2]));
    let finest = || faces.iter().copied();
    let face_normal = |t: &[u32; 3]| {
        let [a, b, c] = t.map(|f| pos(f as usize));
        cross(sub(b, a), sub(c, a))
    };
    let mut normal = vec![[0.0f64; 3]; n];
    for t in finest() {
        let fnrm = face_normal(&t);
        for f in distinct_corners(t) {
            for a in 0..3 {
                normal[f as usize][a] += fnrm[a];
            }
        }
    }
    for v in &mut normal {
        let l = norm(*v);
        *v = if l > 0.0 && l.is_finite() { v.map(|x| x / l) } else { [0.0; 3] };
    }
    crate::pm::trace("criteria: leaf cones");
    // Leaf cones: the angle between a vertex normal and its incident face normals.
    let mut leaf_alpha = vec![0.0f64; n];
    for t in finest() {
        let fnrm = face_normal(&t);
        let l = norm(fnrm);
        if !(l > 0.0 && l.is_finite()) {
            continue;
        }
        let fnrm = fnrm.map(|x| x / l);
        for f in t {
            let a = angle(normal[f as usize], fnrm);
            leaf_alpha[f as usize] = leaf_alpha[f as usize].max(a);
        }
    }
    drop(faces);
    crate::pm::trace("criteria: split tree");

    // Per split, in f64: radius (which is also the geometric error, see below; made from
    // the geometric error), attribute error, cone angle; a split's from its children's, so
    // bottom-up: in the reverse of the split tree's pre-order, a sort ([`preorder`]), where a
    // split's children are the two subtrees done last and its FVIDs those of the splits
    // around it (in split order, what this followed before, a split's children and FVIDs lie
    // anywhere in the arrays: a spilled build read their pages back again and again).
    crate::pm::trace("criteria: per split");
    let mut order = preorder(&pm.splits);
    let mut vertices: Vec<[u32; 2]> = pm.splits.iter().map(|s| [s.v, s.v_u]).collect();
    let mut geometric = geometric;
    permute_in_place(&mut vertices, &mut geometric, &order);
    let max_angle = std::f64::consts::FRAC_PI_2;
    // The subtrees done whose parent is not yet: their vertex, radius, attribute error and
    // cone angle.
    let mut done: Vec<(u32, [f64; 3])> = Vec::new();
    let mut criteria = vec![Criteria::default(); pm.splits.len()];
    for (p, &[v, u]) in vertices.iter().enumerate().rev() {
        // A child's radius, attribute error and cone angle: the subtree done last where it
        // splits `f` (the left child splits `v` again, the right one `v_u`), else a leaf's.
        let mut child = |f: u32| match done.last() {
            Some(&(w, c)) if w == f => {
                done.pop();
                c
            }
            _ => [0.0, 0.0, leaf_alpha[f as usize]],
        };
        let (l, r) = (child(v), child(u));
        let (v, u) = (v as usize, u as usize);
        // The geometric error is at least the farthest finest vertex of the region from `v`,
        // so it serves as the region's bounding radius (conservatively: a larger sphere only
        // refines more near the frustum's sides), and the radius costs nothing to store. It
        // is raised where needed so that the children's spheres nest in it: a child's error
        // may exceed its region (raised to its neighbours'), and the runtime tests spheres,
        // which must nest for a child never to ask for a split its parent does not.
        let nest = |c: [f64; 3], d: f64| (d + c[0]) * (1.0 + SLACK);
        let radius = geometric[p].max(nest(l, 0.0)).max(nest(r, norm(sub(pos(u), pos(v)))));
        let attribute = l[1].max(norm(sub(normal[u], normal[v])) + r[1]);
        let alpha = (l[2].max(angle(normal[v], normal[u]) + r[2]) * (1.0 + SLACK) + SLACK).min(max_angle);
        let cone = if norm(normal[v]) == 0.0 { max_angle } else { alpha };
        done.push((v as u32, [radius, attribute, cone]));
        criteria[p] = Criteria {
            sin_alpha: if cone >= max_angle { 1.0 } else { cone.sin() as f32 },
            geometric_error: radius as f32,
            attribute_error: attribute as f32,
            radius: radius as f32,
        };
    }
    drop((vertices, geometric, leaf_alpha));
    // Into split order.
    place(&mut criteria, &mut order, 0);
    let normal: Vec<[f32; 3]> = normal.iter().map(|v| v.map(|x| x as f32)).collect();
    (normal, criteria)
}
