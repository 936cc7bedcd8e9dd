// Algorithm 4, parallel vertex splits: one thread per split gives the split's faces, whose
// FVIDs the reorganisation decoded into their slots after the old ones (at m + fsum[i]),
// their current vertex indices and their owner (the split's v_u, unique per split). A corner
// in [v, v_u) is v (new slot j), one in v_u's range [v_u, FVID of slot j + 2) is v_u (slot



@group(0) @binding(1) var<storage, read> vfvid: array<u32>;
@group(0) @binding(3) var<storage, read> vsum: array<u32>;
@group(0) @binding(4) var<storage, read> fsum: array<u32>;
@group(0) @binding(5) var<storage, read> list: array<u32>;
@group(0) @binding(6) var<storage, read> dfvid: array<u32>;
@group(0) @binding(7) var<storage, read_write> face_idx: array<u32>;
@group(0) @binding(8) var<storage, read> face_fvid: array<u32>;
@group(0) @binding(9) var<storage, read_write> face_owner: array<u32>;

// The index of the active vertex with the greatest FVID <= f (0 if there is none).
fn find(f: u32) -> u32 {
    var lo = 0u;
    var hi = P.n_new;
    while (lo < hi) {
        let mid = (lo + hi) >> 1u;
        if (dfvid[mid] <= f) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return max(lo, 1u) - 1u;
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread_index(gid, groups);
    if (k >= P.splits) {
        return;
    }
    let i = list[k];
    let v = vfvid[i];
    let j = vsum[i];
    let v_u = dfvid[j + 1u];
    let owner = v_u;
    var end = NONE;
    if (j + 2u < P.n_new) {
        end = dfvid[j + 2u];
    }
    let out = P.m + fsum[i];
    let count = fsum[i + 1u] - fsum[i];
    for (var e = 0u; e < count; e++) {
        let dst = out + e;
        for (var c = 0u; c < 3u; c++) {
            let f = face_fvid[3u * dst + c];
            var idx: u32;
            if (f >= v && f < v_u) {
                idx = j;
            } else if (f >= v_u && f < end) {
                idx = j + 1u;
            } else {
                idx = find(f);
            }
            face_idx[3u * dst + c] = idx;
        }
        face_owner[dst] = owner;
    }
}

// An all-levels pass: one thread per new face (their FVIDs and owners written by the split
// decoding's `descend`), each corner found by binary search in the new FVID buffer.
@compute @workgroup_size(256)
fn index_new(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread_index(gid, groups);
    if (k >= P.f_add) {
        return;
    }
    let dst = P.m + k;
    for (var c = 0u; c < 3u; c++) {
        face_idx[3u * dst + c] = find(face_fvid[3u * dst + c]);
    }
}
