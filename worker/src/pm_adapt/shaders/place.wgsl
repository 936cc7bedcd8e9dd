// An all-levels pass's splits from what `count` kept (state.wgsl's scratch area) instead of
// walking the descents again (split_decode.wgsl's `descend`): `place_leaves` copies each kept
// leaf to its vertex's slots of the new vertex buffers, `place_splits` each kept split's faces
// to their vertex's face slots, each owned by its split's v_u. A vertex that no longer splits
// after the regions (its count below 2) is skipped. The host runs these only where every
// leaf, split and face fitted in the scratch area.

@group(0) @binding(1) var<storage, read> vsum: array<u32>;
@group(0) @binding(2) var<storage, read> fsum: array<u32>;
@group(0) @binding(3) var<storage, read_write> dfvid: array<u32>;
@group(0) @binding(4) var<storage, read_write> dstate: array<VState>;
@group(0) @binding(5) var<storage, read_write> dpoint: array<Point>;
@group(0) @binding(6) var<storage, read_write> dec_faces: array<u32>;
@group(0) @binding(7) var<storage, read_write> face_owner: array<u32>;
@group(0) @binding(8) var<storage, read> scratch: array<vec4<u32>>;
@group(0) @binding(9) var<storage, read> sc_faces: array<u32>;
// The leaves and splits kept (the count's queue words Q_SC_LEAVES and Q_SC_SPLITS; more than
// the scratch area holds only where the host runs `descend` instead).
@group(0) @binding(10) var<storage, read> queue: array<u32, 16>;

@compute @workgroup_size(256)
fn place_leaves(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let r = thread_index(gid, groups);
    if (r >= min(queue[Q_COUNT + Q_SC_LEAVES], P.sc_leaves)) {
        return;
    }
    let at = sc_leaf_at(r);
    let m = scratch[at];
    let i = m.y;
    let j = vsum[i];
    let count = vsum[i + 1u] - j;
    if (count < 2u || m.z >= count) {
        return;
    }
    let c = unpack_state(array<vec4<u32>, 7>(scratch[at + 1u], scratch[at + 2u], scratch[at + 3u], scratch[at + 4u],
                                             scratch[at + 5u], scratch[at + 6u], scratch[at + 7u]));
    dfvid[j + m.z] = m.x;
    dstate[j + m.z] = c;
    dpoint[j + m.z] = Point(bitcast<vec4<f32>>(scratch[at + 8u]), bitcast<vec4<f32>>(scratch[at + 9u]));
}

@compute @workgroup_size(256)
fn place_splits(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let r = thread_index(gid, groups);
    if (r >= min(queue[Q_COUNT + Q_SC_SPLITS], P.sc_splits)) {
        return;
    }
    let at = sc_split_at(r);
    let m = scratch[at];
    let base = scratch[at + 1u].x;
    let i = m.x;
    if (vsum[i + 1u] - vsum[i] < 2u || base == NONE) {
        return;
    }
    let out = P.m + fsum[i] + m.y;
    for (var e = 0u; e < m.w; e++) {
        dec_faces[3u * (out + e)] = sc_faces[3u * (base + e)];
        dec_faces[3u * (out + e) + 1u] = sc_faces[3u * (base + e) + 1u];
        dec_faces[3u * (out + e) + 2u] = sc_faces[3u * (base + e) + 2u];
        face_owner[out + e] = m.z;
    }
}
