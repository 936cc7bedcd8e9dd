// GPU prefix sums: a work-efficient (Blelloch) exclusive scan, in place, of `data[0..count]`
// (count from `L`). `scan_blocks` scans each block of 512 elements in workgroup memory (up-
// sweep and down-sweep, O(n) additions) and writes the block's total to `sums`; the host
// scans `sums` the same way, recursively, and `add_blocks` adds each block's scanned offset
// back. (Sengupta, Harris, Zhang and Owens, "Scan primitives for GPU computing", 2007.)

struct Level {
    count: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> L: Level;
@group(0) @binding(1) var<storage, read_write> data: array<u32>;
@group(0) @binding(2) var<storage, read_write> sums: array<u32>;

const BLOCK: u32 = 512u;
var<workgroup> tmp: array<u32, 512>;

fn block_index(wid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return wid.x + wid.y * groups.x;
}

@compute @workgroup_size(256)
fn scan_blocks(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let b = block_index(wid, groups);
    let base = b * BLOCK;
    let a = base + 2u * t;
    tmp[2u * t] = select(0u, data[a], a < L.count);
    tmp[2u * t + 1u] = select(0u, data[a + 1u], a + 1u < L.count);
    // Up-sweep.
    var offset = 1u;
    for (var d = BLOCK >> 1u; d > 0u; d >>= 1u) {
        workgroupBarrier();
        if (t < d) {
            let ai = offset * (2u * t + 1u) - 1u;
            let bi = offset * (2u * t + 2u) - 1u;
            tmp[bi] += tmp[ai];
        }
        offset <<= 1u;
    }
    workgroupBarrier();
    if (t == 0u) {
        sums[b] = tmp[BLOCK - 1u];
        tmp[BLOCK - 1u] = 0u;
    }
    // Down-sweep.
    for (var d = 1u; d < BLOCK; d <<= 1u) {
        offset >>= 1u;
        workgroupBarrier();
        if (t < d) {
            let ai = offset * (2u * t + 1u) - 1u;
            let bi = offset * (2u * t + 2u) - 1u;
            let x = tmp[ai];
            tmp[ai] = tmp[bi];
            tmp[bi] += x;
        }
    }
    workgroupBarrier();
    if (a < L.count) {
        data[a] = tmp[2u * t];
    }
    if (a + 1u < L.count) {
        data[a + 1u] = tmp[2u * t + 1u];
    }
}

@compute @workgroup_size(256)
fn add_blocks(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let b = block_index(wid, groups);
    let a = b * BLOCK + 2u * t;
    let offset = sums[b];
    if (a < L.count) {
        data[a] += offset;
    }
    if (a + 1u < L.count) {
        data[a + 1u] += offset;
    }
}
