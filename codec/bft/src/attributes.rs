//! Per-vertex colours and normals of a `.bft` stream (sections `COLR` and `NORM`, version 4).
//!
//! Attributes are coded after a stream's connectivity and positions, one value per slot in
//! slot order, so that every prediction may use the whole decoded connectivity and every
//! position. The encoder, the decoder and the tile writer share `encode_colors`, `encode_normals` and their decoders:
//! a tile's attributes are re-coded from the model's decoded values over the tile's own
//! triangles, exactly as its positions are. A duplicate slot (the encoder's cut at a
//! non-manifold vertex) codes nothing and takes its source slot's values.
//!
//! Colours are range-coded ([`crate::rangecoder`]) whatever the stream's [`super::Coding`].
//! Normals are range-coded in a range-coded stream and prefix-coded in a prefix-coded one
//! (version 6 of the `.bft` format): the tile sort re-codes the normals of every piece of a
//! straddling level-of-detail chunk every frame, and range-coded that took 31% of a close-up's
//! sort in `perf`. A prefix-coded version 4 stream, written before version 6, has range-coded
//! normals.
//!
//! # Colours
//!
//! 8-bit RGB, or RGBA when some alpha is not 255 (the header's flags say which). A slot's
//! colour is predicted by the rounded mean of the colours of its *earlier* neighbours (slots
//! below it that share a triangle with it, counted once per shared triangle), or by the
//! previous slot's colour when it has none. Residuals are taken modulo 256 and decorrelated
//! as the lossless image coders do (green first, then red and blue minus green's residual),
//! each through an adaptive binary tree over the 256 values whose context is the size of the
//! slot's green residual.
//!
//! # Normals
//!
//! Octahedral, as Draco quantizes them: `bits` per coordinate (2 to 16) on the grid
//! `0..=2^bits - 2`, whose center is exact. A slot's normal is predicted from the geometry, as
//! Draco's geometric normal prediction does: the area-weighted sum of its triangles' face
//! normals over the quantized positions (integer arithmetic, so the encoder and every decoder
//! agree bit for bit whatever the triangle order), flipped when a bit says the file's normals
//! face the other way. The residual of each octahedral coordinate is coded by its bit length
//! (context: the coordinate and the previous residual's length), sign, and mantissa.

use crate::csr::Csr;
use crate::rangecoder::{BitTree, Decoder, Encoder, PROB_INIT};

use super::format::{corrupt, BftError, Coding};

/// Normal quantization when none is asked for: 10 bits per octahedral coordinate (about
/// 0.2 degrees apart).
pub const DEFAULT_NORMAL_BITS: u8 = 10;

/// The per-slot attributes of a stream: each list is empty or holds one value per slot.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SlotAttributes {
    /// RGBA per slot (alpha 255 where the stream has no alpha).
    pub colors: Vec<[u8; 4]>,
    /// Whether alpha is coded.
    pub alpha: bool,
    /// Octahedral normals per slot, on the grid of `normal_bits`.
    pub normals: Vec<[u16; 2]>,
    pub normal_bits: u8,
    /// The input vertex index of each slot (`encode --keep-order`), or empty.
    pub order: Vec<u32>,
}

impl SlotAttributes {
    /// Whether there are no colours and no normals (what tiles carry; not the order).
    pub fn is_empty(&self) -> bool {
        self.colors.is_empty() && self.normals.is_empty()
    }

    /// The float normal of a slot's octahedral code.
    pub fn normal(&self, slot: usize) -> [f32; 3] {
        oct_decode(self.normals[slot], self.normal_bits)
    }

    /// The values of `slots` (a list of slots of this stream), in that order.
    pub fn select(&self, slots: &[u32]) -> SlotAttributes {
        let pick =
            |v: &[[u8; 4]]| if v.is_empty() { Vec::new() } else { slots.iter().map(|&s| v[s as usize]).collect() };
        SlotAttributes {
            colors: pick(&self.colors),
            alpha: self.alpha,
            normals: if self.normals.is_empty() {
                Vec::new()
            } else {
                slots.iter().map(|&s| self.normals[s as usize]).collect()
            },
            normal_bits: self.normal_bits,
            order: Vec::new(),
        }
    }
}

/// The largest octahedral coordinate at `bits`: the grid is `0..=2^bits - 2`.
#[inline]
fn oct_max(bits: u8) -> i64 {
    (1i64 << bits) - 2
}

/// Octahedral quantization of a direction (need not be unit) to `bits` per coordinate; the
/// zero vector (and a non-finite one) maps to +Z.
pub fn oct_encode(n: [f32; 3], bits: u8) -> [u16; 2] {
    oct_encode64(n.map(f64::from), bits)
}

fn oct_encode64([x, y, z]: [f64; 3], bits: u8) -> [u16; 2] {
    let max = oct_max(bits) as f64;
    let s = x.abs() + y.abs() + z.abs();
    let (mut u, mut v) = if s > 0.0 && s.is_finite() { (x / s, y / s) } else { (0.0, 0.0) };
    if s > 0.0 && s.is_finite() && z < 0.0 {
        let sign = |a: f64| if a >= 0.0 { 1.0 } else { -1.0 };
        (u, v) = ((1.0 - v.abs()) * sign(u), (1.0 - u.abs()) * sign(v));
    }
    let q = |a: f64| ((a + 1.0) * 0.5 * max).round().clamp(0.0, max) as u16;
    [q(u), q(v)]
}

/// The unit direction of an octahedral code at `bits`.
pub fn oct_decode(o: [u16; 2], bits: u8) -> [f32; 3] {
    let max = oct_max(bits) as f64;
    let mut u = o[0] as f64 / max * 2.0 - 1.0;
    let mut v = o[1] as f64 / max * 2.0 - 1.0;
    let z = 1.0 - u.abs() - v.abs();
    if z < 0.0 {
        let sign = |a: f64| if a >= 0.0 { 1.0 } else { -1.0 };
        (u, v) = ((1.0 - v.abs()) * sign(u), (1.0 - u.abs()) * sign(v));
    }
    let len = (u * u + v * v + z * z).sqrt();
    [(u / len) as f32, (v / len) as f32, (z / len) as f32]
}

/// What [`encode`] codes: values per slot, and for duplicate slots their source.
pub(crate) struct Input<'a> {
    /// Quantized positions per slot.
    pub positions: &'a [[u32; 3]],
    /// Every triangle of the stream over slots (loose ones included).
    pub triangles: &'a [[u32; 3]],
    /// `(slot, source)`, increasing slots.
    pub duplicates: &'a [(u32, u32)],
}

/// The slots' earlier neighbours, once per shared triangle (colour prediction).
fn earlier_neighbours(slots: usize, triangles: &[[u32; 3]]) -> Csr<u32> {
    Csr::build(slots, || {
        triangles
            .iter()
            .flat_map(|&[a, b, c]| [(a, b), (a, c), (b, a), (b, c), (c, a), (c, b)].into_iter().filter(|&(s, n)| n < s))
    })
}

/// Per slot, the sum of its triangles' face normals over quantized positions, in wrapping
/// integer arithmetic (exact and order-independent; a wrap only worsens a prediction).
fn face_sums(positions: &[[u32; 3]], triangles: &[[u32; 3]]) -> Vec<[i64; 3]> {
    let mut acc = vec![[0i64; 3]; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|s| positions[s as usize].map(i64::from));
        let (e, f) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
        let n = [
            e[1].wrapping_mul(f[2]).wrapping_sub(e[2].wrapping_mul(f[1])),
            e[2].wrapping_mul(f[0]).wrapping_sub(e[0].wrapping_mul(f[2])),
            e[0].wrapping_mul(f[1]).wrapping_sub(e[1].wrapping_mul(f[0])),
        ];
        for &s in t {
            let a = &mut acc[s as usize];
            for i in 0..3 {
                a[i] = a[i].wrapping_add(n[i]);
            }
        }
    }
    acc
}

/// What a normal coder needs of a stream: its slots, their face sums and duplicate sources.
fn normal_inputs(input: &Input) -> (usize, Vec<[i64; 3]>, Vec<u32>) {
    let n = input.positions.len();
    (n, face_sums(input.positions, input.triangles), sources(n, input.duplicates))
}

/// Per slot, its duplicate source (or itself).
fn sources(slots: usize, duplicates: &[(u32, u32)]) -> Vec<u32> {
    let mut src: Vec<u32> = (0..slots as u32).collect();
    for &(s, from) in duplicates {
        src[s as usize] = src[from as usize];
    }
    src
}

#[inline]
fn zigzag(r: u8) -> u32 {
    let r = r as i8 as i32;
    ((r << 1) ^ (r >> 31)) as u32 & 0xff
}

#[inline]
fn unzigzag(z: u32) -> u8 {
    ((z >> 1) as i32 ^ -((z & 1) as i32)) as u8
}

/// Context of the red, blue and alpha trees: the size of the green residual.
#[inline]
fn green_ctx(g: u32) -> usize {
    match g {
        0 => 0,
        1..=2 => 1,
        3..=8 => 2,
        _ => 3,
    }
}

struct ColorModel {
    green: BitTree<256>,
    others: Vec<BitTree<256>>,
}

impl ColorModel {
    fn new() -> Self {
        ColorModel { green: BitTree::default(), others: vec![BitTree::default(); 3 * 4] }
    }
}

fn predict_color(values: &[[u8; 4]], earlier: &[u32], prev: Option<[u8; 4]>) -> [u8; 4] {
    if earlier.is_empty() {
        return prev.unwrap_or([128, 128, 128, 255]);
    }
    let n = earlier.len() as u32;
    let mut sum = [0u32; 4];
    for &s in earlier {
        for c in 0..4 {
            sum[c] += values[s as usize][c] as u32;
        }
    }
    sum.map(|v| ((v + n / 2) / n) as u8)
}

/// Codes the colours of the slots (`values` per slot; duplicates' values are ignored).
pub(crate) fn encode_colors(input: &Input, values: &[[u8; 4]], alpha: bool) -> Vec<u8> {
    let n = input.positions.len();
    let earlier = earlier_neighbours(n, input.triangles);
    let src = sources(n, input.duplicates);
    let mut decoded = vec![[0u8; 4]; n];
    let mut model = ColorModel::new();
    let mut enc = Encoder::new();
    let mut prev = None;
    for s in 0..n {
        if src[s] as usize != s {
            decoded[s] = decoded[src[s] as usize];
            continue;
        }
        let p = predict_color(&decoded, earlier.get(s), prev);
        let v = values[s];
        let r = [0, 1, 2, 3].map(|c| v[c].wrapping_sub(p[c]));
        let g = zigzag(r[1]);
        model.green.encode(&mut enc, g);
        let ctx = green_ctx(g);
        model.others[ctx].encode(&mut enc, zigzag(r[0].wrapping_sub(r[1])));
        model.others[4 + ctx].encode(&mut enc, zigzag(r[2].wrapping_sub(r[1])));
        if alpha {
            model.others[8 + ctx].encode(&mut enc, zigzag(r[3]));
        }
        decoded[s] = if alpha { v } else { [v[0], v[1], v[2], 255] };
        prev = Some(decoded[s]);
    }
    enc.finish()
}

/// Decodes what [`encode_colors`] wrote.
pub(crate) fn decode_colors(input: &Input, bytes: &[u8], alpha: bool) -> Result<Vec<[u8; 4]>, BftError> {
    let n = input.positions.len();
    let earlier = earlier_neighbours(n, input.triangles);
    let src = sources(n, input.duplicates);
    let mut out = vec![[0u8; 4]; n];
    let mut model = ColorModel::new();
    let mut dec = Decoder::new(bytes);
    let mut prev = None;
    for s in 0..n {
        if src[s] as usize != s {
            out[s] = out[src[s] as usize];
            continue;
        }
        let p = predict_color(&out, earlier.get(s), prev);
        let g = model.green.decode(&mut dec);
        let ctx = green_ctx(g);
        let rg = unzigzag(g);
        let rr = unzigzag(model.others[ctx].decode(&mut dec)).wrapping_add(rg);
        let rb = unzigzag(model.others[4 + ctx].decode(&mut dec)).wrapping_add(rg);
        let a = if alpha { p[3].wrapping_add(unzigzag(model.others[8 + ctx].decode(&mut dec))) } else { 255 };
        out[s] = [p[0].wrapping_add(rr), p[1].wrapping_add(rg), p[2].wrapping_add(rb), a];
        prev = Some(out[s]);
        if dec.overrun() > 8 {
            return Err(BftError::Truncated("colour stream"));
        }
    }
    if dec.overrun() > 0 {
        return Err(BftError::Truncated("colour stream"));
    }
    Ok(out)
}

const NORMAL_CTX: usize = 6;

struct NormalModel {
    class: Vec<BitTree<32>>,
    sign: [u16; 2],
    second: [[u16; 32]; 2],
    flip: u16,
    prev_class: [u32; 2],
}

impl NormalModel {
    fn new() -> Self {
        NormalModel {
            class: vec![BitTree::default(); 2 * NORMAL_CTX],
            sign: [PROB_INIT; 2],
            second: [[PROB_INIT; 32]; 2],
            flip: PROB_INIT,
            prev_class: [0; 2],
        }
    }

    #[inline]
    fn ctx(&self, axis: usize) -> usize {
        // The other coordinate's last length for v, this one's own for u.
        let p = if axis == 0 { self.prev_class[0] } else { self.prev_class[0].max(self.prev_class[1]) };
        axis * NORMAL_CTX + (p as usize).min(NORMAL_CTX - 1)
    }
}

/// The predicted direction of slot `s`, before the flip bit.
fn normal_prediction(sum: [i64; 3], prev: Option<[u16; 2]>, bits: u8) -> [f64; 3] {
    if sum != [0; 3] {
        sum.map(|v| v as f64)
    } else {
        oct_decode(prev.unwrap_or([0; 2]), bits).map(f64::from)
    }
}

/// Whether the value `v` faces away from the prediction `p` (the encoder's flip bit).
fn faces_away(p: [f64; 3], v: [u16; 2], bits: u8) -> bool {
    let actual = oct_decode(v, bits);
    (0..3).map(|i| p[i] * actual[i] as f64).sum::<f64>() < 0.0
}

/// The octahedral code predicted from `p`, turned around when `flip`.
fn predicted_code(p: [f64; 3], flip: bool, bits: u8) -> [u16; 2] {
    oct_encode64(if flip { p.map(|c| -c) } else { p }, bits)
}

/// What an encoder codes of each slot that is not a duplicate, in slot order: its value, the
/// flip bit, and the predicted code (after the flip) that its residual is taken from.
fn normal_predictions<'a>(
    input: &Input,
    values: &'a [[u16; 2]],
    bits: u8,
) -> impl Iterator<Item = ([u16; 2], bool, [u16; 2])> + 'a {
    let (n, sums, src) = normal_inputs(input);
    let mut prev = None;
    (0..n).filter(move |&s| src[s] as usize == s).map(move |s| {
        let v = values[s];
        let p = normal_prediction(sums[s], prev, bits);
        let flip = faces_away(p, v, bits);
        prev = Some(v);
        (v, flip, predicted_code(p, flip, bits))
    })
}

/// Codes the octahedral normals of the slots at `bits` (duplicates' values are ignored) for a
/// stream coded as `coding`: range-coded ([`encode_normals_range`]) in a range-coded stream,
/// prefix-coded ([`encode_normals_prefix`]) in a prefix-coded one.
pub(crate) fn encode_normals(input: &Input, values: &[[u16; 2]], bits: u8, coding: Coding) -> Vec<u8> {
    match coding {
        Coding::Range => encode_normals_range(input, values, bits),
        Coding::Prefix | Coding::PrefixByDegree => encode_normals_prefix(input, values, bits),
    }
}

/// Decodes what [`encode_normals`] wrote: `prefix` for a version 6 stream
/// ([`super::format`]).
pub(crate) fn decode_normals(input: &Input, bytes: &[u8], bits: u8, prefix: bool) -> Result<Vec<[u16; 2]>, BftError> {
    if prefix {
        decode_normals_prefix(input, bytes, bits)
    } else {
        decode_normals_range(input, bytes, bits)
    }
}

/// The adaptive range coder's normals, as every range-coded stream and every version 4 stream
/// codes them.
fn encode_normals_range(input: &Input, values: &[[u16; 2]], bits: u8) -> Vec<u8> {
    let mut model = NormalModel::new();
    let mut enc = Encoder::new();
    for (v, flip, pred) in normal_predictions(input, values, bits) {
        enc.bit(&mut model.flip, flip);
        for axis in 0..2 {
            let r = v[axis] as i64 - pred[axis] as i64;
            let m = r.unsigned_abs() as u32;
            let class = 32 - m.leading_zeros();
            let ctx = model.ctx(axis);
            model.class[ctx].encode(&mut enc, class);
            if class > 0 {
                enc.bit(&mut model.sign[axis], r < 0);
                if class >= 2 {
                    let rest = class - 1;
                    enc.bit(&mut model.second[axis][class as usize], (m >> (rest - 1)) & 1 != 0);
                    enc.direct_bits(m, rest - 1);
                }
            }
            model.prev_class[axis] = class;
        }
    }
    enc.finish()
}

/// Decodes what [`encode_normals_range`] wrote.
fn decode_normals_range(input: &Input, bytes: &[u8], bits: u8) -> Result<Vec<[u16; 2]>, BftError> {
    let (n, sums, src) = normal_inputs(input);
    let max = oct_max(bits);
    let mut model = NormalModel::new();
    let mut dec = Decoder::new(bytes);
    let mut out = vec![[0u16; 2]; n];
    let mut prev = None;
    for s in 0..n {
        if src[s] as usize != s {
            out[s] = out[src[s] as usize];
            continue;
        }
        let p = normal_prediction(sums[s], prev, bits);
        let pred = predicted_code(p, dec.bit(&mut model.flip), bits);
        let mut v = [0u16; 2];
        for axis in 0..2 {
            let ctx = model.ctx(axis);
            let class = model.class[ctx].decode(&mut dec);
            let mut m = 0u32;
            let mut neg = false;
            if class > 0 {
                if class > bits as u32 {
                    return Err(corrupt(format!("normal of vertex {s} is outside the octahedral grid")));
                }
                neg = dec.bit(&mut model.sign[axis]);
                m = 1 << (class - 1);
                if class >= 2 {
                    let rest = class - 1;
                    let top = dec.bit(&mut model.second[axis][class as usize]) as u32;
                    m |= top << (rest - 1) | dec.direct_bits(rest - 1);
                }
            }
            let x = pred[axis] as i64 + if neg { -(m as i64) } else { m as i64 };
            if !(0..=max).contains(&x) {
                return Err(corrupt(format!("normal of vertex {s} is outside the octahedral grid")));
            }
            v[axis] = x as u16;
            model.prev_class[axis] = class;
        }
        out[s] = v;
        prev = Some(v);
        if dec.overrun() > 8 {
            return Err(BftError::Truncated("normal stream"));
        }
    }
    if dec.overrun() > 0 {
        return Err(BftError::Truncated("normal stream"));
    }
    Ok(out)
}

/// Residual classes of a normal coordinate (bit lengths 0..=16, `bits` being at most 16).
const NORMAL_CLASSES: usize = 17;
/// Prefix-coded normals' table contexts per coordinate ([`normal_prefix_ctx`]).
const NORMAL_PREFIX_CTX: usize = 3;
/// The first coordinate's symbol is its class and the flip bit, `class << 1 | flip`.
const NORMAL_U_SYMBOLS: usize = 2 * NORMAL_CLASSES;

/// The table context of a class (the range coder's six, folded to three: a prefix-coded tile
/// stores its tables, and a piece of a few hundred vertices pays for each).
#[inline]
fn normal_prefix_ctx(class: u32) -> usize {
    match class {
        0..=1 => 0,
        2..=3 => 1,
        _ => 2,
    }
}

/// Codes the octahedral normals of the slots at `bits` with static prefix codes, the `NORM`
/// section of a prefix-coded stream (version 6; [`super::prefix`] codes its commands and
/// positions). The same prediction as [`encode_normals_range`]; per slot, the first coordinate's
/// class with the flip bit as one symbol and the second's class, each from one of
/// [`NORMAL_PREFIX_CTX`] tables chosen by the class before it (the previous slot's first, then
/// this slot's first), each followed by its sign and the bits below its leading one. The
/// tables lead the section (`NORMAL_PREFIX_CTX` first-coordinate tables, then as many
/// second-coordinate ones, as [`super::prefix`] writes its tables).
///
/// Why: the tile sort re-codes the normals of every straddling chunk's pieces each frame.
/// Orbiting the 223M-triangle dragon's level-of-detail close-up a degree a frame in one
/// process (`CLOSE=1 orbitsort`), the sort took 164 ms a frame against 207 range-coded, and the
/// tiles 0.99x the bytes.
fn encode_normals_prefix(input: &Input, values: &[[u16; 2]], bits: u8) -> Vec<u8> {
    let mut u_counts = [[0u64; NORMAL_U_SYMBOLS]; NORMAL_PREFIX_CTX];
    let mut v_counts = [[0u64; NORMAL_CLASSES]; NORMAL_PREFIX_CTX];
    // Per coded coordinate: `table << 6 | symbol`, the class (raw bits), the raw bits.
    let mut coded: Vec<(u16, u8, u16)> = Vec::with_capacity(2 * values.len());
    let mut prev_u = 0;
    for (v, flip, pred) in normal_predictions(input, values, bits) {
        let (cu, ru) = super::prefix::residual_bits(v[0] as i64 - pred[0] as i64);
        let (cv, rv) = super::prefix::residual_bits(v[1] as i64 - pred[1] as i64);
        let (tu, tv) = (normal_prefix_ctx(prev_u), normal_prefix_ctx(cu));
        let su = (cu << 1 | flip as u32) as usize;
        u_counts[tu][su] += 1;
        v_counts[tv][cv as usize] += 1;
        coded.push(((tu << 6 | su) as u16, cu as u8, ru as u16));
        coded.push((((NORMAL_PREFIX_CTX + tv) << 6 | cv as usize) as u16, cv as u8, rv as u16));
        prev_u = cu;
    }
    let (u_tables, v_tables) = (super::prefix::tables(&u_counts), super::prefix::tables(&v_counts));
    let tables: [&[_]; 2] = [&u_tables, &v_tables];
    let mut w = crate::huffman::BitWriter::default();
    u_tables.iter().chain(&v_tables).for_each(|t| super::prefix::write_table(&mut w, t));
    for &(ts, class, raw) in &coded {
        let t = (ts >> 6) as usize;
        let (code, len) = tables[t / NORMAL_PREFIX_CTX][t % NORMAL_PREFIX_CTX].code((ts & 63) as u8);
        // At most 15 bits of code and 16 raw.
        w.put(code << class | raw as u32, len + class);
    }
    w.finish()
}

/// Decodes what [`encode_normals_prefix`] wrote.
fn decode_normals_prefix(input: &Input, bytes: &[u8], bits: u8) -> Result<Vec<[u16; 2]>, BftError> {
    use crate::huffman::{BitReader, SmallTable};
    let (n, sums, src) = normal_inputs(input);
    let max = oct_max(bits);
    let mut r = BitReader::new(bytes, 0);
    let mut tables = vec![SmallTable::EMPTY; 2 * NORMAL_PREFIX_CTX];
    let (u_tables, v_tables) = tables.split_at_mut(NORMAL_PREFIX_CTX);
    u_tables.iter_mut().try_for_each(|t| super::prefix::read_table(&mut r, NORMAL_U_SYMBOLS, "normal", t))?;
    v_tables.iter_mut().try_for_each(|t| super::prefix::read_table(&mut r, NORMAL_CLASSES, "normal", t))?;
    let outside = |s: usize| corrupt(format!("normal of vertex {s} is outside the octahedral grid"));
    // One coordinate: its symbol from `table` (the class above `flip_bits` bits), then its
    // raw bits; (symbol, class, residual).
    let coordinate = |r: &mut BitReader, table: &SmallTable, s: usize, flip_bits: u32| {
        let w = r.window_of::<{ super::prefix::MAX_CODE_LEN as u32 + 16 }>();
        let (sym, code_len) = table.lookup(w).ok_or_else(|| corrupt(format!("invalid normal code at vertex {s}")))?;
        let class = (sym >> flip_bits) as u32;
        if class > bits as u32 {
            return Err(outside(s));
        }
        let d = super::prefix::residual(w << code_len, class);
        r.consume(code_len + class);
        Ok::<_, BftError>((sym, class, d))
    };
    let mut out = vec![[0u16; 2]; n];
    let (mut prev, mut prev_u) = (None, 0);
    for s in 0..n {
        if src[s] as usize != s {
            out[s] = out[src[s] as usize];
            continue;
        }
        let (su, cu, du) = coordinate(&mut r, &u_tables[normal_prefix_ctx(prev_u)], s, 1)?;
        let (_, _, dv) = coordinate(&mut r, &v_tables[normal_prefix_ctx(cu)], s, 0)?;
        let p = normal_prediction(sums[s], prev, bits);
        let pred = predicted_code(p, su & 1 != 0, bits);
        let mut v = [0u16; 2];
        for (axis, d) in [du, dv].into_iter().enumerate() {
            let x = pred[axis] as i64 + d;
            if !(0..=max).contains(&x) {
                return Err(outside(s));
            }
            v[axis] = x as u16;
        }
        out[s] = v;
        prev = Some(v);
        prev_u = cu;
        if r.overrun() > 64 {
            return Err(BftError::Truncated("normal stream"));
        }
    }
    if r.overrun() > 0 {
        return Err(BftError::Truncated("normal stream"));
    }
    Ok(out)
}

/// Codes the input vertex index of every slot that is not a duplicate (section `ORDR`,
/// `encode --keep-order`): each as its difference from the previous one plus one, zigzagged,
/// through an adaptive Elias-gamma coder, so runs of consecutive indices cost about a bit.
pub(crate) fn encode_order(values: &[u32], duplicates: &[(u32, u32)]) -> Vec<u8> {
    let src = sources(values.len(), duplicates);
    let mut coder = crate::rangecoder::UIntCoder::default();
    let mut enc = Encoder::new();
    let mut next = 0i64;
    for (s, &v) in values.iter().enumerate() {
        if src[s] as usize == s {
            let d = v as i64 - next;
            coder.encode(&mut enc, ((d << 1) ^ (d >> 63)) as u32);
            next = v as i64 + 1;
        }
    }
    enc.finish()
}

/// Decodes what [`encode_order`] wrote for `slots` slots; every index must be below `limit`.
pub(crate) fn decode_order(
    slots: usize,
    duplicates: &[(u32, u32)],
    bytes: &[u8],
    limit: u32,
) -> Result<Vec<u32>, BftError> {
    // `Decoded::to_mesh` gives every input vertex a place, 12 bytes of position at least: a
    // header that names more than the cap allows is refused here, not allocated there.
    crate::input::check_decoded("the vertex order", limit.into(), "input vertices", 12).map_err(BftError::TooLarge)?;
    let src = sources(slots, duplicates);
    let mut coder = crate::rangecoder::UIntCoder::default();
    let mut dec = Decoder::new(bytes);
    let mut out = vec![0u32; slots];
    let mut next = 0i64;
    for s in 0..slots {
        if src[s] as usize != s {
            out[s] = out[src[s] as usize];
            continue;
        }
        let z = coder.decode(&mut dec).ok_or_else(|| corrupt("bad vertex order code"))? as i64;
        let v = next + ((z >> 1) ^ -(z & 1));
        // (A repeated index, which only a forged file has, makes one vertex overwrite another
        // in `Decoded::to_mesh`; checking for it would cost a table of every input vertex.)
        if !(0..limit as i64).contains(&v) {
            return Err(corrupt(format!("vertex order: slot {s} names input vertex {v} of {limit}")));
        }
        out[s] = v as u32;
        next = v + 1;
        if dec.overrun() > 8 {
            return Err(BftError::Truncated("vertex order"));
        }
    }
    if dec.overrun() > 0 {
        return Err(BftError::Truncated("vertex order"));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octahedral_codes_round_trip_on_the_grid() {
        for bits in [4u8, 8, 10, 12] {
            let max = oct_max(bits) as u16;
            for u in (0..=max).step_by(((max as usize) / 37).max(1)) {
                for v in (0..=max).step_by(((max as usize) / 41).max(1)) {
                    let n = oct_decode([u, v], bits);
                    let len = n.iter().map(|c| c * c).sum::<f32>().sqrt();
                    assert!((len - 1.0).abs() < 1e-5);
                    let back = oct_encode(n, bits);
                    // Points of the square's border fold onto each other: the direction, not
                    // the code, is what must come back.
                    let again = oct_decode(back, bits);
                    let dot: f32 = (0..3).map(|i| again[i] * n[i]).sum();
                    assert!(dot > 0.9999, "bits {bits}: {u},{v} -> {n:?} -> {back:?}");
                }
            }
        }
        assert_eq!(oct_decode(oct_encode([0.0, 0.0, 1.0], 10), 10), [0.0, 0.0, 1.0]);
        assert_eq!(oct_encode([0.0; 3], 10), oct_encode([0.0, 0.0, 1.0], 10));
        assert_eq!(oct_encode([f32::NAN; 3], 10), oct_encode([0.0, 0.0, 1.0], 10));
    }

    #[test]
    fn zigzag_is_a_bijection_on_bytes() {
        let mut seen = [false; 256];
        for r in 0..=255u8 {
            let z = zigzag(r);
            assert!(!seen[z as usize]);
            seen[z as usize] = true;
            assert_eq!(unzigzag(z), r);
        }
        assert_eq!(zigzag(0), 0);
        assert_eq!(zigzag(255), 1);
        assert_eq!(zigzag(1), 2);
    }
}
