// Shared declarations of the progressive-mesh adaptation stages (worker/src/pm_adapt/).
// Every stage file but scan.wgsl (a generic scan) is compiled with this file prepended; the stages mirror the CPU reference
// codec/src/pm/adapt.rs step for step, and `needs_split` below repeats its refinement test
// operation for operation (no transcendental functions, no dot() or length() builtins whose
// evaluation order the compiler picks), so that both reach the same decisions.

const NONE: u32 = 0xffffffffu;
// Owner of a face removed by this pass's collapses, until the face compaction drops it.
const DEAD: u32 = 0xfffffffeu;
const WG: u32 = 256u;

// Per active vertex: its operation (the split that refines it) with that operation's context
// and criteria, and its creator's (the split whose v_u is this vertex's FVID; the collapse a
// right child performs). The state of codec/src/pm/dpm_adapt.rs: operations are decoded from
// the .dpm's compressed bytes when a vertex gets them, nothing per operation is kept.
struct VState {
    v_end: u32,        // one past the last FVID the vertex stands for
    addr: u32,         // its operation's address, NONE at a leaf
    faces: u32,        // faces its operation makes
    c_addr: u32,       // its creator's address, NONE for a base vertex's FVID
    c_v: u32,          // the creator's vertex: the collapse target's FVID
    c_v_end: u32,      // the creator's range end
    c_faces: u32,      // faces the creator's split made
    flags: u32,        // out of core: PENDING, ABSENT (0 in core)
    pc: vec4<u32>,     // its operation's context: the parent's quantized criteria
    pn: vec4<u32>,     // quantized position and octahedral normal (pack_pn)
    // sin(alpha), geometric error, attribute error, radius
    crit: vec4<f32>,   // its operation's criteria
    c_pc: vec4<u32>,   // the creator's context's parent criteria
    c_crit: vec4<f32>, // the creator's criteria
}

// A vertex's quantized position (at most 24 bits a coordinate) and octahedral normal (at most
// 17 bits a component: normal_bits up to 16 and the zero code 1 << normal_bits) in one vector:
// x, y, z with the normal's 17th bits above x's and y's 24, and the normal's low 16 bits of
// each component in w (a VState of 112 bytes instead of 128).
fn pack_pn(pos: vec3<u32>, nrm: vec2<u32>) -> vec4<u32> {
    return vec4<u32>(pos.x | ((nrm.x >> 16u) << 24u), pos.y | ((nrm.y >> 16u) << 24u), pos.z,
                     (nrm.x & 0xffffu) | (nrm.y << 16u));
}

fn state_pos(s: VState) -> vec3<u32> {
    return vec3<u32>(s.pn.x & 0xffffffu, s.pn.y & 0xffffffu, s.pn.z);
}

fn state_nrm(s: VState) -> vec2<u32> {
    return vec2<u32>((s.pn.w & 0xffffu) | ((s.pn.x >> 24u) << 16u), (s.pn.w >> 16u) | ((s.pn.y >> 24u) << 16u));
}

// The words of a stage's descent queue (descent.wgsl), from Q_COUNT for `count` and
// Q_DESCEND for `descend`: the next of its list to take, the descents paused now, and of the
// finished ones the steps in all (64 bits, low word first) and the most steps of one (what
// the host sizes the rounds by); `count`'s also the leaves, splits and faces its scratch
// area was asked to keep (state.wgsl, place.wgsl).
const Q_NEXT: u32 = 0u;
const Q_PAUSED: u32 = 1u;
const Q_STEPS: u32 = 2u;
const Q_MOST: u32 = 4u;
const Q_SC_LEAVES: u32 = 5u;
const Q_SC_SPLITS: u32 = 6u;
const Q_SC_FACES: u32 = 7u;
const Q_COUNT: u32 = 0u;
const Q_DESCEND: u32 = 8u;

// Where record `r` of the count's scratch area starts (in vectors): from 0, P.sc_leaves leaf
// records of SC_LEAF_VECS vectors, then P.sc_splits split records of SC_SPLIT_VECS.
const SC_LEAF_VECS: u32 = 10u;
const SC_SPLIT_VECS: u32 = 2u;

fn sc_leaf_at(r: u32) -> u32 {
    return r * SC_LEAF_VECS;
}

fn sc_split_at(r: u32) -> u32 {
    return P.sc_leaves * SC_LEAF_VECS + r * SC_SPLIT_VECS;
}

// A vertex state as the seven vectors a record keeps it in (descent.wgsl's resume records,
// state.wgsl's scratch leaves), and back.
fn pack_state(c: VState) -> array<vec4<u32>, 7> {
    return array<vec4<u32>, 7>(vec4<u32>(c.v_end, c.addr, c.faces, c.c_addr), vec4<u32>(c.c_v, c.c_v_end, c.c_faces, c.flags),
                               c.pc, c.pn, bitcast<vec4<u32>>(c.crit), c.c_pc, bitcast<vec4<u32>>(c.c_crit));
}

fn unpack_state(v: array<vec4<u32>, 7>) -> VState {
    return VState(v[0].x, v[0].y, v[0].z, v[0].w, v[1].x, v[1].y, v[1].z, v[1].w, v[2], v[3],
                  bitcast<vec4<f32>>(v[4]), v[5], bitcast<vec4<f32>>(v[6]));
}

// VState.flags, out of core only. PENDING: the operation's node was not resident when the
// vertex got it, so its criteria and face count are not decoded yet (`crit` and `faces` are
// zero); ABSENT: its node is not resident this pass. A vertex with either does not split
// (codec::pm::DpmAdapter's `pending` and `Source::resident`).
const PENDING: u32 = 1u;
const ABSENT: u32 = 2u;

// A vertex's collapse target FVID: its creator's vertex, if it is the creator's right child
// (its range ends where the creator's did); NONE otherwise.
fn target_of(s: VState) -> u32 {
    if (s.c_addr != NONE && s.v_end == s.c_v_end) {
        return s.c_v;
    }
    return NONE;
}

// Vertex `t` made the vertex of the operation `c` carries as its creator (a collapse's target,
// an all-levels region's first vertex): that operation, its context and criteria; `t` keeps
// its own creator, which the FVID it keeps still names. The operation was decoded when it
// split (and needs no node check: a collapse decodes nothing), so no flags.
fn creators_vertex(t: VState, c: VState) -> VState {
    var s = t;
    s.v_end = c.c_v_end;
    s.addr = c.c_addr;
    s.faces = c.c_faces;
    s.pc = c.c_pc;
    s.crit = c.c_crit;
    s.flags = 0u;
    return s;
}

// Per active vertex: its position and unit normal (w unused), what the renderer pulls.
struct Point {
    pos: vec4<f32>,
    nrm: vec4<f32>,
}

struct Params {
    // Frustum planes (left, right, bottom, top, near, far), world-normalised, positive inside.
    planes: array<vec4<f32>, 6>,
    eye: vec4<f32>,
    pixels_per_unit: f32,
    error_px: f32,
    c_lod: f32,
    attribute_scale: f32,
    n: u32,        // active vertices before the pass
    m: u32,        // faces before the pass
    mode: u32,     // 0: the view decides; 1: split every vertex that can split, collapse none;
                   // 2: the view decides collapses, nothing splits (held within a memory budget)
    n_new: u32,    // active vertices after the pass
    f_add: u32,    // faces the splits add
    m_new: u32,    // faces after the pass
    splits: u32,   // splits performed (an all-levels pass: vertices that split)
    levels: u32,   // 1: an all-levels pass (codec::pm::Levels::All), 0: one level
    budget: u32,   // an all-levels pass: the most splits one vertex's descent performs
    stack_slots: u32, // an all-levels pass: the descents' stack slots (descent.wgsl), the
                      // threads of `count` and `descend`
    round_steps: u32, // the most steps a slot takes in one dispatch (a descent resumes in the next)
    rounds: u32,      // the dispatches (rounds) of `count` or `descend` the host runs
    loop_probe: u32,  // 2: the iterations of descent.wgsl's `loops_alive` probe
    sc_leaves: u32,   // an all-levels pass: the leaves, splits and faces the count's scratch
    sc_splits: u32,   // area holds (state.wgsl's `count`, place.wgsl)
    sc_faces: u32,
    // Occlusion, one frame late (state.wgsl's `occluded`): the view-projection of the frame
    // whose depth pyramid `occ` holds, the rectangle of that frame it covers (pixels x0, y0,
    // x1, y1), and the frame's width, height, the finest cell's side in pixels, 1 when on.
    occ_vp: mat4x4<f32>,
    occ_rect: vec4<f32>,
    occ_size: vec4<f32>,
}

// Every stage binds its parameters here.
@group(0) @binding(0) var<storage, read> P: Params;

// Counters the stages accumulate with atomics, read back once per pass.
const STAT_COLLAPSES: u32 = 0u;
const STAT_CANCELLED: u32 = 1u;
const STAT_REMOVED_FACES: u32 = 2u;
const STAT_SPLIT_CURSOR: u32 = 3u;
const STAT_HOLE_CURSOR: u32 = 4u;
const STAT_FILL_CURSOR: u32 = 5u;
const STAT_SPLIT_VERTICES: u32 = 6u;   // an all-levels pass: vertices that split
const STAT_DESCENTS: u32 = 7u;         // an all-levels pass: vertices that descend (listed)

// The linear thread index of a 1D or 2D dispatch of WG-thread workgroups.
fn thread_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * WG;
}

// The refinement test of codec::pm::adapt::needs_split, in the same order of operations.
// (It reads the view from the uniform `P` directly: a copy of the whole block per call, which
// a by-value parameter asks for, made the state update several times slower on lavapipe.)
fn needs_split(center: vec3<f32>, normal: vec3<f32>, crit: vec4<f32>) -> bool {
    let r = crit.w;
    let tx = center.x - P.eye.x;
    let ty = center.y - P.eye.y;
    let tz = center.z - P.eye.z;
    let dist2 = tx * tx + ty * ty + tz * tz;
    let dist = sqrt(dist2);
    let has_normal = normal.x != 0.0 || normal.y != 0.0 || normal.z != 0.0;
    if (dist > r && crit.x < 1.0 && has_normal) {
        let nt = normal.x * tx + normal.y * ty + normal.z * tz;
        if (nt > 0.0) {
            let cx = normal.y * tz - normal.z * ty;
            let cy = normal.z * tx - normal.x * tz;
            let cz = normal.x * ty - normal.y * tx;
            let cos_a = nt / dist;
            let sin_a = sqrt(cx * cx + cy * cy + cz * cz) / dist;
            let sin_al = crit.x;
            let cos_al = sqrt(max(1.0 - sin_al * sin_al, 0.0));
            let sin_b = r / dist;
            let cos_b = sqrt(max(dist2 - r * r, 0.0)) / dist;
            let cos1 = cos_a * cos_al - sin_a * sin_al;
            let sin1 = sin_a * cos_al + cos_a * sin_al;
            if (cos1 > 0.0 && cos1 * cos_b - sin1 * sin_b > 0.0) {
                return false;
            }
        }
    }
    let err = max(crit.y, P.attribute_scale * crit.z);
    if (!(err > 0.0)) {
        return false;
    }
    var outside = 0.0;
    for (var k = 0u; k < 6u; k++) {
        let q = P.planes[k];
        let o = -(q.x * center.x + q.y * center.y + q.z * center.z + q.w) - r;
        outside = max(outside, o);
    }
    let d = max(dist - r, 0.0) + P.c_lod * outside;
    return err * P.pixels_per_unit > P.error_px * d;
}
