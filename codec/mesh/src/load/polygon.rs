//! Triangulation of the loaders' polygons (PLY face lists and OBJ faces alike), in time
//! linear in the corners for a convex polygon and `O(n log n)`-like for a concave one.
//!
//! * A triangle is kept as it is.
//! * A polygon is projected onto the plane of its Newell normal (the normal its winding
//!   gives, also for a polygon that is not quite planar), oriented so that the polygon runs
//!   counter-clockwise in the plane.
//! * A **convex** polygon (every turn to the left or straight, and the boundary going round
//!   once: an `O(n)` test) is fanned from its first corner, `(v0, v1, v2), (v0, v2, v3), ...`,
//!   as the loaders always did, so convex quads and polygons load to the same triangles.
//! * A **concave** polygon of up to [`EAR_CLIP_CORNERS`] corners is ear-clipped in the plane
//!   by the `earcut` crate (a port of Mapbox's earcut, which also copes with self-touching
//!   outlines, such as a bridge to a hole traversed both ways). Every triangle is oriented
//!   like the polygon (counter-clockwise in the plane, so its normal agrees with the Newell
//!   normal), starts at its first corner in the polygon, and the triangles are sorted, so a
//!   triangulation that is the fan is written as the fan. earcut leaves out corners that carry
//!   no area (a repeated corner, a corner in the middle of a straight edge), so such a corner
//!   of a concave polygon is in no triangle; the triangles still cover the polygon exactly.
//!   But when corners are left out of an outline that crosses itself (a twisted quad, which
//!   is a bow tie in its plane), the polygon is fanned as before, keeping every corner.
//! * A larger concave polygon is triangulated by the constrained Delaunay triangulation of
//!   its outline (the `spade` crate, exact predicates, `O(n log n)`), keeping the triangles
//!   inside: those reached from the left of an outline edge without crossing one. Ear
//!   clipping finds an ear by testing the other corners in its bounding box, which on a star
//!   of long thin spikes holds a large share of them: earcut took 14.8 s for a star of 200k
//!   corners. An outline whose edges cross (self-intersecting), or with a corner on another
//!   edge, goes to earcut after all. Repeated positions are one vertex here (one of their
//!   corners' indices stands for all); an edge traversed both ways (a bridge to a hole) has
//!   the inside on both sides.
//! * A **degenerate** polygon, with no area (all corners collinear or repeated: a Newell
//!   normal that vanishes next to the polygon's squared extent), or with a corner that is not
//!   finite or not in the vertex list (the loader then reports the bad index), is fanned: its
//!   triangles have no area, but every corner stays in the mesh, as before. So is a concave
//!   polygon whose ear clipping gives no triangle at all, and one of more than 2^24 corners
//!   (beyond what earcut is sure to index).

use earcut::Earcut;
use spade::handles::FixedVertexHandle;
use spade::{ConstrainedDelaunayTriangulation, HasPosition, Point2, Triangulation};

/// Polygons with more corners than this are fanned (earcut's node offsets are 32-bit).
const MAX_EARCUT_CORNERS: usize = 1 << 24;

/// Concave polygons with more corners than this go to the constrained Delaunay triangulation.
pub(super) const EAR_CLIP_CORNERS: usize = 256;

/// A polygon corner in the plane, with its place in the polygon.
#[derive(Clone, Copy)]
struct Corner {
    at: Point2<f64>,
    k: u32,
}

impl HasPosition for Corner {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.at
    }
}

/// Reusable buffers for triangulating many polygons.
#[derive(Default)]
pub(super) struct Triangulator {
    earcut: Earcut<f64>,
    plane: Vec<[f64; 2]>,
    /// How far the projected corners may be from where exact positions would put them: the
    /// rounding of `f32` positions of this magnitude.
    noise: f64,
    ears: Vec<u32>,
    /// Triangles as corner places in the polygon.
    tris: Vec<[u32; 3]>,
}

/// Appends triangles given by corner places (oriented like the polygon), each rotated to start
/// at its first corner in the polygon and sorted: so a triangulation that happens to be the
/// fan comes out exactly as [`fan`] writes it.
fn emit(poly: &[u32], tris: &mut [[u32; 3]], out: &mut Vec<[u32; 3]>) {
    for t in tris.iter_mut() {
        let m = (0..3).min_by_key(|&i| t[i]).unwrap_or(0);
        *t = [t[m], t[(m + 1) % 3], t[(m + 2) % 3]];
    }
    tris.sort_unstable();
    out.extend(tris.iter().map(|t| t.map(|k| poly[k as usize])));
}

/// The fan `(v0, v1, v2), (v0, v2, v3), ...` of a polygon of at least three corners.
pub(super) fn fan(poly: &[u32], out: &mut Vec<[u32; 3]>) {
    out.extend(poly[1..].windows(2).map(|w| [poly[0], w[0], w[1]]));
}

impl Triangulator {
    /// Appends the triangles of the polygon with corners `poly` (indices into `positions`,
    /// in winding order) to `out`; a polygon of fewer than three corners gives none.
    pub(super) fn polygon(&mut self, positions: &[[f32; 3]], poly: &[u32], out: &mut Vec<[u32; 3]>) {
        if poly.len() < 3 {
            return;
        }
        if poly.len() == 3 {
            out.push([poly[0], poly[1], poly[2]]);
            return;
        }
        let finite = |&i: &u32| positions.get(i as usize).is_some_and(|p| p.iter().all(|c| c.is_finite()));
        if poly.len() > MAX_EARCUT_CORNERS || !poly.iter().all(finite) {
            return fan(poly, out);
        }
        if !self.project(positions, poly) || self.is_convex() {
            return fan(poly, out);
        }
        if poly.len() > EAR_CLIP_CORNERS && self.delaunay(poly, out) {
            return;
        }
        self.earcut.earcut(self.plane.iter().copied(), &[] as &[u32], &mut self.ears);
        if self.ears.len() < 3 * (poly.len() - 2) && self.crosses_itself() {
            // A corner in no triangle of an outline that crosses itself (a twisted quad seen in
            // its plane is a bow tie): the fan keeps every corner, as before.
            return fan(poly, out);
        }
        let mut tris = std::mem::take(&mut self.tris);
        tris.clear();
        for t in self.ears.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]];
            let flip = cross2(self.plane[a as usize], self.plane[b as usize], self.plane[c as usize]) < 0.0;
            tris.push(if flip { [a, c, b] } else { [a, b, c] });
        }
        emit(poly, &mut tris, out);
        self.tris = tris;
    }

    /// Triangulates the projected polygon by the constrained Delaunay triangulation of its
    /// outline, keeping the faces inside; false (nothing appended) if the outline crosses
    /// itself or the triangulation cannot be made.
    fn delaunay(&self, poly: &[u32], out: &mut Vec<[u32; 3]>) -> bool {
        // Corners go in along the outline, each located from the one before (constant time
        // for an outline, where spade's bulk loading, a radial sweep from the centroid, slows
        // down on corners that are equally far from it, as a regular star's are); a corner at
        // the position of an earlier one is that vertex.
        let n = self.plane.len();
        let mut cdt = ConstrainedDelaunayTriangulation::<Corner>::new();
        let mut vertex_of: Vec<FixedVertexHandle> = Vec::with_capacity(n);
        for (k, &[x, y]) in self.plane.iter().enumerate() {
            let c = Corner { at: spade::mitigate_underflow(Point2::new(x, y)), k: k as u32 };
            let v = match vertex_of.last() {
                Some(&hint) => cdt.insert_with_hint(c, hint),
                None => cdt.insert(c),
            };
            let Ok(v) = v else {
                return false;
            };
            vertex_of.push(v);
        }
        for k in 0..n {
            let (a, b) = (vertex_of[k], vertex_of[(k + 1) % n]);
            if a != b && !cdt.exists_constraint(a, b) && cdt.try_add_constraint(a, b).is_empty() {
                return false; // the outline crosses itself
            }
        }
        // Inside: the faces on the left of the outline's edges (the outline runs
        // counter-clockwise), and those reached from them without crossing a constraint.
        let mut inside = vec![false; cdt.num_all_faces()];
        let mut stack = Vec::new();
        for k in 0..n {
            let (from, to) = (vertex_of[k], vertex_of[(k + 1) % n]);
            if from == to {
                continue;
            }
            // Missing when a corner lies on the edge (spade splits the constraint there).
            let Some(e) = cdt.get_edge_from_neighbors(from, to) else {
                return false;
            };
            let f = e.face();
            if !f.is_outer() && !inside[f.fix().index()] {
                inside[f.fix().index()] = true;
                stack.push(f.fix());
            }
        }
        while let Some(f) = stack.pop() {
            let Some(face) = cdt.face(f).as_inner() else {
                continue;
            };
            for e in face.adjacent_edges() {
                if cdt.is_constraint_edge(e.as_undirected().fix()) {
                    continue;
                }
                let g = e.rev().face();
                if g.is_outer() {
                    // Reached the outside without crossing the outline: not a simple polygon.
                    return false;
                }
                if !inside[g.fix().index()] {
                    inside[g.fix().index()] = true;
                    stack.push(g.fix());
                }
            }
        }
        let mut tris: Vec<[u32; 3]> =
            cdt.inner_faces().filter(|f| inside[f.fix().index()]).map(|f| f.vertices().map(|v| v.data().k)).collect();
        if tris.is_empty() {
            return false;
        }
        emit(poly, &mut tris, out);
        true
    }

    /// Whether two edges of the projected outline that share no corner cross properly (a
    /// quadratic test, for the ear-clipped polygons only).
    fn crosses_itself(&self) -> bool {
        let p = &self.plane;
        let n = p.len();
        let side = |a, b, c| cross2(a, b, c).partial_cmp(&0.0);
        (0..n).any(|i| {
            let (a, b) = (p[i], p[(i + 1) % n]);
            (i + 2..n).filter(|&j| (j + 1) % n != i).any(|j| {
                let (c, d) = (p[j], p[(j + 1) % n]);
                let (s1, s2) = (side(a, b, c), side(a, b, d));
                let (s3, s4) = (side(c, d, a), side(c, d, b));
                let opposite = |x: Option<std::cmp::Ordering>, y| {
                    x.is_some_and(|x| x != std::cmp::Ordering::Equal) && y == x.map(|x| x.reverse())
                };
                opposite(s1, s2) && opposite(s3, s4)
            })
        })
    }

    /// Projects the corners into `plane`, a 2D frame of the plane of the polygon's Newell
    /// normal `n` (with `(e1, e2, n)` right-handed, so the polygon runs counter-clockwise);
    /// false for a polygon without area.
    fn project(&mut self, positions: &[[f32; 3]], poly: &[u32]) -> bool {
        let p0 = positions[poly[0] as usize].map(f64::from);
        let at = |i: u32| {
            let p = positions[i as usize];
            [f64::from(p[0]) - p0[0], f64::from(p[1]) - p0[1], f64::from(p[2]) - p0[2]]
        };
        let mut n = [0.0f64; 3];
        let (mut lo, mut hi) = ([0.0f64; 3], [0.0f64; 3]);
        let mut magnitude = 0.0f32;
        let mut prev = at(poly[poly.len() - 1]);
        for &i in poly {
            let p = at(i);
            magnitude = positions[i as usize].iter().fold(magnitude, |m, c| m.max(c.abs()));
            n[0] += (prev[1] - p[1]) * (prev[2] + p[2]);
            n[1] += (prev[2] - p[2]) * (prev[0] + p[0]);
            n[2] += (prev[0] - p[0]) * (prev[1] + p[1]);
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
            prev = p;
        }
        let len = norm(n);
        let extent2 = (0..3).map(|a| (hi[a] - lo[a]) * (hi[a] - lo[a])).sum::<f64>();
        if !(len > 1e-9 * extent2 && len.is_finite()) {
            return false;
        }
        let n = n.map(|x| x / len);
        self.noise = 4.0 * f64::from(f32::EPSILON) * f64::from(magnitude);
        // e1: the axis least aligned with n, made orthogonal to it; e2 = n x e1.
        let k = (0..3).min_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs())).unwrap_or(0);
        let mut e1 = [0.0; 3];
        e1[k] = 1.0;
        let d = n[k];
        let e1 = normalize([e1[0] - d * n[0], e1[1] - d * n[1], e1[2] - d * n[2]]);
        let e2 = [n[1] * e1[2] - n[2] * e1[1], n[2] * e1[0] - n[0] * e1[2], n[0] * e1[1] - n[1] * e1[0]];
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        self.plane.clear();
        self.plane.extend(poly.iter().map(|&i| {
            let p = at(i);
            [dot(p, e1), dot(p, e2)]
        }));
        true
    }

    /// Whether the projected polygon is convex: no turn to the right, and the boundary goes
    /// round once (its direction's x and y components each change sign at most twice, which
    /// rules out a star polygon whose turns are all to the left). Straight and zero-length
    /// edges count as convex, and so do turns and directions within the rounding of the
    /// positions (a corner in the middle of a straight edge of an `f32` mesh).
    fn is_convex(&self) -> bool {
        let p = &self.plane;
        let n = p.len();
        let (mut x_changes, mut y_changes) = (0, 0);
        let (mut last_dx, mut last_dy) = (0.0f64, 0.0f64);
        // The first edge with a direction, to compare the last ones with it at the end.
        let (mut first_dx, mut first_dy) = (0.0f64, 0.0f64);
        let len = |a: [f64; 2], b: [f64; 2]| (b[0] - a[0]).hypot(b[1] - a[1]);
        let noise = self.noise;
        for i in 0..n {
            let (a, b, c) = (p[i], p[(i + 1) % n], p[(i + 2) % n]);
            // Moving a corner by `noise` changes the cross product by at most `noise` times
            // the lengths of the other two sides.
            if cross2(a, b, c) < -2.0 * noise * (len(a, b) + len(b, c) + len(a, c)) {
                return false;
            }
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let (dx, dy) =
                (if dx.abs() <= 2.0 * noise { 0.0 } else { dx }, if dy.abs() <= 2.0 * noise { 0.0 } else { dy });
            for (d, last, first, changes) in
                [(dx, &mut last_dx, &mut first_dx, &mut x_changes), (dy, &mut last_dy, &mut first_dy, &mut y_changes)]
            {
                if d != 0.0 {
                    if *last != 0.0 && (d > 0.0) != (*last > 0.0) {
                        *changes += 1;
                    }
                    if *first == 0.0 {
                        *first = d;
                    }
                    *last = d;
                }
            }
        }
        // Close the cycle: the change from the last direction back to the first.
        for (last, first, changes) in [(last_dx, first_dx, &mut x_changes), (last_dy, first_dy, &mut y_changes)] {
            if last != 0.0 && first != 0.0 && (last > 0.0) != (first > 0.0) {
                *changes += 1;
            }
        }
        x_changes <= 2 && y_changes <= 2
    }
}

/// Twice the signed area of the 2D triangle `(a, b, c)` (positive counter-clockwise).
fn cross2(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = norm(a);
    a.map(|x| x / l)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2D outline placed in a tilted plane away from the origin, as loader positions.
    fn place(outline: &[[f64; 2]]) -> Vec<[f32; 3]> {
        let (e1, e2) = ([0.6, 0.0, 0.8], [0.48, 0.6, -0.36]);
        outline.iter().map(|&[x, y]| std::array::from_fn(|a| (10.0 + x * e1[a] + y * e2[a]) as f32)).collect()
    }

    fn area2(p: &[[f64; 2]], t: [u32; 3]) -> f64 {
        cross2(p[t[0] as usize], p[t[1] as usize], p[t[2] as usize])
    }

    /// Twice the signed area of an outline.
    fn outline_area2(p: &[[f64; 2]]) -> f64 {
        (0..p.len()).map(|i| cross2([0.0, 0.0], p[i], p[(i + 1) % p.len()])).sum()
    }

    /// Even-odd point in polygon.
    fn inside(p: &[[f64; 2]], q: [f64; 2]) -> bool {
        let mut c = false;
        for i in 0..p.len() {
            let (a, b) = (p[i], p[(i + 1) % p.len()]);
            if (a[1] > q[1]) != (b[1] > q[1]) && q[0] < a[0] + (q[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) {
                c = !c;
            }
        }
        c
    }

    fn triangulate(outline: &[[f64; 2]]) -> Vec<[u32; 3]> {
        let positions = place(outline);
        let poly: Vec<u32> = (0..outline.len() as u32).collect();
        let mut out = vec![];
        Triangulator::default().polygon(&positions, &poly, &mut out);
        out
    }

    /// The triangles of a concave outline (counter-clockwise) cover it exactly, each inside
    /// it and counter-clockwise; reversed, every triangle is reversed.
    fn check_concave(outline: &[[f64; 2]]) {
        let a = outline_area2(outline);
        assert!(a > 0.0);
        let tris = triangulate(outline);
        assert_eq!(tris.len(), outline.len() - 2, "a simple polygon has n - 2 triangles");
        let sum: f64 = tris.iter().map(|&t| area2(outline, t)).sum();
        assert!((sum - a).abs() < 1e-9 * a, "area {sum} against {a}");
        for &t in &tris {
            // Zero area happens: a triangulation may join three corners in a line.
            let at = area2(outline, t);
            assert!(at > -1e-9, "triangle {t:?} is not counter-clockwise");
            if at < 1e-9 {
                continue;
            }
            let c = t
                .iter()
                .fold([0.0; 2], |c, &i| [c[0] + outline[i as usize][0] / 3.0, c[1] + outline[i as usize][1] / 3.0]);
            assert!(inside(outline, c), "triangle {t:?} lies outside");
        }
        let rev: Vec<[f64; 2]> = outline.iter().rev().copied().collect();
        let n = outline.len() as u32 - 1;
        for t in triangulate(&rev) {
            let back = t.map(|i| n - i);
            assert!(area2(outline, back) < 1e-9, "reversed outline, triangle {back:?} keeps its orientation");
        }
    }

    fn star(n: usize, inner: f64) -> Vec<[f64; 2]> {
        (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                let r = if i % 2 == 1 { inner } else { 1.0 };
                [r * a.cos(), r * a.sin()]
            })
            .collect()
    }

    #[test]
    fn concave_polygons_are_ear_clipped_inside_with_their_orientation() {
        let l_shape = [[0.0, 0.0], [3.0, 0.0], [3.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]];
        let arrow = [[0.0, 0.0], [2.0, 1.0], [4.0, 0.0], [2.0, 3.0]];
        // The L's reflex corner is its fourth: the fan from the first corner would cross
        // outside; here it does not.
        check_concave(&l_shape);
        check_concave(&arrow);
        let rotated: Vec<[f64; 2]> = (0..6).map(|k| l_shape[(k + 3) % 6]).collect();
        check_concave(&rotated);
        check_concave(&star(10, 0.4));
        // Above EAR_CLIP_CORNERS: the constrained Delaunay triangulation.
        check_concave(&star(2 * EAR_CLIP_CORNERS + 2, 0.5));
        check_concave(&star(2_000, 0.5));
    }

    #[test]
    fn convex_polygons_are_fanned() {
        for n in [4, 5, 6, 7, 50, 1000] {
            let outline: Vec<[f64; 2]> =
                (0..n).map(|i| i as f64 / n as f64 * std::f64::consts::TAU).map(|a| [a.cos(), a.sin() * 0.5]).collect();
            let positions = place(&outline);
            for poly in [(0..n as u32).collect::<Vec<_>>(), (0..n as u32).rev().collect()] {
                let mut out = vec![];
                Triangulator::default().polygon(&positions, &poly, &mut out);
                let mut fanned = vec![];
                fan(&poly, &mut fanned);
                assert_eq!(out, fanned, "{n} corners");
            }
        }
        // A square with a corner in the middle of an edge, and one repeated: still the fan.
        let positions = place(&[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [2.0, 2.0], [2.0, 2.0], [0.0, 2.0]]);
        let mut out = vec![];
        Triangulator::default().polygon(&positions, &[0, 1, 2, 3, 4, 5], &mut out);
        assert_eq!(out, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]]);
    }

    #[test]
    fn a_square_with_a_bridged_hole_covers_the_ring() {
        // Outer square counter-clockwise, a bridge in, the hole clockwise, the bridge back.
        for k in [4, 200] {
            let mut outline = vec![];
            for i in 0..k {
                outline.push([4.0 * i as f64 / k as f64, 0.0]);
            }
            outline.extend([[4.0, 0.0], [4.0, 4.0], [0.0, 4.0], [0.0, 2.0], [1.0, 2.0]]);
            for i in 0..k {
                outline.push([1.0, 2.0 + i as f64 / k as f64]);
            }
            outline.extend([[1.0, 3.0], [3.0, 3.0], [3.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]]);
            let tris = triangulate(&outline);
            let sum: f64 = tris.iter().map(|&t| area2(&outline, t)).sum();
            assert!((sum - 2.0 * 12.0).abs() < 1e-9, "{k}: area {}", sum / 2.0);
            assert!(tris.iter().all(|&t| area2(&outline, t) >= 0.0));
        }
    }

    #[test]
    fn degenerate_polygons_are_fanned_without_panic() {
        let mut t = Triangulator::default();
        let line = place(&[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [1.5, 0.0]]);
        let mut out = vec![];
        t.polygon(&line, &[0, 1, 2, 3, 4], &mut out);
        assert_eq!(out, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
        out.clear();
        t.polygon(&line, &[2, 2, 2, 2], &mut out);
        assert_eq!(out, vec![[2, 2, 2]; 2]);
        let mut bad = place(&[[0.0, 0.0], [2.0, 0.0], [1.0, 1.0], [2.0, 2.0], [0.0, 2.0]]);
        bad[1][0] = f32::NAN;
        out.clear();
        t.polygon(&bad, &[0, 1, 2, 3, 4], &mut out);
        assert_eq!(out.len(), 3);
        out.clear();
        t.polygon(&bad, &[0, 7, 2, 3], &mut out);
        assert_eq!(out, vec![[0, 7, 2], [0, 2, 3]], "an index out of range is fanned (the loader reports it)");
        out.clear();
        t.polygon(&line, &[0, 1], &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn self_intersecting_polygons_do_not_panic() {
        // A pentagram (every turn to the left, going round twice) and a large bow tie.
        let pentagram: Vec<[f64; 2]> =
            (0..5).map(|i| i as f64 * 2.0 / 5.0 * std::f64::consts::TAU).map(|a| [a.cos(), a.sin()]).collect();
        assert!(!triangulate(&pentagram).is_empty());
        let mut bow: Vec<[f64; 2]> = (0..400).map(|i| [i as f64 / 400.0, 0.0]).collect();
        bow.extend((0..400).map(|i| [1.0 - i as f64 / 400.0, 1.0 - i as f64 / 400.0 * 0.5]));
        bow.extend([[0.5, -1.0], [0.0, 1.0]]);
        let _ = triangulate(&bow);
        // A bow tie (a twisted quad in its plane) has no triangulation: it is fanned, as before.
        assert_eq!(triangulate(&[[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]), vec![[0, 1, 2], [0, 2, 3]]);
    }
}
