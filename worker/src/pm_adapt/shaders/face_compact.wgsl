// Section 5.6, in-place compaction of the face buffers (order not kept, as in [DMG10a]):
// after the pass the live faces number m_new; `holes` lists the DEAD slots below m_new, and
// `fill` moves each live face at or above m_new into one of them. The two counts are equal,
// so the first m_new slots end up exactly the live faces, without a second buffer.

@group(0) @binding(1) var<storage, read_write> face_idx: array<u32>;
@group(0) @binding(2) var<storage, read_write> face_fvid: array<u32>;
@group(0) @binding(3) var<storage, read_write> face_owner: array<u32>;
@group(0) @binding(4) var<storage, read_write> hole: array<u32>;
@group(0) @binding(5) var<storage, read_write> stats: array<atomic<u32>, 8>;

@compute @workgroup_size(256)
fn holes(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread_index(gid, groups);
    if (k >= P.m_new || face_owner[k] != DEAD) {
        return;
    }
    hole[atomicAdd(&stats[STAT_HOLE_CURSOR], 1u)] = k;
}

@compute @workgroup_size(256)
fn fill(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = P.m_new + thread_index(gid, groups);
    if (k >= P.m + P.f_add || face_owner[k] == DEAD) {
        return;
    }
    let dst = hole[atomicAdd(&stats[STAT_FILL_CURSOR], 1u)];
    for (var c = 0u; c < 3u; c++) {
        face_idx[3u * dst + c] = face_idx[3u * k + c];
        face_fvid[3u * dst + c] = face_fvid[3u * k + c];
    }
    face_owner[dst] = face_owner[k];
}
