// Algorithm 5, parallel index update of the faces that existed before the pass: each corner
// moves to its vertex's new slot; a collapsed vertex's corner to the previous slot (its
// target, or its region's vertex), a split vertex's corner to the slot among its new ones
// whose FVID range holds the corner's FVID (binary search; one level: v_u when the FVID
// reaches v_u). A face whose split the pass undoes is marked DEAD for the compaction: its
// owner, kept per face, is its split's v_u, the FVID of the vertex whose creator the split
// is, and the split is undone exactly when that vertex collapses (one level: it is the
// collapsing vertex). The owner rule rather than degeneracy, because input faces may be
// degenerate at every level (see codec/src/pm/adapt.rs).

@group(0) @binding(1) var<storage, read> vfvid: array<u32>;
@group(0) @binding(2) var<storage, read> vsum: array<u32>;
@group(0) @binding(3) var<storage, read> dfvid: array<u32>;
@group(0) @binding(4) var<storage, read_write> face_idx: array<u32>;
@group(0) @binding(5) var<storage, read> face_fvid: array<u32>;
@group(0) @binding(6) var<storage, read_write> face_owner: array<u32>;

// Whether the split owning a face (`owner`, its v_u) is undone by this pass, seen from a
// corner at collapsing vertex `i`: one level, `i` is the vertex whose creator the split is;
// all levels, that vertex (the one at FVID `owner`) collapses.
fn undone(owner: u32, i: u32) -> bool {
    if (P.levels == 0u) {
        return vfvid[i] == owner;
    }
    var lo = 0u;
    var hi = P.n;
    while (lo < hi) {
        let mid = (lo + hi) >> 1u;
        if (vfvid[mid] < owner) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return lo < P.n && vfvid[lo] == owner && vsum[lo + 1u] == vsum[lo];
}

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
            if (owner != NONE && undone(owner, i)) {
                face_owner[k] = DEAD;
                return;
            }
            idx[c] = j - 1u;
        } else if (cnt == 1u) {
            idx[c] = j;
        } else {
            // The last of the vertex's new slots whose FVID is <= the corner's.
            let f = face_fvid[3u * k + c];
            var lo = j + 1u;
            var hi = j + cnt;
            while (lo < hi) {
                let mid = (lo + hi) >> 1u;
                if (dfvid[mid] <= f) {
                    lo = mid + 1u;
                } else {
                    hi = mid;
                }
            }
            idx[c] = lo - 1u;
        }
    }
    for (var c = 0u; c < 3u; c++) {
        face_idx[3u * k + c] = idx[c];
    }
}
