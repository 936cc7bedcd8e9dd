// What the state update and the split decoding share (prepended after vertex_op.wgsl): the
// view test with occlusion, a vertex's point, and the descent of an all-levels pass
// (codec::pm::Levels::All): from a splitting vertex down its subtree of splits while the view
// asks, at most LEVELS_PER_PASS levels, depth first and left before right (FVID order), as
// codec::pm::DpmAdapter's stack goes. The state update walks it to count a vertex's leaves
// and faces, the split decoding walks it again to write them: both make the same decisions
// from the same data. A file that includes this declares `occ`, the depth pyramid.

// Whether a bounding sphere was hidden in the frame of the depth pyramid (the paper's
// occlusion culling one frame late, here of vertices' spheres): its box projected with that
// frame's view-projection lies inside the pyramid's rectangle and behind the farthest depth
// of every cell it covers, at the level where it spans at most two cells a side. A sphere
// that reaches behind the eye or past the rectangle is not occluded.
fn occluded(center: vec3<f32>, r: f32) -> bool {
    if (P.occ_size.w == 0.0) {
        return false;
    }
    var lo = vec2<f32>(3.0e38);
    var hi = vec2<f32>(-3.0e38);
    var zmin = 3.0e38;
    for (var k = 0u; k < 8u; k++) {
        let c = center + vec3<f32>(select(-r, r, (k & 1u) != 0u), select(-r, r, (k & 2u) != 0u),
                                   select(-r, r, (k & 4u) != 0u));
        let q = P.occ_vp * vec4<f32>(c, 1.0);
        if (q.w <= 0.0) {
            return false;
        }
        lo = min(lo, q.xy / q.w);
        hi = max(hi, q.xy / q.w);
        zmin = min(zmin, q.z / q.w);
    }
    if (zmin <= 0.0) {
        return false;
    }
    let x0 = (lo.x + 1.0) * 0.5 * P.occ_size.x;
    let x1 = (hi.x + 1.0) * 0.5 * P.occ_size.x;
    let y0 = (1.0 - hi.y) * 0.5 * P.occ_size.y;
    let y1 = (1.0 - lo.y) * 0.5 * P.occ_size.y;
    if (x0 < P.occ_rect.x || y0 < P.occ_rect.y || x1 > P.occ_rect.z || y1 > P.occ_rect.w) {
        return false;
    }
    let levels = occ[0];
    var level = 0u;
    var side = P.occ_size.z;
    while (level + 1u < levels && max(x1 - x0, y1 - y0) > side) {
        level++;
        side *= 2.0;
    }
    let w = occ[1u + 3u * level];
    let h = occ[2u + 3u * level];
    let at = occ[3u + 3u * level];
    let cx0 = min(u32((x0 - P.occ_rect.x) / side), w - 1u);
    let cx1 = min(u32((x1 - P.occ_rect.x) / side), w - 1u);
    let cy0 = min(u32((y0 - P.occ_rect.y) / side), h - 1u);
    let cy1 = min(u32((y1 - P.occ_rect.y) / side), h - 1u);
    var far = 0.0;
    for (var cy = cy0; cy <= cy1; cy++) {
        for (var cx = cx0; cx <= cx1; cx++) {
            far = max(far, bitcast<f32>(occ[at + cy * w + cx]));
        }
    }
    return zmin > far;
}

// The refinement test, and not hidden (occlusion culling on).
fn wants_split(center: vec3<f32>, normal: vec3<f32>, crit: vec4<f32>) -> bool {
    return needs_split(center, normal, crit) && !occluded(center, crit.w);
}

// The position of a quantized one, as the CPU decoder computes it.
fn dequantize(q: vec3<u32>) -> vec3<f32> {
    return vec3<f32>(D.grid.x + f32(q.x) * D.grid.w, D.grid.y + f32(q.y) * D.grid.w, D.grid.z + f32(q.z) * D.grid.w);
}

// The unit normal (or zero) of an octahedral code, as the CPU decoder computes it.
fn oct_decode(q: vec2<u32>) -> vec3<f32> {
    let zero = 1u << D.normal_bits;
    if (q.x == zero && q.y == zero) {
        return vec3<f32>(0.0);
    }
    let m = f32(zero - 1u);
    var x = f32(q.x) / m * 2.0 - 1.0;
    var y = f32(q.y) / m * 2.0 - 1.0;
    let z = 1.0 - abs(x) - abs(y);
    if (z < 0.0) {
        let ox = x;
        let oy = y;
        x = (1.0 - abs(oy)) * select(-1.0, 1.0, ox >= 0.0);
        y = (1.0 - abs(ox)) * select(-1.0, 1.0, oy >= 0.0);
    }
    let l = sqrt(x * x + y * y + z * z);
    return vec3<f32>(x / l, y / l, z / l);
}

// Whether a vertex with state `s` at point `pt` splits this pass: an operation, decoded and
// resident (no flags), that the view asks for; any in mode 1; none in mode 2.
fn splits_now(s: VState, pt: Point) -> bool {
    return s.addr != NONE && s.flags == 0u && P.mode != 2u
        && (P.mode == 1u || wants_split(pt.pos.xyz, pt.nrm.xyz, s.crit));
}

// The point of a vertex from its quantized position and normal.
fn point_of(s: VState) -> Point {
    return Point(vec4<f32>(dequantize(state_pos(s)), 1.0), vec4<f32>(oct_decode(state_nrm(s)), 0.0));
}

// A descent in progress, per invocation: the current vertex (its state, FVID, point and depth
// below the start, and whether its own operation's criteria and face count are still to be
// decoded), the right children still to visit (at most one per level), the leaves visited and
// the faces of the splits done, which go to `dec_faces` from `dc_face_out` (NONE_ADDR: counted
// only); `dc_last_vu` and `dc_last_faces` describe the split just done.
//
// The right children wait in `dstack` (a storage buffer the including file declares), in the
// invocation's slot `dc_slot` of P.stack_slots: STACK_WORDS / 4 vectors an entry, entry e's
// vector q of slot t at ((e * STACK_WORDS / 4 + q) * P.stack_slots + t), so that neighbouring
// invocations touch neighbouring vectors. A slot holds min(LEVELS_PER_PASS, P.budget) entries
// (a descent pushes one per split). Not in indexed private arrays: llvmpipe (lavapipe)
// compiles those slower (an adapter's first all-levels passes 8.6 s against 5.1 s), and a
// hardware driver reserves their memory for every thread it can run at once.
//
// `descent_step` calls each half of the decoder once, so that each is inlined once.
// llvmpipe (lavapipe) stops every loop of an invocation after 65535 iterations in all,
// silently (as it counts them a step takes up to 256-512; `loops_alive` checks that it did
// not happen): there a slot pauses its descent after P.round_steps steps and the next
// dispatch goes on with it (the resume record).
var<private> dc_cur: VState;
var<private> dc_f: u32;
var<private> dc_pt: Point;
var<private> dc_depth: u32;
var<private> dc_uncached: bool;
var<private> dc_slot: u32;
var<private> dc_rounds: u32;
var<private> dc_steps: u32;
var<private> dc_sp: u32;
var<private> dc_splits: u32;
var<private> dc_leaves: u32;
var<private> dc_faces: u32;
var<private> dc_face_out: u32;
var<private> dc_last_vu: u32;
var<private> dc_last_faces: u32;
var<private> dc_vertex: u32;
var<private> dc_q: u32;
var<private> dc_dsteps: u32;
// `count` keeps what it finds (state.wgsl): a split's faces go to the scratch faces from
// `dc_last_base` (NONE_ADDR where they did not fit).
var<private> dc_scratch: bool;
var<private> dc_last_base: u32;

// An entry of the stack, STACK_WORDS / 4 vectors: (the right child's FVID, depth, range end,
// operation address), its context, (its quantized position xyz, its creator's address),
// (its octahedral normal xy, its creator's vertex and face count), the creator's context,
// the creator's criteria (f32 bits).
const STACK_WORDS: u32 = 24u;

fn sk_at(e: u32, q: u32) -> u32 {
    return (e * (STACK_WORDS / 4u) + q) * P.stack_slots + dc_slot;
}

// After the stacks, a record per slot (RESUME_VECS vectors, vector q of slot t at
// resume_base() + q * P.stack_slots + t): (1: a descent paused in it, else 0; the rounds the
// slot ran, sp, depth), (FVID, splits, leaves, faces), (uncached, the descent's vertex, its
// steps so far, 0), the current vertex's state (7 vectors) and point (2). A slot that reaches
// P.round_steps steps in a round saves its descent there and the next round (dispatch) goes
// on with it, so that no invocation runs past llvmpipe's loop limit however long its descents.
const RESUME_VECS: u32 = 12u;

fn resume_at(q: u32) -> u32 {
    let entries = min(LEVELS_PER_PASS, P.budget);
    return P.stack_slots * (entries * (STACK_WORDS / 4u) + q) + dc_slot;
}

// The descents of a stage form a queue (in `queue`, which the including file declares, from
// word `dc_q`; the Q_* words of common.wgsl). A slot takes the next descent whenever it
// finished one, so that its lanes stay busy however unequal the descents (on lavapipe eight
// lanes wait for the longest of theirs, on a GPU a warp's 32).

// Saves the descent paused at the step cap for the next round.
fn descent_save() {
    dstack[resume_at(0u)] = vec4<u32>(1u, dc_rounds, dc_sp, dc_depth);
    dstack[resume_at(1u)] = vec4<u32>(dc_f, dc_splits, dc_leaves, dc_faces);
    dstack[resume_at(2u)] = vec4<u32>(select(0u, 1u, dc_uncached), dc_vertex, dc_dsteps, 0u);
    let c = pack_state(dc_cur);
    dstack[resume_at(3u)] = c[0];
    dstack[resume_at(4u)] = c[1];
    dstack[resume_at(5u)] = c[2];
    dstack[resume_at(6u)] = c[3];
    dstack[resume_at(7u)] = c[4];
    dstack[resume_at(8u)] = c[5];
    dstack[resume_at(9u)] = c[6];
    dstack[resume_at(10u)] = bitcast<vec4<u32>>(dc_pt.pos);
    dstack[resume_at(11u)] = bitcast<vec4<u32>>(dc_pt.nrm);
    atomicAdd(&queue[dc_q + Q_PAUSED], 1u);
}

// A round of slot `slot` of the stage whose queue starts at word `q`: counts the round, and
// returns the vertex of the descent the last round paused in the slot (NONE if none), which
// the caller resumes with `descent_resume`.
fn descent_round(slot: u32, q: u32) -> u32 {
    dc_slot = slot;
    dc_q = q;
    dc_steps = 0u;
    let r0 = dstack[resume_at(0u)];
    dc_rounds = r0.y + 1u;
    dstack[resume_at(0u)] = vec4<u32>(0u, dc_rounds, r0.zw);
    if (r0.x != 1u) {
        return NONE;
    }
    atomicSub(&queue[q + Q_PAUSED], 1u);
    return dstack[resume_at(2u)].y;
}

// Goes on with the descent the last round paused in the slot, writing to `face_out`.
fn descent_resume(face_out: u32) {
    let r0 = dstack[resume_at(0u)];
    let r1 = dstack[resume_at(1u)];
    let r2 = dstack[resume_at(2u)];
    dc_sp = r0.z;
    dc_depth = r0.w;
    dc_f = r1.x;
    dc_splits = r1.y;
    dc_leaves = r1.z;
    dc_faces = r1.w;
    dc_uncached = r2.x != 0u;
    dc_vertex = r2.y;
    dc_dsteps = r2.z;
    dc_cur = unpack_state(array<vec4<u32>, 7>(dstack[resume_at(3u)], dstack[resume_at(4u)], dstack[resume_at(5u)],
                                              dstack[resume_at(6u)], dstack[resume_at(7u)], dstack[resume_at(8u)],
                                              dstack[resume_at(9u)]));
    dc_pt = Point(bitcast<vec4<f32>>(dstack[resume_at(10u)]), bitcast<vec4<f32>>(dstack[resume_at(11u)]));
    dc_face_out = face_out;
}

// The vertex of the next descent of the queue, of `list`'s first `total`; NONE when all are
// taken or the slot's steps of this round are spent (the caller then starts it).
fn descent_take(total: u32) -> u32 {
    if (dc_steps == P.round_steps) {
        return NONE;
    }
    let k = atomicAdd(&queue[dc_q + Q_NEXT], 1u);
    if (k >= total) {
        return NONE;
    }
    return list[k];
}

// Whether llvmpipe's loop limit has not been reached: it ends every loop of an invocation,
// silently, once 65535 iterations ran in all (counted from the start of the outermost loop
// running, a nested loop's iterations included), and every loop after that runs its body
// once. So a loop of P.loop_probe (2) iterations, a number the compiler cannot know, runs
// both unless the limit was reached, maybe in the middle of a decode (whose values are then
// wrong).
fn loops_alive() -> bool {
    var k = 0u;
    loop {
        k += 1u;
        if (k >= P.loop_probe) {
            break;
        }
    }
    return k == P.loop_probe;
}

// Reports a decoding failure, as the loop limit where llvmpipe's was reached (the decoder's
// loops then ended early, and what it found wrong follows from that).
fn descent_report(status: u32, addr: u32) {
    report(select(DEC_LOOP_LIMIT, status, loops_alive()), addr);
}

// Whether the descent may take another step this round (counted): not past the round's
// steps, and the last step ran whole (else the caller's `descent_end` fails the pass).
fn descent_may_step() -> bool {
    if (dc_steps == P.round_steps || !loops_alive()) {
        return false;
    }
    dc_steps += 1u;
    dc_dsteps += 1u;
    return true;
}

// After a descent's loop, `finished` when it left by its one exit (no right child left):
// counts its steps in the queue and returns true. At the step cap it pauses for the next
// round instead (false: nothing to write yet), unless this is the last round the host runs
// (P.rounds). Otherwise the GPU ended the loop, or llvmpipe's loop limit was reached
// (`loops_alive`). Those fail the pass (DEC_LOOP_LIMIT at `addr`) instead of a wrong result,
// and end the slot's round.
fn descent_end(finished: bool, addr: u32) -> bool {
    if (!loops_alive()) {
        report(DEC_LOOP_LIMIT, addr);
        return false;
    }
    if (!finished) {
        if (dc_steps == P.round_steps && dc_rounds < P.rounds) {
            descent_save();
            return false;
        }
        report(DEC_LOOP_LIMIT, addr);
        return false;
    }
    let before = atomicAdd(&queue[dc_q + Q_STEPS], dc_dsteps);
    if (before + dc_dsteps < before) {
        atomicAdd(&queue[dc_q + Q_STEPS + 1u], 1u);
    }
    atomicMax(&queue[dc_q + Q_MOST], dc_dsteps);
    return true;
}

// Starts the descent of vertex `i` from its state `s` (FVID `f`, point `pt`, faces to
// `face_out`) in the slot of this round.
fn descent_start(i: u32, s: VState, f: u32, pt: Point, face_out: u32) {
    dc_vertex = i;
    dc_cur = s;
    dc_f = f;
    dc_pt = pt;
    dc_depth = 0u;
    dc_uncached = false;
    dc_sp = 0u;
    dc_splits = 0u;
    dc_leaves = 0u;
    dc_faces = 0u;
    dc_face_out = face_out;
    dc_dsteps = 0u;
}

// What one step of a descent did.
const STEP_SPLIT: u32 = 1u;  // split the current vertex (its left child is current now)
const STEP_LEAF: u32 = 2u;   // the current vertex is a leaf: the caller takes it, then pops

// One step, one vertex visited: decodes the head of its operation (criteria, children, face
// count) and, if the vertex's split cache is not yet made, makes it from the head (as
// vertex_op.wgsl's `with_op`); then splits it if it splits (an operation, decoded and
// resident, that the view asks for; any in mode 1; none in mode 2; within LEVELS_PER_PASS
// levels and P.budget splits) as split_decode.wgsl's `main` splits one, decoding the rest of
// the operation from where the head stopped: the right child waits on the stack, the left one
// becomes current (it keeps the point). A leaf where it does not split, or its operation fails
// to decode (reported: the pass fails). Head and rest in one step: each operation's head is
// decoded once, and a step's lanes all decode (lanes waited for each other's other kind of
// step when the split cache and the split were steps of their own).
fn descent_step() -> u32 {
    let s0 = dc_cur;
    let f = dc_f;
    var h: DecodedOp;
    if (s0.addr != NONE) {
        h = decode_head(s0.addr, f, s0.v_end, s0.pc, state_pos(s0), state_nrm(s0));
    }
    if (dc_uncached) {
        dc_uncached = false;
        dc_cur.faces = 0u;
        dc_cur.crit = vec4<f32>(0.0);
        dc_cur.flags = 0u;
        if (s0.addr != NONE) {
            if (h.status == DEC_ABSENT) {
                dc_cur.flags = PENDING;
            } else if (h.status != DEC_OK) {
                descent_report(h.status, s0.addr);
            } else {
                dc_cur.faces = h.faces;
                dc_cur.crit = bitcast<vec4<f32>>(h.crit_f);
            }
        }
    }
    let s = dc_cur;
    if (!(dc_splits < P.budget && dc_depth < LEVELS_PER_PASS && splits_now(s, dc_pt))) {
        return STEP_LEAF;
    }
    if (h.status != DEC_OK) {
        descent_report(h.status, s.addr);
        return STEP_LEAF;
    }
    var out = NONE_ADDR;
    if (dc_scratch) {
        let base = atomicAdd(&queue[dc_q + Q_SC_FACES], h.faces);
        out = select(NONE_ADDR, base, base <= P.sc_faces && h.faces <= P.sc_faces - base);
        dc_last_base = out;
    } else if (dc_face_out != NONE_ADDR) {
        out = dc_face_out + dc_faces;
    }
    let o = decode_tail(out);
    if (o.status != DEC_OK) {
        descent_report(o.status, s.addr);
        return STEP_LEAF;
    }
    dc_splits += 1u;
    let sp = dc_sp;
    dstack[sk_at(sp, 0u)] = vec4<u32>(o.v_u, dc_depth + 1u, s.v_end, o.right);
    dstack[sk_at(sp, 1u)] = o.crit;
    dstack[sk_at(sp, 2u)] = vec4<u32>(o.position.xyz, s.addr);
    dstack[sk_at(sp, 3u)] = vec4<u32>(o.normal.xy, f, o.faces);
    dstack[sk_at(sp, 4u)] = s.pc;
    dstack[sk_at(sp, 5u)] = bitcast<vec4<u32>>(s.crit);
    dc_sp = sp + 1u;
    var l = s;
    l.v_end = o.v_u;
    l.addr = o.left;
    l.pc = o.crit;
    dc_cur = l;
    dc_uncached = true;
    dc_depth += 1u;
    dc_last_vu = o.v_u;
    dc_last_faces = o.faces;
    dc_faces += o.faces;
    return STEP_SPLIT;
}

// After a leaf: the next right child waiting becomes current (its split cache still to be
// decoded), as split_decode.wgsl's `main` makes a right child; false when none is left.
fn descent_pop() -> bool {
    if (dc_sp == 0u) {
        return false;
    }
    let sp = dc_sp - 1u;
    dc_sp = sp;
    let q0 = dstack[sk_at(sp, 0u)];
    let q2 = dstack[sk_at(sp, 2u)];
    let q3 = dstack[sk_at(sp, 3u)];
    var r: VState;
    r.v_end = q0.z;
    r.addr = q0.w;
    r.pc = dstack[sk_at(sp, 1u)];
    r.pn = pack_pn(q2.xyz, q3.xy);
    r.c_addr = q2.w;
    r.c_v = q3.z;
    r.c_v_end = r.v_end;
    r.c_faces = q3.w;
    r.c_pc = dstack[sk_at(sp, 4u)];
    r.c_crit = bitcast<vec4<f32>>(dstack[sk_at(sp, 5u)]);
    dc_cur = r;
    dc_f = q0.x;
    dc_depth = q0.y;
    dc_pt = point_of(r);
    dc_uncached = true;
    return true;
}

// The index of the first of the `n` old active vertices whose FVID is >= f (n if none).
fn lower_bound(f: u32, n: u32) -> u32 {
    var lo = 0u;
    var hi = n;
    while (lo < hi) {
        let mid = (lo + hi) >> 1u;
        if (vfvid[mid] < f) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return lo;
}
