// Algorithm 5, parallel index update of the faces that existed before the pass: each corner
// moves to its vertex's new slot; a collapsed vertex's corner to the previous slot (its
// target), a split vertex's corner to the next slot (v_u) when the corner's FVID reaches
// v_u. A face created by a performed collapse's split (its owner, kept per face, is the
// collapsing vertex's creator) is marked DEAD for the compaction: the owner rule rather than
// degeneracy, because input faces may be degenerate at every level (see codec/src/pm/adapt.rs).

@group(0) @binding(1) var<storage, read> vstate: array<VState>;
@group(0) @binding(2) var<storage, read> vsum: array<u32>;
@group(0) @binding(3) var<storage, read> dfvid: array<u32>;
@group(0) @binding(4) var<storage, read_write> face_idx: array<u32>;
@group(0) @binding(5) var<storage, read> face_fvid: array<u32>;
@group(0) @binding(6) var<storage, read_write> face_owner: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread_index(gid, groups);
    if (k >= P.m) {
        return;
    }
    let owner = face_owner[k];
    var idx: array<u32, 3>;
    for (var c = 0u; c < 3u; c++) {
        let i = face_idx[3u * k + c];
        let j = vsum[i];
        let cnt = vsum[i + 1u] - j;
        if (cnt == 0u) {
            if (owner != NONE && vstate[i].c_addr == owner) {
                face_owner[k] = DEAD;
                return;
            }
            idx[c] = j - 1u;
        } else if (cnt == 1u) {
            idx[c] = j;
        } else if (dfvid[j + 1u] <= face_fvid[3u * k + c]) {
            idx[c] = j + 1u;
        } else {
            idx[c] = j;
        }
    }
    for (var c = 0u; c < 3u; c++) {
        face_idx[3u * k + c] = idx[c];
    }
}
