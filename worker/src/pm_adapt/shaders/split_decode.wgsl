// Algorithm 3's splits (`main`, a one-level pass): one thread per splitting vertex (the compacted list) decodes its
// operation from the .dpm's bytes (the decoder, decode.wgsl, is prepended to this file) and
// writes its two children to their slots of the new vertex buffers, v at the vertex's slot
// and v_u right after it (v_u's FVID follows v's left range), each with its operation's
// criteria and face count decoded, so that the new FVID buffer is complete before the split
// stage searches it. The split's faces go, as FVIDs, to their slots of the face FVID buffer
// (`dec_faces`), from the face prefix sum `fsum`, for the split stage to index. It is a stage
// of its own, apart from the reorganisation's copies, so that decoding threads run together
// and the copies stay plain loads and stores.

@group(0) @binding(1) var<storage, read> vfvid: array<u32>;
@group(0) @binding(2) var<storage, read> vstate: array<VState>;
@group(0) @binding(3) var<storage, read> vpoint: array<Point>;
@group(0) @binding(4) var<storage, read> vsum: array<u32>;
@group(0) @binding(5) var<storage, read> fsum: array<u32>;
@group(0) @binding(6) var<storage, read> list: array<u32>;
@group(0) @binding(7) var<storage, read_write> dfvid: array<u32>;
@group(0) @binding(8) var<storage, read_write> dstate: array<VState>;
@group(0) @binding(9) var<storage, read_write> dpoint: array<Point>;
// An all-levels pass (`descend`): the view's occlusion test, and the new faces' owners.
@group(0) @binding(15) var<storage, read> occ: array<u32>;
@group(0) @binding(16) var<storage, read_write> face_owner: array<u32>;
// The descents' stacks (descent.wgsl).
@group(0) @binding(17) var<storage, read_write> dstack: array<vec4<u32>>;
// The descents' queue (descent.wgsl).
@group(0) @binding(18) var<storage, read_write> queue: array<atomic<u32>, 16>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread_index(gid, groups);
    if (k >= P.splits) {
        return;
    }
    let i = list[k];
    let j = vsum[i];
    let f = vfvid[i];
    let s = vstate[i];
    let o = decode_op(s.addr, f, s.v_end, s.pc, state_pos(s), state_nrm(s), P.m + fsum[i], DECODE_ALL);
    if (o.status != DEC_OK) {
        // The pass fails (the host reads the error); the slots get harmless copies.
        report(o.status, s.addr);
        dfvid[j] = f;
        dstate[j] = s;
        dpoint[j] = vpoint[i];
        dfvid[j + 1u] = f;
        dstate[j + 1u] = s;
        dpoint[j + 1u] = vpoint[i];
        return;
    }
    var l = s;
    l.flags = 0u;
    l.v_end = o.v_u;
    l.addr = o.left;
    l.pc = o.crit;
    with_op(&l, f);
    var r: VState;
    r.v_end = s.v_end;
    r.addr = o.right;
    r.pc = o.crit;
    r.pn = pack_pn(o.position.xyz, o.normal.xy);
    r.c_addr = s.addr;
    r.c_v = f;
    r.c_v_end = s.v_end;
    r.c_faces = o.faces;
    r.c_pc = s.pc;
    r.c_crit = s.crit;
    with_op(&r, o.v_u);
    dfvid[j] = f;
    dstate[j] = l;
    dpoint[j] = vpoint[i];
    dfvid[j + 1u] = o.v_u;
    dstate[j + 1u] = r;
    dpoint[j + 1u] = Point(vec4<f32>(dequantize(o.position.xyz), 1.0), vec4<f32>(oct_decode(o.normal.xy), 0.0));
}

// An all-levels pass's splits (codec::pm::Levels::All) where the count's scratch area could
// not hold what it found (else place.wgsl copies that): each splitting vertex, taken from a
// queue by one of P.stack_slots threads, walks its subtree again as the state update counted
// it (descent.wgsl), writing the leaves to the vertex's slots in FVID order and the faces of
// every split done to its face slots, each owned by its split's v_u; the split stage's
// `index_new` then indexes them.
@compute @workgroup_size(256)
fn descend(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let t = thread_index(gid, groups);
    if (t >= P.stack_slots) {
        return;
    }
    var i = descent_round(t, Q_DESCEND);
    if (i != NONE) {
        descent_resume(P.m + fsum[i]);
    }
    loop {
        if (i == NONE) {
            i = descent_take(P.splits);
            if (i == NONE) {
                break;
            }
            descent_start(i, vstate[i], vfvid[i], vpoint[i], P.m + fsum[i]);
        }
        let j = vsum[i];
        let count = vsum[i + 1u] - j;
        var finished = false;
        loop {
            if (!descent_may_step()) {
                break;
            }
            let step = descent_step();
            if (step == STEP_SPLIT) {
                for (var e = dc_faces - dc_last_faces; e < dc_faces; e++) {
                    face_owner[dc_face_out + e] = dc_last_vu;
                }
            }
            if (step != STEP_LEAF) {
                continue;
            }
            // Counted alike by the state update; the bound only keeps a fault in its slots.
            if (dc_leaves < count) {
                dfvid[j + dc_leaves] = dc_f;
                dstate[j + dc_leaves] = dc_cur;
                dpoint[j + dc_leaves] = dc_pt;
            }
            dc_leaves += 1u;
            if (!descent_pop()) {
                finished = true;
                break;
            }
        }
        if (!descent_end(finished, vstate[i].addr)) {
            break;
        }
        i = NONE;
    }
}
