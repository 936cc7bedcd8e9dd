// Algorithm 1, vertex state update: per active vertex, 2 (split), 1 (keep) or 0 (collapse)
// into `vcnt`, and the number of faces its split creates into `fcnt`. Thread n writes the
// zero that ends both arrays, so that their exclusive scans end in the totals.

@group(0) @binding(1) var<storage, read> vfvid: array<u32>;
@group(0) @binding(2) var<storage, read> vstate: array<VState>;
@group(0) @binding(3) var<storage, read> vpoint: array<Point>;
@group(0) @binding(4) var<storage, read_write> vcnt: array<u32>;
@group(0) @binding(5) var<storage, read_write> fcnt: array<u32>;

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
    if (s.addr != NONE && s.flags == 0u && (P.mode == 1u || needs_split(vpoint[i].pos.xyz, vpoint[i].nrm.xyz, s.crit))) {
        state = 2u;
        faces = s.faces;
    } else if (P.mode == 0u) {
        let t = target_of(s);
        if (t != NONE && i > 0u && vfvid[i - 1u] == t && (i + 1u == n || target_of(vstate[i + 1u]) != f)) {
            // The collapse's criteria are the creator's; its vertex is the target, the
            // previous one.
            if (!needs_split(vpoint[i - 1u].pos.xyz, vpoint[i - 1u].nrm.xyz, s.c_crit)) {
                state = 0u;
            }
        }
    }
    vcnt[i] = state;
    fcnt[i] = faces;
}
