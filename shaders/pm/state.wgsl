// Algorithm 1, vertex state update: per active vertex, 2 (split), 1 (keep) or 0 (collapse)
// into `vcnt`, and the number of faces its split creates into `fcnt`. Thread n writes the
// zero that ends both arrays, so that their exclusive scans end in the totals.

@group(0) @binding(1) var<storage, read> splits: array<Split>;
@group(0) @binding(2) var<storage, read> points: array<Point>;
@group(0) @binding(3) var<storage, read> vfvid: array<u32>;
@group(0) @binding(4) var<storage, read> vnext: array<u32>;
@group(0) @binding(5) var<storage, read> vnode: array<u32>;
@group(0) @binding(6) var<storage, read_write> vcnt: array<u32>;
@group(0) @binding(7) var<storage, read_write> fcnt: array<u32>;

// The collapse target FVID of a node (its split's v) if it is a right child.
fn target_of(node: u32) -> u32 {
    if (node != NONE && (node & 1u) == 1u) {
        return splits[node >> 1u].v;
    }
    return NONE;
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
    let next = vnext[i];
    var state = 1u;
    var faces = 0u;
    if (next != NONE && (P.mode == 1u || needs_split(points[f].pos.xyz, points[f].nrm.xyz, splits[next].crit))) {
        state = 2u;
        faces = splits[next].face_cnt;
    } else if (P.mode == 0u) {
        let node = vnode[i];
        let t = target_of(node);
        if (t != NONE && i > 0u && vfvid[i - 1u] == t && (i + 1u == n || target_of(vnode[i + 1u]) != f)) {
            // The collapse's criteria are those of the split that made this vertex; its
            // vertex is the target.
            let s = node >> 1u;
            if (!needs_split(points[t].pos.xyz, points[t].nrm.xyz, splits[s].crit)) {
                state = 0u;
            }
        }
    }
    vcnt[i] = state;
    fcnt[i] = faces;
}
