// Algorithm 1, vertex state update: per active vertex, 2 (split), 1 (keep) or 0 (collapse)
// into `vcnt`, and the number of faces its split creates into `fcnt`. Thread n writes the
// zero that ends both arrays, so that their exclusive scans end in the totals.
//
// An all-levels pass (codec::pm::Levels::All) runs `mark`, `count` and `regions` instead:
// `mark` marks every done split the view no longer asks for (each is the creator of one
// active vertex, which evaluates it) as a range of positions [p, q) in the sorted buffer, with
// +1 at p and -1 at q - 1 in `diff` (whose exclusive scan then counts, at each position, the
// undone ranges that hold it and start before it), the farthest range end (an FVID) starting
// at p in `reach`, and p + 1 in `up`, and lists the vertices that split; `count` counts each
// listed vertex's leaves and faces down its subtree (descent.wgsl: P.stack_slots threads
// take the listed vertices from a queue; the host reads their number back to size the
// slots), and keeps the leaves and splits it finds in the scratch area for place.wgsl. After the scan of `diff`, `regions` gives a position inside an undone
// range the count 0 (it collapses), the first position of an outermost range (a region) the
// count 1, and records in `root` which vertex carries the region's operation: the one whose
// creator's range is the region's.

@group(0) @binding(1) var<storage, read> vfvid: array<u32>;
@group(0) @binding(2) var<storage, read> vstate: array<VState>;
@group(0) @binding(3) var<storage, read> vpoint: array<Point>;
@group(0) @binding(4) var<storage, read_write> vcnt: array<u32>;
@group(0) @binding(5) var<storage, read_write> fcnt: array<u32>;
// The depth pyramid of occlusion culling: the number of levels, per level its width, height
// and first word, then the levels' cells, the farthest depth (f32 bits) in each.
@group(0) @binding(6) var<storage, read> occ: array<u32>;
// The decoder's buffers are bind group 1 (decode_bindings.wgsl); the descent decodes.
// The all-levels marks (see above), and the counters.
@group(0) @binding(12) var<storage, read_write> diff: array<atomic<u32>>;
@group(0) @binding(13) var<storage, read_write> reach: array<atomic<u32>>;
@group(0) @binding(14) var<storage, read_write> up: array<u32>;
@group(0) @binding(15) var<storage, read_write> root: array<u32>;
@group(0) @binding(16) var<storage, read_write> stats: array<atomic<u32>, 8>;
// The vertices that descend.
@group(0) @binding(17) var<storage, read_write> list: array<u32>;
// The descents' stacks (descent.wgsl).
@group(0) @binding(18) var<storage, read_write> dstack: array<vec4<u32>>;
// The descents' queue (descent.wgsl).
@group(0) @binding(19) var<storage, read_write> queue: array<atomic<u32>, 16>;
// The count's scratch area (`sc_leaf_at`, `sc_split_at` of common.wgsl; `count` binds the
// scratch faces as `dec_faces`).
@group(0) @binding(20) var<storage, read_write> scratch: array<vec4<u32>>;

// Keeps leaf `k` of vertex `i`'s descent in the scratch area, if it has room: (its FVID, i,
// k, 0), its state (7 vectors, as descent_save) and its point (2), for place.wgsl.
fn keep_leaf(i: u32, k: u32) {
    let r = atomicAdd(&queue[Q_COUNT + Q_SC_LEAVES], 1u);
    if (r >= P.sc_leaves) {
        return;
    }
    let at = sc_leaf_at(r);
    let c = pack_state(dc_cur);
    scratch[at] = vec4<u32>(dc_f, i, k, 0u);
    scratch[at + 1u] = c[0];
    scratch[at + 2u] = c[1];
    scratch[at + 3u] = c[2];
    scratch[at + 4u] = c[3];
    scratch[at + 5u] = c[4];
    scratch[at + 6u] = c[5];
    scratch[at + 7u] = c[6];
    scratch[at + 8u] = bitcast<vec4<u32>>(dc_pt.pos);
    scratch[at + 9u] = bitcast<vec4<u32>>(dc_pt.nrm);
}

// Keeps the split just done in vertex `i`'s descent: (i, its first face's index in the
// descent, the faces' owner v_u, their number), (where its faces are in the scratch faces,
// NONE_ADDR if they did not fit, 0, 0, 0).
fn keep_split(i: u32) {
    let r = atomicAdd(&queue[Q_COUNT + Q_SC_SPLITS], 1u);
    if (r >= P.sc_splits) {
        return;
    }
    let at = sc_split_at(r);
    scratch[at] = vec4<u32>(i, dc_faces - dc_last_faces, dc_last_vu, dc_last_faces);
    scratch[at + 1u] = vec4<u32>(dc_last_base, 0u, 0u, 0u);
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    let n = P.n;
    if (i > n) {
        return;
    }
    if (i == n) {
        vcnt[n] = 0u;
        fcnt[n] = 0u;
        return;
    }
    let f = vfvid[i];
    let s = vstate[i];
    var state = 1u;
    var faces = 0u;
    if (splits_now(s, vpoint[i])) {
        state = 2u;
        faces = s.faces;
    } else if (P.mode != 1u) {
        let t = target_of(s);
        if (t != NONE && i > 0u && vfvid[i - 1u] == t && (i + 1u == n || target_of(vstate[i + 1u]) != f)) {
            // The collapse's criteria are the creator's; its vertex is the target, the
            // previous one.
            if (!wants_split(vpoint[i - 1u].pos.xyz, vpoint[i - 1u].nrm.xyz, s.c_crit)) {
                state = 0u;
            }
        }
    }
    vcnt[i] = state;
    fcnt[i] = faces;
}

@compute @workgroup_size(256)
fn mark(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    let n = P.n;
    if (i > n) {
        return;
    }
    if (i == n) {
        vcnt[n] = 0u;
        fcnt[n] = 0u;
        return;
    }
    let s = vstate[i];
    var mark = 0u;
    if (P.mode != 1u && s.c_addr != NONE) {
        // The creator's centre is its vertex's, the first of its range.
        let p = min(lower_bound(s.c_v, n), n - 1u);
        if (!wants_split(vpoint[p].pos.xyz, vpoint[p].nrm.xyz, s.c_crit)) {
            let q = max(lower_bound(s.c_v_end, n), 1u);
            atomicAdd(&diff[p], 1u);
            atomicSub(&diff[q - 1u], 1u);
            atomicMax(&reach[p], s.c_v_end);
            mark = p + 1u;
        }
    }
    up[i] = mark;
    vcnt[i] = 1u;
    fcnt[i] = 0u;
    // A vertex that splits descends in `count`, one thread per such vertex.
    if (splits_now(s, vpoint[i])) {
        list[atomicAdd(&stats[STAT_DESCENTS], 1u)] = i;
    }
}

@compute @workgroup_size(256)
fn count(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let t = thread_index(gid, groups);
    if (t >= P.stack_slots) {
        return;
    }
    let total = atomicLoad(&stats[STAT_DESCENTS]);
    dc_scratch = true;
    var i = descent_round(t, Q_COUNT);
    if (i != NONE) {
        descent_resume(NONE_ADDR);
    }
    loop {
        if (i == NONE) {
            i = descent_take(total);
            if (i == NONE) {
                break;
            }
            descent_start(i, vstate[i], vfvid[i], vpoint[i], NONE_ADDR);
        }
        var finished = false;
        loop {
            if (!descent_may_step()) {
                break;
            }
            let step = descent_step();
            if (step == STEP_SPLIT) {
                keep_split(i);
            }
            if (step != STEP_LEAF) {
                continue;
            }
            keep_leaf(i, dc_leaves);
            dc_leaves += 1u;
            if (!descent_pop()) {
                finished = true;
                break;
            }
        }
        if (!descent_end(finished, vstate[i].addr)) {
            break;
        }
        vcnt[i] = dc_leaves;
        fcnt[i] = dc_faces;
        i = NONE;
    }
}

@compute @workgroup_size(256)
fn regions(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread_index(gid, groups);
    if (k >= P.n) {
        return;
    }
    var c = vcnt[k];
    if (atomicLoad(&diff[k]) != 0u) {
        // Inside an undone range that starts before it: it collapses, and its creator (undone)
        // takes its faces.
        c = 0u;
        atomicAdd(&stats[STAT_COLLAPSES], 1u);
        atomicAdd(&stats[STAT_REMOVED_FACES], vstate[k].c_faces);
    } else if (atomicLoad(&reach[k]) != 0u) {
        c = 1u; // a region's first vertex: it becomes the region's vertex
    }
    if (c != vcnt[k]) {
        vcnt[k] = c;
        fcnt[k] = 0u;
    }
    if (c >= 2u) {
        atomicAdd(&stats[STAT_SPLIT_VERTICES], 1u);
    }
    let u = up[k];
    if (u != 0u) {
        let p = u - 1u;
        if (atomicLoad(&diff[p]) == 0u && atomicLoad(&reach[p]) == vstate[k].c_v_end) {
            root[p] = k + 1u;
        }
    }
}
