// Algorithm 3, vertex buffer reorganisation: each surviving vertex is copied to its slot in
// the new buffers, given by the exclusive prefix sum `vsum` of the vertex counts (a count is
// vsum[i + 1] - vsum[i]). A split vertex also writes its two children here, v at its slot
// and v_u right after it (v_u's FVID follows v's left range), with their next splits and
// nodes, so that the new FVID buffer is complete before the split stage searches it.

@group(0) @binding(1) var<storage, read> splits: array<Split>;
@group(0) @binding(2) var<storage, read> vfvid: array<u32>;
@group(0) @binding(3) var<storage, read> vnext: array<u32>;
@group(0) @binding(4) var<storage, read> vnode: array<u32>;
@group(0) @binding(5) var<storage, read> vsum: array<u32>;
@group(0) @binding(6) var<storage, read_write> dfvid: array<u32>;
@group(0) @binding(7) var<storage, read_write> dnext: array<u32>;
@group(0) @binding(8) var<storage, read_write> dnode: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= P.n) {
        return;
    }
    let j = vsum[i];
    let cnt = vsum[i + 1u] - j;
    if (cnt == 1u) {
        dfvid[j] = vfvid[i];
        dnext[j] = vnext[i];
        dnode[j] = vnode[i];
    } else if (cnt == 2u) {
        let s = vnext[i];
        let split = splits[s];
        dfvid[j] = vfvid[i];
        dnext[j] = split.child0;
        dnode[j] = 2u * s;
        dfvid[j + 1u] = split.v_u;
        dnext[j + 1u] = split.child1;
        dnode[j + 1u] = 2u * s + 1u;
    }
}
