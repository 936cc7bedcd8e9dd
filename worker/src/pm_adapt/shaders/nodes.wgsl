// Out of core only, the first stage of a pass (the start of codec::pm::DpmAdapter's pass): per
// active vertex with an operation, ABSENT where the operation's node is not resident this pass
// (the vertex does not split; a collapse needs no node), and a PENDING vertex whose node has
// come in gets its split cache decoded (criteria and face count). The page table does not
// change during a pass: the host writes it before the pass's first submission.

@group(0) @binding(1) var<storage, read> vfvid: array<u32>;
@group(0) @binding(2) var<storage, read_write> vstate: array<VState>;

fn resident(addr: u32) -> bool {
    let node = addr >> 16u;
    return node < D.nodes && tables[D.lens_at + D.nodes + node] != NONE_ADDR;
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= P.n) {
        return;
    }
    var s = vstate[i];
    if (s.addr == NONE) {
        return;
    }
    let here = resident(s.addr);
    let was = s.flags;
    if ((s.flags & PENDING) != 0u && here) {
        with_op(&s, vfvid[i]);
    }
    s.flags = (s.flags & PENDING) | select(ABSENT, 0u, here);
    if (s.flags != was || (was & PENDING) != 0u) {
        vstate[i] = s;
    }
}
