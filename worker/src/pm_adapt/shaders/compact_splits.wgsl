// Compaction of the splits (Algorithm 4's first step): the old index of every splitting
// vertex (count 2, or more in an all-levels pass) goes to `list`, so that the split stages
// run one thread per splitting vertex. Order does not matter (each split's faces go to the
// slots its face prefix sum gives), so an atomic cursor replaces a third scan.

@group(0) @binding(1) var<storage, read> vsum: array<u32>;
@group(0) @binding(2) var<storage, read_write> list: array<u32>;
@group(0) @binding(3) var<storage, read_write> stats: array<atomic<u32>, 8>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= P.n || vsum[i + 1u] - vsum[i] < 2u) {
        return;
    }
    list[atomicAdd(&stats[STAT_SPLIT_CURSOR], 1u)] = i;
}
