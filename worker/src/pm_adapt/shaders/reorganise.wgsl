// Algorithm 3, vertex buffer reorganisation: each surviving vertex is copied to its slot in
// the new buffers, given by the exclusive prefix sum `vsum` of the vertex counts (a count is
// vsum[i + 1] - vsum[i]). A split vertex's two slots are written by the split decoding
// (split_decode.wgsl), which runs before, one thread per split.

@group(0) @binding(1) var<storage, read> vfvid: array<u32>;
@group(0) @binding(2) var<storage, read> vstate: array<VState>;
@group(0) @binding(3) var<storage, read> vpoint: array<Point>;
@group(0) @binding(4) var<storage, read> vsum: array<u32>;
@group(0) @binding(5) var<storage, read_write> dfvid: array<u32>;
@group(0) @binding(6) var<storage, read_write> dstate: array<VState>;
@group(0) @binding(7) var<storage, read_write> dpoint: array<Point>;
// An all-levels pass: per region's first vertex, 1 + the vertex carrying the region's
// operation as its creator (0 elsewhere).
@group(0) @binding(8) var<storage, read> root: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= P.n) {
        return;
    }
    let j = vsum[i];
    if (vsum[i + 1u] - j == 1u) {
        var s = vstate[i];
        if (P.levels == 1u && root[i] != 0u) {
            // A region's first vertex becomes the region's vertex again: the region's
            // operation from the vertex that carries it.
            s = creators_vertex(s, vstate[root[i] - 1u]);
        }
        dfvid[j] = vfvid[i];
        dstate[j] = s;
        dpoint[j] = vpoint[i];
    }
}
