// Decodes a batch of operations, one thread each, from their addresses and contexts: the
// decoder's test and benchmark entry point (worker/src/pm_adapt/decoder.rs), compiled after
// the generated constants and decode.wgsl. Operation i's faces go to face slots
// i * D.max_faces onwards.

// One operation to decode: its address and context (`Job` in decoder.rs).
struct Job {
    addr: u32,
    v: u32,
    v_end: u32,
    pad: u32,
    parent_criteria: vec4<u32>,
    position: vec4<u32>, // xyz
    normal: vec4<u32>,   // xy
}

@group(0) @binding(0) var<storage, read> jobs: array<Job>;
@group(0) @binding(1) var<storage, read_write> decoded: array<DecodedOp>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = gid.x + gid.y * groups.x * 64u;
    if (i >= D.count) {
        return;
    }
    let j = jobs[i];
    decoded[i] = decode_op(j.addr, j.v, j.v_end, j.parent_criteria, j.position.xyz, j.normal.xy, i * D.max_faces,
                           DECODE_ALL);
}
