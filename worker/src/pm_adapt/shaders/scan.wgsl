// GPU prefix sums: a work-efficient exclusive scan, in place, of `data[0..count]` (count from
// `L`), in blocks of 2048 elements per workgroup of 256 threads. `scan_blocks` loads a block
// into workgroup memory (coalesced), each thread scans its 8 consecutive elements serially,
// the 256 thread totals are scanned by the Blelloch up-sweep and down-sweep (Sengupta, Harris,
// Zhang and Owens, "Scan primitives for GPU computing", 2007), and the block's total goes to
// `sums`; the host scans `sums` the same way, recursively, and `add_blocks` adds each block's
// scanned offset back. O(n) additions; 8 elements per thread cut the workgroup barriers per
// element eightfold against one pair per thread, which lavapipe, which runs a workgroup's
// invocations as coroutines switching at every barrier, measured three times faster.

struct Level {
    count: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<storage, read> L: Level;
@group(0) @binding(1) var<storage, read_write> data: array<u32>;
@group(0) @binding(2) var<storage, read_write> sums: array<u32>;

const THREADS: u32 = 256u;
const PER_THREAD: u32 = 8u;
const BLOCK: u32 = 2048u;
var<workgroup> tile: array<u32, 2048>;
var<workgroup> part: array<u32, 256>;

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
    for (var k = 0u; k < PER_THREAD; k++) {
        let i = k * THREADS + t;
        tile[i] = select(0u, data[base + i], base + i < L.count);
    }
    workgroupBarrier();
    // This thread's 8 consecutive elements, serially.
    var sum = 0u;
    for (var k = 0u; k < PER_THREAD; k++) {
        let x = tile[t * PER_THREAD + k];
        tile[t * PER_THREAD + k] = sum;
        sum += x;
    }
    part[t] = sum;
    // Blelloch over the thread totals: up-sweep...
    var offset = 1u;
    for (var d = THREADS >> 1u; d > 0u; d >>= 1u) {
        workgroupBarrier();
        if (t < d) {
            let ai = offset * (2u * t + 1u) - 1u;
            let bi = offset * (2u * t + 2u) - 1u;
            part[bi] += part[ai];
        }
        offset <<= 1u;
    }
    workgroupBarrier();
    if (t == 0u) {
        sums[b] = part[THREADS - 1u];
        part[THREADS - 1u] = 0u;
    }
    // ... and down-sweep.
    for (var d = 1u; d < THREADS; d <<= 1u) {
        offset >>= 1u;
        workgroupBarrier();
        if (t < d) {
            let ai = offset * (2u * t + 1u) - 1u;
            let bi = offset * (2u * t + 2u) - 1u;
            let x = part[ai];
            part[ai] = part[bi];
            part[bi] += x;
        }
    }
    workgroupBarrier();
    let add = part[t];
    for (var k = 0u; k < PER_THREAD; k++) {
        tile[t * PER_THREAD + k] += add;
    }
    workgroupBarrier();
    for (var k = 0u; k < PER_THREAD; k++) {
        let i = k * THREADS + t;
        if (base + i < L.count) {
            data[base + i] = tile[i];
        }
    }
}

@compute @workgroup_size(256)
fn add_blocks(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let b = block_index(wid, groups);
    let offset = sums[b];
    for (var k = 0u; k < PER_THREAD; k++) {
        let a = b * BLOCK + k * THREADS + t;
        if (a < L.count) {
            data[a] += offset;
        }
    }
}
