// Decoding one operation of a .dpm file (version 5) from its address and context on the GPU:
// the WGSL twin of codec/src/pm/format/op.rs `read_op`, field for field and check for check,
// so that it decodes what the CPU decodes bit for bit and refuses what the CPU refuses
// (worker/tests/pm_decode.rs compares the two over every operation of real meshes and over
// damaged ones). Every step is an integer step: the format was made so (the format's
// documentation, "Integer-exact decoding").
//
// A shader that decodes prepends the generated constants (the table layout of the format's
// fields, `decoder_prelude` in worker/src/pm_adapt/decoder.rs), this file and the decoder's
// buffers, bind group 1 (decode_bindings.wgsl):
//   D:         the DecodeParams uniform,
//   ops:       array<u32>, the operations section, four bytes per word, little-endian; out of
//              core (D.nodes > 0) a pool of slots of D.slot_bytes each, holding resident nodes,
//   tables:    array<u32>, the probability tables (see `read_sym`), then from D.values_at the
//              f32 bits of the sin(alpha) codes (256) and the log tables of the lengths and of
//              the attribute error (LOG_STEPS each); out of core, from D.lens_at, every node's
//              length, then every node's slot in `ops` (the page table, NONE_ADDR: not
//              resident),
//   dec_faces: array<u32>, read_write, where decoded faces go (FVID triples).
//
// Out of core an address is node * 2^16 + local address (section 4.2.1 of the paper): the
// decoder looks the node up in the page table and reads within its slot; an operation whose
// node is not resident is answered DEC_ABSENT (the caller waits for it, it is not an error).
//
// Bounded work and reads: every read of `ops` is below D.ops_len (out of core: below the end
// of the node's bytes in its slot), every loop has a constant or
// header-checked bound (a symbol at most MAX_LEN bits, a value at most 5 groups or 28 raw bits,
// the faces at most D.max_faces, at most 65535), and a failed check stops the decoding with a
// status, never a fault.

struct DecodeParams {
    ops_len: u32,       // bytes of the operations section
    vertices: u32,      // FVIDs, below 2^31
    position_bits: u32,
    normal_bits: u32,
    avg_op_size: u32,   // 16.16 fixed point
    max_faces: u32,     // the header's: no operation adds more
    count: u32,         // operations to decode (batch entry points)
    values_at: u32,     // where the value tables start in `tables`
    nodes: u32,         // out of core: the nodes; 0 in core
    lens_at: u32,       // out of core: where the node lengths start in `tables` (the page table after)
    slot_bytes: u32,    // out of core: bytes per slot of `ops`
    pad: u32,
    grid: vec4<f32>,    // the position grid: its origin (xyz) and step (w)
}

// One decoded operation (`Decoded` in Rust's decoder.rs).
struct DecodedOp {
    status: u32,        // DEC_OK or the check that failed
    v_u: u32,
    flags: u32,         // 1: v_l splits further, 2: v_u does, 4: v_u's operation is stored first
    left: u32,          // address of v_l's operation, NONE_ADDR if none
    right: u32,         // address of v_u's operation, NONE_ADDR if none
    end: u32,           // one past the operation's last byte
    faces: u32,         // faces added (written to dec_faces)
    pad: u32,
    crit: vec4<u32>,    // quantized criteria: sin(alpha), geometric error, attribute error, radius
    crit_f: vec4<u32>,  // their f32 values, as bits
    position: vec4<u32>, // v_u's quantized position (w unused)
    normal: vec4<u32>,  // v_u's octahedral normal (zw unused)
}

const NONE_ADDR: u32 = 0xffffffffu;
const DEC_OK: u32 = 0u;
const DEC_TRUNCATED: u32 = 1u;   // the operations section ends inside the operation
const DEC_CONTEXT: u32 = 2u;     // address or context out of range
const DEC_SYMBOL: u32 = 3u;      // a bit pattern that is no code of its table
const DEC_VALUE: u32 = 4u;       // a value wider than 32 bits, or a bad head
const DEC_CRITERION: u32 = 5u;   // a refinement criterion out of range
const DEC_TREE: u32 = 6u;        // split tree inconsistent with the FVID ranges
const DEC_FACES: u32 = 7u;       // face count, form or corner out of range
const DEC_POSITION: u32 = 8u;
const DEC_NORMAL: u32 = 9u;
const DEC_POINTER: u32 = 10u;
const DEC_ABSENT: u32 = 11u;     // out of core: the operation's node is not resident (no error)
const DEC_LOOP_LIMIT: u32 = 12u; // a descent's loop ended without finishing (a GPU's loop limit)

// How far decode_op goes: everything, or up to the face count (criteria, children, v_u and
// the number of faces: what a vertex needs to ask for its split and size it).
const DECODE_ALL: u32 = 0u;
const DECODE_TO_FACES: u32 = 1u;

// The bit reader: the byte that holds the next bit and how many of its bits were read (most
// significant first), and the first failure (reads after one return zeros without touching
// memory); r_end is one past the last byte it may read (the section's, or the node's in its
// slot).
var<private> r_byte: u32;
var<private> r_off: u32;
var<private> r_end: u32;
var<private> r_err: u32;

fn fail(code: u32) {
    if (r_err == DEC_OK) {
        r_err = code;
    }
}

fn op_byte(i: u32) -> u32 {
    return (ops[i >> 2u] >> ((i & 3u) * 8u)) & 0xffu;
}

// The bits left to read before r_end, at most 32.
fn bits_left() -> u32 {
    if (r_byte >= r_end) {
        return 0u;
    }
    return min(min(r_end - r_byte, 5u) * 8u - r_off, 32u);
}

// A word's bytes in the other order: the operations' bytes as a big-endian number.
fn byte_swap(x: u32) -> u32 {
    return (x << 24u) | ((x & 0xff00u) << 8u) | ((x >> 8u) & 0xff00u) | (x >> 24u);
}

// The next 32 bits, the next one the most significant, zeros past r_end (not read): at most
// two words of `ops`.
fn peek() -> u32 {
    let left = bits_left();
    if (left == 0u) {
        return 0u;
    }
    let i = r_byte >> 2u;
    let hi = byte_swap(ops[i]);
    var lo = 0u;
    if ((i + 1u) * 4u < r_end) {
        lo = byte_swap(ops[i + 1u]);
    }
    let s = (r_byte & 3u) * 8u + r_off;
    var w = hi;
    if (s > 0u) {
        w = (hi << s) | (lo >> (32u - s));
    }
    if (left < 32u) {
        w &= ~(0xffffffffu >> left);
    }
    return w;
}

fn skip(bits: u32) {
    let t = r_off + bits;
    r_byte += t >> 3u;
    r_off = t & 7u;
}

// One past the last byte read from.
fn reader_end() -> u32 {
    return r_byte + select(0u, 1u, r_off != 0u);
}

// The next `k` bits (1 to 32) as a number; past the end a failure.
fn read_bits(k: u32) -> u32 {
    if (r_err != DEC_OK) {
        return 0u;
    }
    if (bits_left() < k) {
        fail(DEC_TRUNCATED);
        return 0u;
    }
    let v = peek() >> (32u - k);
    skip(k);
    return v;
}

// Where a table's lookup starts among its words.
const LUT_AT: u32 = 3u * (MAX_LEN + 1u) + 1u + 64u;

// One symbol of canonical Huffman table `t`. `tables[t]` is where the table's TABLE_WORDS
// words start (identical tables share them): the first code per length (MAX_LEN + 1 words),
// the count per length, the offset of the length's symbols, the longest length, the symbols
// by code, four bytes per word, then per LUT_BITS-bit pattern the symbol of the code it
// begins with and that code's length (`sym | len << 8`, two a word), 0 where the code is
// longer. Longer codes are compared length by length. It fails as a bit-by-bit reader would:
// truncated where the code (or the search for one) runs past the end, else no code of the
// table (decoder.rs `lut_entry`).
fn read_sym(t: u32) -> u32 {
    if (r_err != DEC_OK) {
        return 0u;
    }
    let base = tables[t];
    let longest = min(tables[base + 3u * (MAX_LEN + 1u)], MAX_LEN);
    let left = bits_left();
    let w = peek();
    let p = w >> (32u - LUT_BITS);
    let e = (tables[base + LUT_AT + (p >> 1u)] >> ((p & 1u) * 16u)) & 0xffffu;
    var len = e >> 8u;
    var sym = e & 0xffu;
    if (e == 0u) {
        for (var l = LUT_BITS + 1u; l <= longest; l++) {
            let code = w >> (32u - l);
            let first = tables[base + l];
            let d = code - first;
            if (code >= first && d < tables[base + MAX_LEN + 1u + l]) {
                let k = tables[base + 2u * (MAX_LEN + 1u) + l] + d;
                sym = (tables[base + 3u * (MAX_LEN + 1u) + 1u + (k >> 2u)] >> ((k & 3u) * 8u)) & 0xffu;
                len = l;
                break;
            }
        }
    }
    if (len == 0u) {
        fail(select(DEC_SYMBOL, DEC_TRUNCATED, left < longest));
        return 0u;
    }
    if (len > left) {
        fail(DEC_TRUNCATED);
        return 0u;
    }
    skip(len);
    return sym;
}

// A value in 7-bit groups, least significant first, from the three tables at `t0` (group
// significance 0, 1, 2 and more); at most 32 bits.
fn get_groups(t0: u32) -> u32 {
    var v = 0u;
    for (var i = 0u; i < 5u; i++) {
        let s = read_sym(t0 + min(i, 2u));
        if (r_err != DEC_OK) {
            return 0u;
        }
        let g = s & 0x7fu;
        if (i == 4u && g > 15u) {
            fail(DEC_VALUE);
            return 0u;
        }
        v |= g << (7u * i);
        if ((s & 0x80u) == 0u) {
            return v;
        }
    }
    fail(DEC_VALUE);
    return 0u;
}

// A bucket value of table `t`: the symbol itself below 16, else a bit length and the three
// bits below the leading one, then the raw low bits; at most 32 bits.
fn get_bucket(t: u32) -> u32 {
    let s = read_sym(t);
    if (r_err != DEC_OK || s < 16u) {
        return s;
    }
    let b = ((s - 16u) >> 3u) + 5u;
    if (b > 32u) {
        fail(DEC_VALUE);
        return 0u;
    }
    let raw = b - 4u;
    return ((8u | ((s - 16u) & 7u)) << raw) | read_bits(raw);
}

// The inverse of the zigzag map (0, -1, 1, -2, ...), over all of u32.
fn unzigzag(u: u32) -> i32 {
    if ((u & 1u) == 0u) {
        return i32(u >> 1u);
    }
    return -i32(u >> 1u) - 1;
}

// |x| as u32, exact for the most negative i32.
fn magnitude(x: i32) -> u32 {
    if (x >= 0) {
        return u32(x);
    }
    return u32(-(x + 1)) + 1u;
}

fn bit_length(x: u32) -> u32 {
    return 32u - countLeadingZeros(x);
}

// Whether `base + d` lies in [0, hi] (no overflow: base and hi are below 2^31).
fn lands_in(base: i32, d: i32, hi: i32) -> bool {
    return d >= -base && d <= hi - base;
}

// The contexts of codec/src/pm/format/fields.rs.
fn region_class(size: u32) -> u32 {
    return min(bit_length(max(size, 2u)) - 2u, 2u);
}

fn split_class(n: u32) -> u32 {
    return min(bit_length(n) - 3u, 5u);
}

fn head_class(size: u32) -> u32 {
    return clamp(size, 2u, 5u) - 2u;
}

fn magnitude_class(k: u32) -> u32 {
    if (k == 0u) {
        return 0u;
    }
    return min(1u + (k - 1u) / LOG_STEPS, 27u);
}

fn corner_class(has_prev: bool, prev: u32, range: u32) -> u32 {
    if (!has_prev) {
        return min(bit_length(range) - 2u, 3u);
    }
    return 4u + min(prev, 2u);
}

fn valid_oct(q: vec2<u32>) -> bool {
    let zero = 1u << D.normal_bits;
    return (q.x == zero && q.y == zero) || (q.x < zero && q.y < zero);
}

// Criterion `pred - residual`, or a failure unless it lies in [0, hi].
fn criterion(pred: u32, residual: i32, hi: u32) -> u32 {
    if (residual >= 0) {
        let r = u32(residual);
        if (r <= pred && pred - r <= hi) {
            return pred - r;
        }
    } else {
        let r = magnitude(residual);
        if (pred <= hi && r <= hi - pred) {
            return pred + r;
        }
    }
    fail(DEC_CRITERION);
    return 0u;
}

// The f32 bits of log code `k` from the 35-entry table at `values[at]` (codec's `log_value`):
// the octave's power of two added to the exponent bits, f32::MAX past the range.
fn log_value_bits(k: u32, at: u32) -> u32 {
    if (k == 0u) {
        return 0u;
    }
    let bits = tables[D.values_at + at + (k - 1u) % LOG_STEPS];
    let e = (k - 1u) / LOG_STEPS;
    if (((bits >> 23u) & 0xffu) + e >= 0xffu) {
        return 0x7f7fffffu;
    }
    return bits + (e << 23u);
}

// The f32 bits of quantized criteria: sin(alpha) from its table, the lengths and the
// attribute error from theirs.
fn crit_values(c: vec4<u32>) -> vec4<u32> {
    return vec4<u32>(tables[D.values_at + min(c.x, 255u)], log_value_bits(c.y, 256u),
                     log_value_bits(c.z, 256u + LOG_STEPS), log_value_bits(c.w, 256u));
}

// The address offset estimate: avg * (first - 1) in 16.16 fixed point, rounded, capped at
// u32::MAX (codec's `pointer_estimate`), with the 64-bit product in 32-bit halves.
fn pointer_estimate(avg: u32, first: u32) -> u32 {
    let b = first - 1u;
    let a_lo = avg & 0xffffu;
    let a_hi = avg >> 16u;
    let b_lo = b & 0xffffu;
    let b_hi = b >> 16u;
    let ll = a_lo * b_lo;
    let lh = a_lo * b_hi;
    let hl = a_hi * b_lo;
    let hh = a_hi * b_hi;
    // lo = ll + (lh << 16) + (hl << 16), hi = hh + (lh >> 16) + (hl >> 16) + carries.
    var lo = ll;
    var hi = hh + (lh >> 16u) + (hl >> 16u);
    let s1 = lo + (lh << 16u);
    hi += select(0u, 1u, s1 < lo);
    lo = s1;
    let s2 = lo + (hl << 16u);
    hi += select(0u, 1u, s2 < lo);
    lo = s2;
    let s3 = lo + 0x8000u;
    hi += select(0u, 1u, s3 < lo);
    lo = s3;
    if (hi >= 0x10000u) {
        return 0xffffffffu;
    }
    return (hi << 16u) | (lo >> 16u);
}

// A pointer offset from its estimate and coded residual, `est + r`; NONE_ADDR below zero or
// past 2^32 (so past any section).
fn offset_from(est: u32, r: i32) -> u32 {
    if (r >= 0) {
        let o = est + u32(r);
        return select(o, NONE_ADDR, o < est);
    }
    let back = magnitude(r);
    return select(est - back, NONE_ADDR, back > est);
}

// Decodes the operation at byte `addr` for vertex `v` (FVIDs v..v_end), its parent's quantized
// criteria `pc`, its quantized position `pos` and octahedral normal `nrm`; the faces go to
// dec_faces from face slot `face_out` on (nowhere for NONE_ADDR). With `upto` DECODE_TO_FACES it
// stops after the face count: then only status, v_u, flags, faces and the criteria are set.
fn decode_op(addr: u32, v: u32, v_end: u32, pc: vec4<u32>, pos: vec3<u32>, nrm: vec2<u32>, face_out: u32,
             upto: u32) -> DecodedOp {
    let h = decode_head(addr, v, v_end, pc, pos, nrm);
    if (upto == DECODE_TO_FACES) {
        return h;
    }
    if (h.status != DEC_OK) {
        var o: DecodedOp;
        o.status = h.status;
        o.left = NONE_ADDR;
        o.right = NONE_ADDR;
        return o;
    }
    return decode_tail(face_out);
}

// What decode_head leaves for decode_tail: the operation's context, where its bytes are, and
// what the head decoded (the bit reader's position is r_byte and r_off).
var<private> dh_v: u32;
var<private> dh_v_end: u32;
var<private> dh_pos: vec3<u32>;
var<private> dh_nrm: vec2<u32>;
var<private> dh_node: u32;
var<private> dh_len: u32;
var<private> dh_base: u32;
var<private> dh_pattern: u32;
var<private> dh_first: u32;
var<private> dh_has_left: bool;
var<private> dh_has_right: bool;
var<private> dh_o: DecodedOp;

// The operation's head, up to its face count (decode_op with DECODE_TO_FACES: status, v_u,
// flags, faces and the criteria); after a head that decoded, decode_tail goes on from where
// it stopped.
fn decode_head(addr: u32, v: u32, v_end: u32, pc: vec4<u32>, pos: vec3<u32>, nrm: vec2<u32>) -> DecodedOp {
    var o: DecodedOp;
    o.left = NONE_ADDR;
    o.right = NONE_ADDR;
    // Where the operation's bytes are: in core the section, out of core its node's slot.
    var node = NONE_ADDR;
    var local = addr;
    var len = D.ops_len;
    var base = 0u;
    if (D.nodes != 0u) {
        node = addr >> 16u;
        local = addr & 0xffffu;
        if (node >= D.nodes) {
            o.status = DEC_CONTEXT;
            return o;
        }
        let slot = tables[D.lens_at + D.nodes + node];
        if (slot == NONE_ADDR) {
            o.status = DEC_ABSENT;
            return o;
        }
        len = min(tables[D.lens_at + node], D.slot_bytes);
        base = slot * D.slot_bytes;
    }
    r_byte = base + local;
    r_end = base + len;
    r_off = 0u;
    r_err = DEC_OK;
    let n = D.vertices;
    let max_q = (1u << D.position_bits) - 1u;
    if (local >= len || v >= v_end || v_end > n || !valid_oct(nrm) || any(pos > vec3<u32>(max_q))) {
        o.status = DEC_CONTEXT;
        return o;
    }
    let size = v_end - v;

    // 1. criteria residuals, 2. the head, 3. the radius.
    let r_sin = unzigzag(get_groups(T_SIN + 3u * min(pc.x >> 6u, 3u)));
    let r_geom = unzigzag(get_groups(T_GEOM));
    let r_attr = unzigzag(get_groups(T_ATTR));
    let head = get_groups(T_HEAD + 3u * head_class(size));
    if (r_err != DEC_OK) {
        o.status = r_err;
        return o;
    }
    let code = head % 5u;
    let nfc = head / 5u % 4u;
    let pattern = head / 20u % 3u;
    let rz = head / 60u;
    if (rz > 1u) {
        o.status = DEC_VALUE;
        return o;
    }
    var r_radius = 0;
    if (rz == 1u) {
        let g = get_groups(T_RADIUS);
        if (g == 0xffffffffu) {
            // A residual of 2^31: the radius would be negative.
            fail(DEC_CRITERION);
        } else {
            r_radius = unzigzag(g + 1u);
        }
    }
    var crit: vec4<u32>;
    crit.x = criterion(pc.x, r_sin, 255u);
    crit.y = criterion(pc.y, r_geom, MAX_K);
    crit.z = criterion(pc.z, r_attr, MAX_K);
    crit.w = criterion(min(pc.w, crit.y), r_radius, MAX_K);
    if (r_err != DEC_OK) {
        o.status = r_err;
        return o;
    }

    // 4. the split point.
    let has_left = code == 1u || code == 2u || code == 4u;
    let has_right = code == 1u || code == 3u || code == 4u;
    let swapped = code == 4u;
    var v_u: u32;
    var first = 0u;
    if (has_left && has_right) {
        var s = 2u;
        if (size > 4u) {
            let g = get_groups(T_SPLIT + 3u * split_class(size));
            if (r_err == DEC_OK && g > size - 4u) {
                fail(DEC_TREE);
            }
            s = g + 2u;
        } else if (size < 4u) {
            fail(DEC_TREE);
        }
        if (r_err != DEC_OK) {
            o.status = r_err;
            return o;
        }
        v_u = select(v + s, v_end - s, swapped);
        first = s;
    } else if (has_left) {
        v_u = v_end - 1u;
    } else {
        v_u = v + 1u;
    }
    if (v_u <= v || v_u >= v_end || (has_left && v_u - v < 2u) || (!has_left && v_u - v != 1u)
        || (has_right && v_end - v_u < 2u) || (!has_right && v_end - v_u != 1u)) {
        o.status = DEC_TREE;
        return o;
    }

    // 5. the faces.
    var nf = nfc;
    if (nfc == 3u) {
        let g = get_groups(T_FACE_COUNT);
        // max_faces is at most 65535, so a count that wraps is above it too.
        nf = select(g + 3u, 0xffffffffu, g > 0xfffffffcu);
    }
    let rest = len - local;
    if (r_err == DEC_OK && (nf > D.max_faces || (rest < 8192u && nf > rest * 8u) || (nf == 0u && pattern != 0u))) {
        fail(DEC_FACES);
    }
    o.status = r_err;
    o.v_u = v_u;
    o.flags = select(0u, 1u, has_left) | select(0u, 2u, has_right) | select(0u, 4u, swapped);
    o.faces = nf;
    o.crit = crit;
    o.crit_f = crit_values(crit);
    dh_v = v;
    dh_v_end = v_end;
    dh_pos = pos;
    dh_nrm = nrm;
    dh_node = node;
    dh_len = len;
    dh_base = base;
    dh_pattern = pattern;
    dh_first = first;
    dh_has_left = has_left;
    dh_has_right = has_right;
    dh_o = o;
    return o;
}

// The rest of the operation decode_head began (the faces to dec_faces from face slot
// `face_out` on, nowhere for NONE_ADDR): the whole operation, as decode_op decodes it.
fn decode_tail(face_out: u32) -> DecodedOp {
    var o = dh_o;
    let v = dh_v;
    let v_end = dh_v_end;
    let pos = dh_pos;
    let nrm = dh_nrm;
    let node = dh_node;
    let len = dh_len;
    let base = dh_base;
    let pattern = dh_pattern;
    let first = dh_first;
    let has_left = dh_has_left;
    let has_right = dh_has_right;
    let swapped = (o.flags & 4u) != 0u;
    let v_u = o.v_u;
    let nf = o.faces;
    let crit = o.crit;
    let n = D.vertices;
    let max_q = (1u << D.position_bits) - 1u;
    let size = v_end - v;
    var has_prev = false;
    var pt = 0u;
    var pu = 0u;
    var po = 0u;
    for (var i = 0u; i < nf && r_err == DEC_OK; i++) {
        var form: u32;
        if (pattern < 2u && i == 0u) {
            form = pattern;
        } else if (pattern < 2u && i == 1u) {
            form = 1u - pattern;
        } else {
            form = get_groups(T_FACE_FORM);
        }
        var f: vec3<u32>;
        if (form <= 1u) {
            var t = 0u;
            if (v_u - v > 1u) {
                t = get_groups(T_FACE_T + 3u * corner_class(has_prev, pt, v_u - v));
            }
            var u = 0u;
            if (v_end - v_u > 1u) {
                u = get_groups(T_FACE_U + 3u * corner_class(has_prev, pu, v_end - v_u));
            }
            var ov: u32;
            if (!has_prev) {
                ov = get_bucket(T_FACE_OTHER + region_class(size));
            } else {
                let g = get_bucket(T_FACE_OTHER_DELTA + region_class(size));
                ov = po + g;
                if (ov < po) {
                    // Past 2^32: the corner would be outside the FVIDs (fewer than 2^31).
                    fail(DEC_FACES);
                }
            }
            has_prev = true;
            pt = t;
            pu = u;
            po = ov;
            if (r_err != DEC_OK) {
                break;
            }
            var other: u32;
            var other_ok: bool;
            if ((ov & 1u) == 0u) {
                // At or after v_end.
                other_ok = (ov >> 1u) < n - v_end;
                other = v_end + (ov >> 1u);
            } else {
                // Before v.
                let back = (ov >> 1u) + 1u;
                other_ok = back <= v;
                other = v - back;
            }
            if (t >= v_u - v || u >= v_end - v_u || !other_ok) {
                fail(DEC_FACES);
                break;
            }
            if (form == 0u) {
                f = vec3<u32>(v + t, v_u + u, other);
            } else {
                f = vec3<u32>(v_u + u, v + t, other);
            }
        } else if (form == 2u) {
            for (var c = 0u; c < 3u; c++) {
                let s = unzigzag(get_groups(T_FACE_GENERAL));
                var x: u32;
                var ok: bool;
                if (s < 0) {
                    let back = magnitude(s);
                    ok = back <= v;
                    x = v - back;
                } else {
                    x = v + u32(s);
                    ok = x < n;
                }
                if (r_err == DEC_OK && !ok) {
                    fail(DEC_FACES);
                }
                f[c] = x;
            }
            if (r_err != DEC_OK) {
                break;
            }
        } else {
            fail(DEC_FACES);
            break;
        }
        if (face_out != NONE_ADDR) {
            let at = 3u * (face_out + i);
            dec_faces[at] = f.x;
            dec_faces[at + 1u] = f.y;
            dec_faces[at + 2u] = f.z;
        }
    }
    if (r_err != DEC_OK) {
        o.status = r_err;
        return o;
    }

    // 6. the position of v_u: two tangential axes, then the third from the tangent plane.
    var nv = vec3<i32>(0);
    let zero = 1u << D.normal_bits;
    if (!(nrm.x == zero && nrm.y == zero)) {
        let m = i32(zero - 1u);
        let x = 2 * i32(nrm.x) - m;
        let y = 2 * i32(nrm.y) - m;
        let z = m - abs(x) - abs(y);
        if (z >= 0) {
            nv = vec3<i32>(x, y, z);
        } else {
            nv = vec3<i32>((m - abs(y)) * select(-1, 1, x >= 0), (m - abs(x)) * select(-1, 1, y >= 0), z);
        }
    }
    var a = 0u;
    if (abs(nv.y) > abs(nv.x)) {
        a = 1u;
    }
    if (abs(nv.z) > abs(nv[a])) {
        a = 2u;
    }
    var axes = vec3<u32>(0u, 1u, 2u);
    if (a == 0u) {
        axes = vec3<u32>(1u, 2u, 0u);
    } else if (a == 1u) {
        axes = vec3<u32>(0u, 2u, 1u);
    }
    let shift = u32(max(i32(D.normal_bits) - 11, 0));
    let n0 = nv[axes.x] >> shift;
    let n1 = nv[axes.y] >> shift;
    let n2 = nv[axes.z] >> shift;
    let pclass = magnitude_class(crit.w);
    let d0 = unzigzag(get_bucket(T_POS_TANGENT + pclass));
    let d1 = unzigzag(get_bucket(T_POS_TANGENT + pclass));
    let tclass = min(bit_length(min(magnitude(d0), 1u << 27u) + min(magnitude(d1), 1u << 27u)), 27u);
    let r2 = unzigzag(get_bucket(T_POS_NORMAL + tclass));
    if (r_err != DEC_OK) {
        o.status = r_err;
        return o;
    }
    var pred = 0;
    let limit: i32 = 1 << 18u;
    if (n2 != 0 && d0 > -limit && d0 < limit && d1 > -limit && d1 < limit) {
        let num = -(n0 * d0 + n1 * d1);
        let q = i32((magnitude(num) + magnitude(n2) / 2u) / magnitude(n2));
        pred = select(q, -q, (num < 0) != (n2 < 0));
    }
    let hi = i32(max_q);
    let b0 = i32(pos[axes.x]);
    let b1 = i32(pos[axes.y]);
    let b2 = i32(pos[axes.z]) + pred;
    if (!lands_in(b0, d0, hi) || !lands_in(b1, d1, hi) || !lands_in(b2, r2, hi)) {
        o.status = DEC_POSITION;
        return o;
    }
    var p: vec3<u32>;
    p[axes.x] = u32(b0 + d0);
    p[axes.y] = u32(b1 + d1);
    p[axes.z] = u32(b2 + r2);

    // 7. the normal of v_u.
    let nclass = magnitude_class(crit.z);
    var q: vec2<u32>;
    for (var c = 0u; c < 2u; c++) {
        let r = unzigzag(get_bucket(T_NORMAL + nclass));
        if (r_err != DEC_OK) {
            o.status = r_err;
            return o;
        }
        if (!lands_in(i32(nrm[c]), r, i32(zero))) {
            o.status = DEC_NORMAL;
            return o;
        }
        q[c] = u32(i32(nrm[c]) + r);
    }
    if (!valid_oct(q)) {
        o.status = DEC_NORMAL;
        return o;
    }

    // 8. the addresses of the children that split.
    var first_addr = NONE_ADDR;
    var second_addr = NONE_ADDR;
    if (D.nodes == 0u) {
        // In core: the child stored first right after this operation, the second at an offset.
        var offset = 0u;
        if (has_left && has_right) {
            let r = unzigzag(get_groups(T_POINTER + 3u * split_class(first + 2u)));
            if (r_err != DEC_OK) {
                o.status = r_err;
                return o;
            }
            offset = offset_from(pointer_estimate(D.avg_op_size, first), r);
            if (offset < 1u || offset == NONE_ADDR) {
                o.status = DEC_POINTER;
                return o;
            }
        }
        let end = reader_end();
        if ((has_left || has_right) && end >= D.ops_len) {
            o.status = DEC_TRUNCATED;
            return o;
        }
        if (has_left && has_right && offset >= D.ops_len - end) {
            o.status = DEC_POINTER;
            return o;
        }
        first_addr = end;
        second_addr = end + offset;
    } else {
        // Out of core (codec's read_op): per child that splits, its node's distance from this
        // one; in another node its local address there; in this node the first directly after
        // this operation and the second at an offset past the first's part in this node.
        let splitting = select(0u, 1u, has_left) + select(0u, 1u, has_right);
        var here = array<bool, 2>(false, false);
        var at = array<u32, 2>(0u, 0u);
        for (var k = 0u; k < splitting; k++) {
            let delta = get_groups(T_NODE_DELTA + 3u * k);
            if (r_err != DEC_OK) {
                o.status = r_err;
                return o;
            }
            if (delta != 0u) {
                var l = 0u;
                if (k == 1u && !here[0] && (at[0] >> 16u) == node + delta) {
                    // Both in one other node: v_l's part there directly before v_u's.
                    let ls = v_u - v;
                    let r = unzigzag(get_groups(T_POINTER + 3u * split_class(ls + 2u)));
                    if (r_err != DEC_OK) {
                        o.status = r_err;
                        return o;
                    }
                    let part = offset_from(pointer_estimate(D.avg_op_size, ls), r);
                    let fl = at[0] & 0xffffu;
                    if (part == NONE_ADDR || part < 1u || part > 0xffffu || (swapped && part > fl)) {
                        o.status = DEC_POINTER;
                        return o;
                    }
                    l = select(fl + part, fl - part, swapped);
                } else {
                    l = get_bucket(T_LOCAL);
                    if (r_err != DEC_OK) {
                        o.status = r_err;
                        return o;
                    }
                }
                if (delta >= D.nodes - node || l > 0xffffu) {
                    o.status = DEC_POINTER;
                    return o;
                }
                at[k] = ((node + delta) << 16u) | l;
            } else if (k == 0u) {
                here[0] = true;
            } else {
                here[1] = true;
                let est = select(0u, pointer_estimate(D.avg_op_size, first), here[0]);
                let r = unzigzag(get_groups(T_POINTER + 3u * split_class(first + 2u)));
                if (r_err != DEC_OK) {
                    o.status = r_err;
                    return o;
                }
                let off = offset_from(est, r);
                if (off == NONE_ADDR || (here[0] && off < 1u)) {
                    o.status = DEC_POINTER;
                    return o;
                }
                at[1] = off;
            }
        }
        // The offsets in this node count from this operation's end.
        let end = reader_end() - base;
        for (var k = 0u; k < splitting; k++) {
            if (here[k]) {
                if (at[k] >= len - min(end, len)) {
                    o.status = select(DEC_POINTER, DEC_TRUNCATED, k == 0u);
                    return o;
                }
                at[k] = (node << 16u) | (end + at[k]);
            }
        }
        first_addr = at[0];
        second_addr = at[1];
    }
    if (has_left && has_right) {
        o.left = select(first_addr, second_addr, swapped);
        o.right = select(second_addr, first_addr, swapped);
    } else if (has_left) {
        o.left = first_addr;
    } else if (has_right) {
        o.right = first_addr;
    }
    let end = reader_end() - base;
    o.status = DEC_OK;
    o.v_u = v_u;
    o.flags = select(0u, 1u, has_left) | select(0u, 2u, has_right) | select(0u, 4u, swapped);
    o.end = end;
    o.faces = nf;
    o.crit = crit;
    o.crit_f = crit_values(crit);
    o.position = vec4<u32>(p, 0u);
    o.normal = vec4<u32>(q, 0u, 0u);
    return o;
}
