//! The quantizers of the `.dpm` file: positions on a grid over the bounding box, normals in
//! the octahedral code, and the refinement criteria (`sin(alpha)` in 8 bits, lengths and the
//! attribute error log-coded at 2%, section 4.2.3); the grid a mesh gets (`fit_header`), and
//! [`quantized`], a mesh as the decoder gives it back.
//!
//! Every quantizer rounds so that what the runtime reads is safe: criteria are rounded up
//! (a cone, an error or a radius never shrinks), positions and normals to the nearest code.

use super::header::{max_q, Header, MAX_OP_FACES};
use super::{EncodeError, EncodeOptions};
use crate::progressive::{Criteria, ProgressiveMesh};

/// The largest log code (also the code of NaN); codes above are corrupt.
pub const MAX_K: u32 = 1 << 20;
/// Log-code steps per doubling: a step is `2^(1/35)` = 1.0200016 (the paper's 2%, made a whole
/// fraction of an octave so that decoding needs no `exp`).
pub const LOG_STEPS: u32 = 35;
const LN_STEP: f64 = std::f64::consts::LN_2 / LOG_STEPS as f64;
/// `2^(j/35)` for `j` in `0..35`, as `f32` bit patterns: the one table that log codes decode
/// through. It is part of the format (not computed at run time), so every decoder, the WGSL
/// one included, reads the same values.
const OCTAVE: [u32; LOG_STEPS as usize] = [
    0x3f800000, 0x3f828f6a, 0x3f852bef, 0x3f87d5d4, 0x3f8a8d5c, 0x3f8d52ce, 0x3f902671, 0x3f93088c, 0x3f95f96b,
    0x3f98f959, 0x3f9c08a4, 0x3f9f2799, 0x3fa25689, 0x3fa595c6, 0x3fa8e5a3, 0x3fac4675, 0x3fafb894, 0x3fb33c57,
    0x3fb6d21a, 0x3fba7a38, 0x3fbe3510, 0x3fc20300, 0x3fc5e46c, 0x3fc9d9b6, 0x3fcde345, 0x3fd2017f, 0x3fd634d0,
    0x3fda7da4, 0x3fdedc67, 0x3fe3518b, 0x3fe7dd82, 0x3fec80c0, 0x3ff13bbf, 0x3ff60ef5, 0x3ffafae1,
];

/// The log code of a length or error `e >= 0` with lower bound `q` (section 4.2.3, relative
/// accuracy 2%): 0 for 0, 1 up to `q`, else one plus `ceil(log2(e / q) * 35)`, moved to the
/// smallest code whose decoded value ([`log_dec`]) is at least `e`, so the decoded value is
/// never below `e` and at most one step above it.
pub(super) fn log_enc(e: f32, q: f32) -> u32 {
    if e.is_nan() {
        return MAX_K;
    }
    if e <= 0.0 {
        return 0;
    }
    if e <= q {
        return 1;
    }
    let k = ((e as f64).ln() - (q as f64).ln()) / LN_STEP;
    let mut k = (k.ceil().clamp(0.0, MAX_K as f64) as u32 + 1).min(MAX_K);
    // Exactly the smallest code whose value is not below `e`.
    while k < MAX_K && log_dec(k, q) < e {
        k += 1;
    }
    while k > 2 && log_dec(k - 1, q) >= e {
        k -= 1;
    }
    k
}

/// The per-file table of log code values within an octave: `q * 2^(j/35)` for `j` in
/// `0..35`, each one correctly rounded `f32` product (what the WGSL decoder uploads).
pub fn log_table(q: f32) -> [f32; LOG_STEPS as usize] {
    OCTAVE.map(|b| q * f32::from_bits(b))
}

/// The value of log code `k` from a [`log_table`]: 0 for 0, else `t[(k-1) % 35]` times
/// `2^((k-1) / 35)`, the power of two added to the exponent bits, an integer step (so every
/// decoder agrees bit for bit); [`f32::MAX`] where the exponent would leave the range (never
/// below the coded value, and finite for a GPU, which may assume no infinities).
pub fn log_value(k: u32, t: &[f32; LOG_STEPS as usize]) -> f32 {
    if k == 0 {
        return 0.0;
    }
    times_power_of_two(t[((k - 1) % LOG_STEPS) as usize], (k - 1) / LOG_STEPS)
}

/// `x * 2^e` by adding `e` to the exponent bits of `x`, a normal `f32` ([`f32::MAX`] past the
/// range). The header keeps the lower bounds normal and below 2^64 and the octave factors are
/// in [1, 2), so a table entry is normal: its exponent field is 1 to 254.
fn times_power_of_two(x: f32, e: u32) -> f32 {
    let bits = x.to_bits();
    if ((bits >> 23) & 0xff) + e >= 0xff {
        return f32::MAX;
    }
    f32::from_bits(bits + (e << 23))
}

/// The value of log code `k` for the lower bound `q` (one entry of [`log_table`]).
pub(super) fn log_dec(k: u32, q: f32) -> f32 {
    if k == 0 {
        return 0.0;
    }
    times_power_of_two(q * f32::from_bits(OCTAVE[((k - 1) % LOG_STEPS) as usize]), (k - 1) / LOG_STEPS)
}

/// `sin(alpha)` in 8 bits (section 4.2.3), rounded up: `k / 255` is at least `s` and less
/// than `1/255` above it, and `sin_enc(k / 255) == k`.
pub(super) fn sin_enc(s: f32) -> u32 {
    if s.is_nan() {
        return 255;
    }
    (s.clamp(0.0, 1.0) * 255.0).ceil() as u32
}

/// The codes of a split's criteria: `sin(alpha)`, geometric error, attribute error, radius.
pub(super) fn quantize_criteria(c: &Criteria, h: &Header) -> [u32; 4] {
    [
        sin_enc(c.sin_alpha),
        log_enc(c.geometric_error, h.length_step),
        log_enc(c.attribute_error, h.attribute_step),
        log_enc(c.radius, h.length_step),
    ]
}

/// The criteria the runtime reads for codes `k`, each at least the value that was coded.
pub(super) fn dequantize_criteria(k: [u32; 4], h: &Header) -> Criteria {
    Criteria {
        sin_alpha: k[0] as f32 / 255.0,
        geometric_error: log_dec(k[1], h.length_step),
        attribute_error: log_dec(k[2], h.attribute_step),
        radius: log_dec(k[3], h.length_step),
    }
}

/// The nearest point of the grid `bbox_min + q * step`, clamped to it (NaN to 0). A
/// coordinate in the box comes back within half a step, plus the `f32` rounding of the
/// coordinates; quantizing a dequantized position gives its code back while the step is
/// coarser than that rounding (on the bunny up to 20 bits; at 24 the grid is finer than an
/// `f32` near the bunny's coordinates, 1.6 steps off were measured, and it is not).
pub(super) fn quantize_position(p: [f32; 3], h: &Header) -> [u32; 3] {
    let m = max_q(h.position_bits) as f32;
    std::array::from_fn(|i| {
        let x = ((p[i] - h.bbox_min[i]) / h.step).round();
        if x.is_nan() {
            0
        } else {
            x.clamp(0.0, m) as u32
        }
    })
}

/// The grid point of code `q`.
pub(super) fn dequantize_position(q: [u32; 3], h: &Header) -> [f32; 3] {
    std::array::from_fn(|i| h.bbox_min[i] + q[i] as f32 * h.step)
}

/// Octahedral normal coding, `bits` per coordinate (`m = 2^bits - 1` steps over `[-1, 1]`);
/// `[2^bits, 2^bits]` stands for the zero normal (and for anything not finite). A unit normal
/// comes back (`oct_decode`) as a unit normal within a chord of `4.23 / m` (the most measured
/// over 10^5 random normals at every width from 4 to 16 bits). Quantizing a decoded normal
/// gives the same normal up to `f32` rounding; on the seams of the lower half (`x` or `y`
/// zero, `z < 0`) two codes stand for one normal and the code may change to the other.
pub(super) fn oct_encode(n: [f32; 3], bits: u8) -> [u32; 2] {
    let zero = 1u32 << bits;
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    if !(l1 > 1e-20 && l1.is_finite()) {
        return [zero, zero];
    }
    let (mut x, mut y) = (n[0] / l1, n[1] / l1);
    if n[2] < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * if ox >= 0.0 { 1.0 } else { -1.0 };
        y = (1.0 - ox.abs()) * if oy >= 0.0 { 1.0 } else { -1.0 };
    }
    let m = max_q(bits) as f32;
    [x, y].map(|c| (((c + 1.0) * 0.5 * m).round()).clamp(0.0, m) as u32)
}

/// The unit normal of an octahedral code, or zero for the zero code.
pub(super) fn oct_decode(q: [u32; 2], bits: u8) -> [f32; 3] {
    let zero = 1u32 << bits;
    if q == [zero, zero] {
        return [0.0; 3];
    }
    let m = max_q(bits) as f32;
    let (mut x, mut y) = (q[0] as f32 / m * 2.0 - 1.0, q[1] as f32 / m * 2.0 - 1.0);
    let z = 1.0 - x.abs() - y.abs();
    if z < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * if ox >= 0.0 { 1.0 } else { -1.0 };
        y = (1.0 - ox.abs()) * if oy >= 0.0 { 1.0 } else { -1.0 };
    }
    let l = (x * x + y * y + z * z).sqrt();
    [x / l, y / l, z / l]
}

/// Whether `q` is a code [`oct_encode`] can produce.
pub(super) fn valid_oct(q: [u32; 2], bits: u8) -> bool {
    let zero = 1u32 << bits;
    q == [zero, zero] || (q[0] < zero && q[1] < zero)
}

/// The header's quantization for a mesh: the position grid over its bounding box, `step` the
/// largest extent over `2^position_bits - 1` (1 for a flat or empty mesh), lengths coded from
/// a quarter step, the attribute error from `1/4096`; the average operation size is left to
/// the encoder.
pub(super) fn fit_header(pm: &ProgressiveMesh, opts: EncodeOptions) -> Result<Header, EncodeError> {
    if !(8..=24).contains(&opts.position_bits) || !(4..=16).contains(&opts.normal_bits) {
        return Err(EncodeError::InvalidOptions("position bits must be 8 to 24, normal bits 4 to 16".into()));
    }
    if pm.positions.iter().flatten().any(|c| !c.is_finite()) {
        return Err(EncodeError::InvalidMesh("non-finite position".into()));
    }
    let (lo, hi) = crate::mesh::bounding_box(&pm.positions).unwrap_or(([0.0; 3], [0.0; 3]));
    let extent = (0..3).map(|i| hi[i] - lo[i]).fold(0f32, f32::max);
    let mut step = extent / max_q(opts.position_bits) as f32;
    if !(step > 0.0 && step.is_finite()) {
        step = 1.0;
    }
    let n = pm.positions.len();
    Ok(Header {
        // Below 2^31, so that a face corner's zigzag offset fits in 32 bits.
        vertices: u32::try_from(n)
            .ok()
            .filter(|&n| n < 1 << 31)
            .ok_or_else(|| EncodeError::InvalidMesh("2^31 vertices or more".into()))?,
        base_vertices: pm.base_vertices.len() as u32,
        base_faces: pm.base_faces.len() as u32,
        splits: pm.splits.len() as u32,
        position_bits: opts.position_bits,
        normal_bits: opts.normal_bits,
        bbox_min: lo,
        step,
        length_step: step * 0.25,
        attribute_step: 1.0 / 4096.0,
        avg_op_size: 0,
        triangles: (pm.base_faces.len() + pm.splits.iter().map(|s| s.faces.len()).sum::<usize>()) as u32,
        max_faces: {
            let most = pm.splits.iter().map(|s| s.faces.len()).max().unwrap_or(0);
            if most > MAX_OP_FACES as usize {
                return Err(EncodeError::InvalidMesh(format!(
                    "a split adds {most} faces, more than the format's {MAX_OP_FACES}"
                )));
            }
            most as u32
        },
        nodes: 0,
    })
}

/// `pm` as the decoder gives it back: positions quantized, normals through the octahedral
/// code, criteria quantized (splits and their order unchanged).
pub fn quantized(pm: &ProgressiveMesh, opts: EncodeOptions) -> Result<ProgressiveMesh, EncodeError> {
    let h = fit_header(pm, opts)?;
    let mut q = pm.clone();
    q.positions = pm.positions.iter().map(|&p| dequantize_position(quantize_position(p, &h), &h)).collect();
    q.normals = pm.normals.iter().map(|&n| oct_decode(oct_encode(n, h.normal_bits), h.normal_bits)).collect();
    q.criteria = pm.criteria.iter().map(|c| dequantize_criteria(quantize_criteria(c, &h), &h)).collect();
    Ok(q)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// xorshift64*, enough for sampling.
    struct Rng(u64);

    impl Rng {
        /// Uniform in `[0, 1)`.
        fn unit(&mut self) -> f32 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32 / (1u64 << 24) as f32
        }

        fn unit_normal(&mut self) -> [f32; 3] {
            loop {
                let v: [f32; 3] = std::array::from_fn(|_| self.unit() * 2.0 - 1.0);
                let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                if l > 0.1 && l <= 1.0 {
                    return v.map(|x| x / l);
                }
            }
        }
    }

    /// The bunny's bounding box (`stanford/bunny_zipper_c3d.obj.gz`).
    const BUNNY_MIN: [f32; 3] = [-0.094_69, 0.032_987, -0.061_874];
    const BUNNY_MAX: [f32; 3] = [0.061_009_8, 0.187_321, 0.058_800_4];

    fn bunny_header(position_bits: u8) -> Header {
        let pm = ProgressiveMesh { positions: vec![BUNNY_MIN, BUNNY_MAX], ..Default::default() };
        fit_header(&pm, EncodeOptions { position_bits, normal_bits: 10, node_bytes: 0 }).expect("valid options")
    }

    fn in_bunny_box(rng: &mut Rng) -> [f32; 3] {
        std::array::from_fn(|i| BUNNY_MIN[i] + rng.unit() * (BUNNY_MAX[i] - BUNNY_MIN[i]))
    }

    fn chord(a: [f32; 3], b: [f32; 3]) -> f32 {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    }

    #[test]
    fn positions_come_back_within_half_a_step() {
        let mut rng = Rng(1);
        for bits in [8, 12, 16, 20, 24] {
            let h = bunny_header(bits);
            assert_eq!(quantize_position(BUNNY_MIN, &h), [0; 3]);
            for _ in 0..20_000 {
                let p = in_bunny_box(&mut rng);
                let d = dequantize_position(quantize_position(p, &h), &h);
                for i in 0..3 {
                    let rounding = 2.0 * f32::EPSILON * (p[i].abs() + h.bbox_min[i].abs());
                    assert!((d[i] - p[i]).abs() <= 0.5 * h.step + rounding, "{bits} bits: {p:?} came back as {d:?}");
                }
            }
        }
    }

    #[test]
    fn quantized_positions_are_fixed_points() {
        let mut rng = Rng(2);
        for bits in [8, 12, 16, 20] {
            let h = bunny_header(bits);
            for _ in 0..20_000 {
                let q = quantize_position(in_bunny_box(&mut rng), &h);
                assert_eq!(quantize_position(dequantize_position(q, &h), &h), q, "{bits} bits");
            }
            let top = [max_q(bits); 3];
            assert_eq!(quantize_position(dequantize_position(top, &h), &h), top);
            // Outside the box: clamped to the grid.
            assert_eq!(quantize_position(BUNNY_MAX.map(|x| x + 1.0), &h), top);
            assert_eq!(quantize_position(BUNNY_MIN.map(|x| x - 1.0), &h), [0; 3]);
        }
    }

    #[test]
    fn normals_come_back_within_the_octahedral_bound() {
        let mut rng = Rng(3);
        let axes =
            [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
        for bits in 4..=16 {
            let m = max_q(bits) as f32;
            for n in axes.into_iter().chain((0..20_000).map(|_| rng.unit_normal())) {
                let c = oct_encode(n, bits);
                assert!(valid_oct(c, bits) && c[0] < 1 << bits, "{bits} bits: {n:?} codes as {c:?}");
                let d = oct_decode(c, bits);
                assert!((chord(d, [0.0; 3]) - 1.0).abs() < 1e-6, "not a unit normal: {d:?}");
                assert!(chord(d, n) <= 4.5 / m, "{bits} bits: {n:?} came back as {d:?}");
            }
        }
    }

    #[test]
    fn quantized_normals_are_fixed_points() {
        let mut rng = Rng(4);
        for bits in 4..=16 {
            for _ in 0..20_000 {
                let d = oct_decode(oct_encode(rng.unit_normal(), bits), bits);
                let again = oct_decode(oct_encode(d, bits), bits);
                assert!(chord(again, d) <= 4.0 * f32::EPSILON, "{bits} bits: {d:?} came back as {again:?}");
            }
            let zero = 1 << bits;
            for n in [[0.0; 3], [f32::NAN, 0.0, 1.0], [f32::INFINITY, 0.0, 0.0]] {
                assert_eq!(oct_encode(n, bits), [zero, zero]);
            }
            assert_eq!(oct_decode([zero, zero], bits), [0.0; 3]);
            assert!(!valid_oct([zero, 0], bits));
        }
    }

    #[test]
    fn log_coded_criteria_round_up_by_at_most_two_percent() {
        let h = bunny_header(16);
        let mut rng = Rng(5);
        for q in [h.length_step, h.attribute_step] {
            assert_eq!(log_enc(0.0, q), 0);
            assert_eq!(log_dec(0, q), 0.0);
            assert_eq!(log_enc(f32::NAN, q), MAX_K);
            assert_eq!(log_dec(log_enc(q * 0.5, q), q), q);
            for _ in 0..20_000 {
                // From a tenth of q to 10^5 q.
                let e = q * 10f32.powf(rng.unit() * 6.0 - 1.0);
                let d = log_dec(log_enc(e, q), q);
                assert!(d >= e && d <= (e * 2f32.powf(1.0 / 35.0) * (1.0 + 1e-6)).max(q), "{e} came back as {d}");
            }
        }
    }

    #[test]
    fn log_codes_come_back_as_themselves() {
        let h = bunny_header(16);
        for q in [h.length_step, h.attribute_step, f32::MIN_POSITIVE, 1.5e19] {
            let t = log_table(q);
            let mut prev = 0.0;
            for k in (0..40_000).chain(MAX_K - 10..=MAX_K) {
                let e = log_dec(k, q);
                assert_eq!(e.to_bits(), log_value(k, &t).to_bits());
                assert!(e.is_finite() && (k == 0 || e > prev || e == f32::MAX), "code {k}: {e} after {prev}");
                if e < f32::MAX {
                    assert_eq!(log_enc(e, q), k, "code {k} ({e}) came back as another");
                }
                prev = e;
            }
        }
        // Whole octaves are exact powers of two.
        assert_eq!(log_dec(1 + 35 * 3, 0.25), 2.0);
    }

    #[test]
    fn sin_alpha_rounds_up_to_a_255th() {
        let mut rng = Rng(6);
        for s in [0.0, 1.0].into_iter().chain((0..20_000).map(|_| rng.unit())) {
            let d = sin_enc(s) as f32 / 255.0;
            assert!(d >= s && d - s < 1.0 / 255.0 + f32::EPSILON, "{s} came back as {d}");
        }
        for k in 0..=255 {
            assert_eq!(sin_enc(k as f32 / 255.0), k);
        }
        assert_eq!(sin_enc(2.0), 255);
        assert_eq!(sin_enc(-1.0), 0);
    }

    #[test]
    fn criteria_never_come_back_smaller() {
        let h = bunny_header(16);
        let mut rng = Rng(7);
        for _ in 0..20_000 {
            let c = Criteria {
                sin_alpha: rng.unit(),
                geometric_error: rng.unit() * 0.01,
                attribute_error: rng.unit() * 2.0,
                radius: rng.unit() * 0.1,
            };
            let k = quantize_criteria(&c, &h);
            let d = dequantize_criteria(k, &h);
            assert!(d.sin_alpha >= c.sin_alpha && d.geometric_error >= c.geometric_error);
            assert!(d.attribute_error >= c.attribute_error && d.radius >= c.radius, "{c:?} came back as {d:?}");
            assert_eq!(quantize_criteria(&d, &h), k);
        }
    }
}
