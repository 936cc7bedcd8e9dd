// Algorithm 2, parallel edge collapses, in place: a collapse whose target is marked for
// splitting is cancelled (count 1); otherwise the target becomes its creator's vertex again:
// it takes the creator's operation, context and criteria from the collapsing vertex and keeps
// its own creator (which the FVID it keeps still names). The collapsed vertex and its faces
// are dropped by the later stages. In place is safe: a target is never itself collapsing (its
// successor is the vertex collapsing into it), and a count that changes goes from 0 to 1,
// which no neighbour reads as 2.

@group(0) @binding(1) var<storage, read_write> vstate: array<VState>;
@group(0) @binding(2) var<storage, read_write> vcnt: array<u32>;
@group(0) @binding(3) var<storage, read_write> stats: array<atomic<u32>, 8>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= P.n || vcnt[i] != 0u) {
        return;
    }
    if (vcnt[i - 1u] == 2u) {
        vcnt[i] = 1u;
        atomicAdd(&stats[STAT_CANCELLED], 1u);
        return;
    }
    let c = vstate[i];
    vstate[i - 1u] = creators_vertex(vstate[i - 1u], c);
    atomicAdd(&stats[STAT_COLLAPSES], 1u);
    atomicAdd(&stats[STAT_REMOVED_FACES], c.c_faces);
}
