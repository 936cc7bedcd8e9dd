//! The fields of an operation and their contexts: per field its kind (for the size breakdown
//! of [`DpmStats`](super::DpmStats)), its number of classes and how its values become symbols,
//! where its tables start among the shared ones, and the functions that choose a class or a
//! prediction from what the decoder already has (the operation's context and the fields read
//! before). Encoder and decoder both call these, so a context is computed one way only; the
//! order in which the fields are coded is in the format's documentation ([`super`]) and `op.rs`.

/// The fields of an operation, for the size breakdown in [`DpmStats`](super::DpmStats).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(usize)]
pub(super) enum Kind {
    Sin,
    GeomError,
    AttrError,
    Radius,
    Head,
    Split,
    FaceCount,
    FaceForm,
    FaceT,
    FaceU,
    FaceOther,
    FaceOtherDelta,
    FaceGeneral,
    Position,
    Normal,
    Pointer,
}

pub(super) const KINDS: usize = 16;

/// How a field's values become byte symbols.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Scheme {
    /// 7-bit groups, least significant first, with a continuation bit; the group's
    /// significance (0, 1, 2+) selects one of three tables (the paper's contexts by byte
    /// significance).
    Groups,
    /// One symbol per value: the value itself below 16, else its bit length and the three bits
    /// below the leading one, followed by the remaining low bits uncoded (as DEFLATE codes
    /// lengths and distances). One table per class; suits wide values whose low bits are
    /// noise.
    Buckets,
}

/// A coded field: its kind for the breakdown, its number of classes (a context chosen from
/// what the decoder already knows, each with its own tables) and its scheme.
#[derive(Clone, Copy, Debug)]
pub(super) struct Field {
    pub(super) kind: Kind,
    pub(super) classes: usize,
    pub(super) scheme: Scheme,
}

const fn field(kind: Kind, classes: usize, scheme: Scheme) -> Field {
    Field { kind, classes, scheme }
}

/// Classes of the region size contexts (see [`region_class`]).
const REGION_CLASSES: usize = 3;

/// The class of an operation by the number of finest vertices its vertex stands for
/// (`v_end - v`, at least 2): its bit length less 2, capped.
pub(super) fn region_class(v: u32, v_end: u32) -> usize {
    let n = v_end.saturating_sub(v).max(2);
    ((32 - n.leading_zeros()) as usize - 2).min(REGION_CLASSES - 1)
}

/// Classes of the split point's contexts (see [`split_class`]).
const SPLIT_CLASSES: usize = 6;

/// The class of the split point of a range of `n` FVIDs (more than 4): its bit length less
/// 3, capped.
pub(super) fn split_class(n: u32) -> usize {
    ((32 - n.leading_zeros()) as usize - 3).min(SPLIT_CLASSES - 1)
}

/// Classes of the magnitude contexts (see [`magnitude_class`]).
const MAGNITUDES: usize = 28;

// The fields, in table order.
pub(super) const SIN: usize = 0;
pub(super) const GEOM: usize = 1;
pub(super) const ATTR: usize = 2;
pub(super) const RADIUS: usize = 3;
pub(super) const HEAD: usize = 4;
pub(super) const SPLIT: usize = 5;
pub(super) const FACE_COUNT: usize = 6;
pub(super) const FACE_FORM: usize = 7;
pub(super) const FACE_T: usize = 8;
pub(super) const FACE_U: usize = 9;
pub(super) const FACE_OTHER: usize = 10;
pub(super) const FACE_OTHER_DELTA: usize = 11;
pub(super) const FACE_GENERAL: usize = 12;
pub(super) const POS_TANGENT: usize = 13;
pub(super) const POS_NORMAL: usize = 14;
pub(super) const NORMAL: usize = 15;
pub(super) const POINTER: usize = 16;
pub(super) const NODE_DELTA: usize = 17;
pub(super) const LOCAL: usize = 18;
pub(super) const FIELDS: [Field; 19] = [
    field(Kind::Sin, 4, Scheme::Groups),
    field(Kind::GeomError, 1, Scheme::Groups),
    field(Kind::AttrError, 1, Scheme::Groups),
    field(Kind::Radius, 1, Scheme::Groups),
    field(Kind::Head, 4, Scheme::Groups),
    field(Kind::Split, SPLIT_CLASSES, Scheme::Groups),
    field(Kind::FaceCount, 1, Scheme::Groups),
    field(Kind::FaceForm, 1, Scheme::Groups),
    field(Kind::FaceT, 7, Scheme::Groups),
    field(Kind::FaceU, 7, Scheme::Groups),
    field(Kind::FaceOther, REGION_CLASSES, Scheme::Buckets),
    field(Kind::FaceOtherDelta, REGION_CLASSES, Scheme::Buckets),
    field(Kind::FaceGeneral, 1, Scheme::Groups),
    field(Kind::Position, MAGNITUDES, Scheme::Buckets),
    field(Kind::Position, MAGNITUDES, Scheme::Buckets),
    field(Kind::Normal, MAGNITUDES, Scheme::Buckets),
    field(Kind::Pointer, SPLIT_CLASSES, Scheme::Groups),
    // Out-of-core files only: per child that splits, its node's distance (class: the child
    // stored first or second) and, in another node, its local address.
    field(Kind::Pointer, 2, Scheme::Groups),
    field(Kind::Pointer, 1, Scheme::Buckets),
];

pub(super) const fn tables_per_class(s: Scheme) -> usize {
    match s {
        Scheme::Groups => 3,
        Scheme::Buckets => 1,
    }
}

/// Per field, the index of its first table; the last entry is the number of tables. The fields
/// in order: `sin(alpha)`, geometric error, attribute error, radius, head, split point, face
/// count, face form, face corner in `v_l`'s range, in `v_u`'s, third corner, its difference,
/// general corner, tangential position, normal position, normal, pointer, and (out of core)
/// node distance and local address. A field's class `c`
/// starts at its base plus `c` (buckets) or `3 c` (groups: significance 0, 1, 2 and more).
pub const TABLE_BASE: [usize; FIELDS.len() + 1] = {
    let mut b = [0; FIELDS.len() + 1];
    let mut i = 0;
    while i < FIELDS.len() {
        b[i + 1] = b[i] + FIELDS[i].classes * tables_per_class(FIELDS[i].scheme);
        i += 1;
    }
    b
};
/// The number of probability tables of a file.
pub const TABLES: usize = TABLE_BASE[FIELDS.len()];

/// The magnitude class of a log-coded length or attribute error `k` (section 4.2.3): 0 for
/// zero, then one class per doubling (35 steps of 2%), capped.
pub(super) fn magnitude_class(k: u32) -> usize {
    if k == 0 {
        0
    } else {
        (1 + (k as usize - 1) / 35).min(MAGNITUDES - 1)
    }
}

/// The prediction of criterion `i`: the parent's value, except for the radius, which is at
/// most both the parent's radius and this operation's geometric error (the error is the
/// region's farthest vertex raised to its neighbours' errors) and is predicted by the
/// smaller of the two.
pub(super) fn criteria_prediction(parent: &[u32; 4], this: &[u32; 4], i: usize) -> i64 {
    if i == 3 {
        parent[3].min(this[1]) as i64
    } else {
        parent[i] as i64
    }
}

/// The class of the head symbol: the size of `v`'s FVID range, 2, 3, 4 or more (a range of 2
/// has two leaves as children, one of 3 one leaf and one split).
pub(super) fn head_class(v: u32, v_end: u32) -> usize {
    (v_end.saturating_sub(v).clamp(2, 5) - 2) as usize
}

/// The class of `sin(alpha)`'s residual: the parent's value in quarters of its range (a wide
/// parent cone often has an equally wide child cone).
pub(super) fn sin_class(parent: &[u32; 4]) -> usize {
    (parent[0] >> 6).min(3) as usize
}

/// The class of a face corner's offset inside `v_l`'s or `v_u`'s FVID range (of `range` FVIDs,
/// at least 2; the corner of a range of 1 is not coded): for the first standard face 0 to 3 by
/// the range's bit length, else 4 to 6 by the previous face's offset (0, 1, more), as the two
/// faces of an edge often share a corner.
pub(super) fn corner_class(prev: Option<u64>, range: u32) -> usize {
    match prev {
        None => ((32 - range.leading_zeros()) as usize - 2).min(3),
        Some(p) => 4 + p.min(2) as usize,
    }
}

/// The estimate of the address offset of the child stored second, from the average operation
/// size: `s_avg * (m - 1)` for `m` the FVID count of the child stored first (section 4.2.1,
/// where that child is always `v_l`: `s_avg * (v_u - v - 1)`). `s_avg` is in 16.16 fixed
/// point (the header's `avg_op_size`); the product is rounded to the
/// nearest byte (halves up) and capped at `u32::MAX`, integer arithmetic every decoder repeats
/// exactly (the WGSL one with 32-bit halves).
pub(super) fn pointer_estimate(avg: u32, first_size: u32) -> i64 {
    let p = avg as u64 * first_size.saturating_sub(1) as u64 + (1 << 15);
    (p >> 16).min(u32::MAX as u64) as i64
}

/// The octahedral code of a normal as an integer vector along the normal (not unit length):
/// with `m = 2^bits - 1`, `x = 2 q_0 - m`, `y = 2 q_1 - m` and `z = m - |x| - |y|`, folded
/// where `z < 0` as the octahedral decoder folds; zero for the zero code. Its
/// components are within `m` in magnitude; integers, so the prediction below is the same in
/// every decoder.
pub(super) fn oct_vector(q: [u32; 2], bits: u8) -> [i32; 3] {
    let zero = 1u32 << bits;
    if q == [zero, zero] {
        return [0; 3];
    }
    let m = ((1u32 << bits) - 1) as i32;
    let (x, y) = (2 * q[0] as i32 - m, 2 * q[1] as i32 - m);
    let z = m - x.abs() - y.abs();
    if z >= 0 {
        return [x, y, z];
    }
    let sign = |c: i32| if c >= 0 { 1 } else { -1 };
    [(m - y.abs()) * sign(x), (m - x.abs()) * sign(y), z]
}

/// Bits a normal component keeps for the tangent-plane prediction (sign included, 12): with
/// tangential deltas below [`TANGENT_LIMIT`] the prediction's products and sum stay below
/// 2^30, in 32-bit integers.
const TANGENT_NORMAL_BITS: u8 = 11;
/// Tangential deltas at or beyond this (in grid steps) are not predicted (prediction 0).
pub(super) const TANGENT_LIMIT: i64 = 1 << 18;

/// The coding frame of a position delta: the axes in coding order, the two least aligned with
/// `v`'s normal first, and the normal's components along them ([`oct_vector`], shifted right
/// to at most 11 bits of magnitude). The last axis is predicted from the first two by the
/// tangent plane (section 4.2.4 predicts `v_u` from `v`; the normal of `v` is known to the
/// decoder, so the delta is predicted to lie in `v`'s tangent plane).
pub(super) fn position_frame(normal: [u32; 2], bits: u8) -> ([usize; 3], [i32; 3]) {
    let n = oct_vector(normal, bits);
    let mut a = 0;
    for i in 1..3 {
        if n[i].abs() > n[a].abs() {
            a = i;
        }
    }
    let axes = match a {
        0 => [1, 2, 0],
        1 => [0, 2, 1],
        _ => [0, 1, 2],
    };
    let shift = bits.saturating_sub(TANGENT_NORMAL_BITS);
    (axes, axes.map(|i| n[i] >> shift))
}

/// The tangent-plane prediction of the last axis from the first two,
/// `-(n_a d_a + n_b d_b) / n_c` rounded to the nearest integer (halves away from zero), in
/// integers: 0 where `n_c` is 0 or a tangential delta is [`TANGENT_LIMIT`] or more.
pub(super) fn tangent_prediction(n: [i32; 3], d0: i64, d1: i64) -> i64 {
    if n[2] == 0 || d0.abs() >= TANGENT_LIMIT || d1.abs() >= TANGENT_LIMIT {
        return 0;
    }
    // |n| < 2^11 and |d| < 2^18: the sum is below 2^30 in magnitude.
    let num = -(n[0] as i64 * d0 + n[1] as i64 * d1);
    let den = n[2] as i64;
    let q = (num.abs() + den.abs() / 2) / den.abs();
    if (num < 0) != (den < 0) {
        -q
    } else {
        q
    }
}

/// The class of the last axis's residual: the bit length of the tangential delta.
pub(super) fn tangent_class(d0: i64, d1: i64) -> usize {
    let m = d0.unsigned_abs() + d1.unsigned_abs();
    ((64 - m.leading_zeros()) as usize).min(MAGNITUDES - 1)
}

#[cfg(test)]
mod tests {
    use super::super::quantize::oct_decode;
    use super::*;

    #[test]
    fn the_integer_octahedral_vector_points_along_the_decoded_normal() {
        for bits in [4u8, 7, 10] {
            let zero = 1u32 << bits;
            assert_eq!(oct_vector([zero, zero], bits), [0; 3]);
            for a in 0..zero {
                for b in 0..zero {
                    let v = oct_vector([a, b], bits);
                    let m = ((1u32 << bits) - 1) as i32;
                    assert!(v.iter().all(|c| c.abs() <= m) && v[0].abs() + v[1].abs() + v[2].abs() == m);
                    let l = v.iter().map(|&c| (c as f64).powi(2)).sum::<f64>().sqrt();
                    let n = oct_decode([a, b], bits);
                    for i in 0..3 {
                        assert!((v[i] as f64 / l - n[i] as f64).abs() < 1e-6, "{bits} bits, code {a},{b}: {v:?} {n:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn the_tangent_prediction_is_the_rounded_quotient() {
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = |m: i64| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x % (2 * m as u64 + 1)) as i64 - m
        };
        for _ in 0..100_000 {
            let n = [next(2047) as i32, next(2047) as i32, next(2047) as i32];
            let (d0, d1) = (next(TANGENT_LIMIT - 1), next(TANGENT_LIMIT - 1));
            let p = tangent_prediction(n, d0, d1);
            if n[2] == 0 {
                assert_eq!(p, 0);
                continue;
            }
            // Exact: |p - num/den| <= 1/2, halves away from zero.
            let (num, den) = (-(n[0] as i64 * d0 + n[1] as i64 * d1), n[2] as i64);
            let twice = 2 * (p * den - num).abs();
            assert!(twice < den.abs() || (twice == den.abs() && p.signum() * den.signum() * num.signum() >= 0));
        }
        assert_eq!(tangent_prediction([1, 1, 1], TANGENT_LIMIT, 0), 0);
        assert_eq!(tangent_prediction([1, 1, 2], 1, 0), -1);
        assert_eq!(tangent_prediction([1, 1, 2], -1, 0), 1);
        assert_eq!(pointer_estimate(3 << 15, 5), 6);
        assert_eq!(pointer_estimate(u32::MAX, u32::MAX), u32::MAX as i64);
        assert_eq!(pointer_estimate(1 << 16, 0), 0);
    }
}
