// Algorithm 3's splits: one thread per splitting vertex (the compacted list) decodes its
// operation from the .dpm's bytes (the decoder, decode.wgsl, is prepended to this file) and
// writes its two children to their slots of the new vertex buffers, v at the vertex's slot
// and v_u right after it (v_u's FVID follows v's left range), each with its operation's
// criteria and face count decoded, so that the new FVID buffer is complete before the split
// stage searches it. The split's faces go, as FVIDs, to their slots of the face FVID buffer
// (`dec_faces`), from the face prefix sum `fsum`, for the split stage to index. It is a stage
// of its own, apart from the reorganisation's copies, so that decoding threads run together
// and the copies stay plain loads and stores.

@group(0) @binding(1) var<storage, read> vfvid: array<u32>;
@group(0) @binding(2) var<storage, read> vstate: array<VState>;
@group(0) @binding(3) var<storage, read> vpoint: array<Point>;
@group(0) @binding(4) var<storage, read> vsum: array<u32>;
@group(0) @binding(5) var<storage, read> fsum: array<u32>;
@group(0) @binding(6) var<storage, read> list: array<u32>;
@group(0) @binding(7) var<storage, read_write> dfvid: array<u32>;
@group(0) @binding(8) var<storage, read_write> dstate: array<VState>;
@group(0) @binding(9) var<storage, read_write> dpoint: array<Point>;
@group(0) @binding(10) var<uniform> D: DecodeParams;
@group(0) @binding(11) var<storage, read> ops: array<u32>;
@group(0) @binding(12) var<storage, read> tables: array<u32>;
@group(0) @binding(13) var<storage, read_write> dec_faces: array<u32>;
@group(0) @binding(14) var<storage, read_write> errors: array<atomic<u32>, 2>;

// The position of a quantized one, as the CPU decoder computes it.
fn dequantize(q: vec3<u32>) -> vec3<f32> {
    return vec3<f32>(D.grid.x + f32(q.x) * D.grid.w, D.grid.y + f32(q.y) * D.grid.w, D.grid.z + f32(q.z) * D.grid.w);
}

// The unit normal (or zero) of an octahedral code, as the CPU decoder computes it.
fn oct_decode(q: vec2<u32>) -> vec3<f32> {
    let zero = 1u << D.normal_bits;
    if (q.x == zero && q.y == zero) {
        return vec3<f32>(0.0);
    }
    let m = f32(zero - 1u);
    var x = f32(q.x) / m * 2.0 - 1.0;
    var y = f32(q.y) / m * 2.0 - 1.0;
    let z = 1.0 - abs(x) - abs(y);
    if (z < 0.0) {
        let ox = x;
        let oy = y;
        x = (1.0 - abs(oy)) * select(-1.0, 1.0, ox >= 0.0);
        y = (1.0 - abs(ox)) * select(-1.0, 1.0, oy >= 0.0);
    }
    let l = sqrt(x * x + y * y + z * z);
    return vec3<f32>(x / l, y / l, z / l);
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread_index(gid, groups);
    if (k >= P.splits) {
        return;
    }
    let i = list[k];
    let j = vsum[i];
    let f = vfvid[i];
    let s = vstate[i];
    let o = decode_op(s.addr, f, s.v_end, s.pc, s.pos.xyz, s.nrm.xy, P.m + fsum[i], DECODE_ALL);
    if (o.status != DEC_OK) {
        // The pass fails (the host reads the error); the slots get harmless copies.
        report(o.status, s.addr);
        dfvid[j] = f;
        dstate[j] = s;
        dpoint[j] = vpoint[i];
        dfvid[j + 1u] = f;
        dstate[j + 1u] = s;
        dpoint[j + 1u] = vpoint[i];
        return;
    }
    var l = s;
    l.flags = 0u;
    l.v_end = o.v_u;
    l.addr = o.left;
    l.pc = o.crit;
    with_op(&l, f);
    var r: VState;
    r.v_end = s.v_end;
    r.addr = o.right;
    r.pc = o.crit;
    r.pos = o.position;
    r.nrm = o.normal;
    r.c_addr = s.addr;
    r.c_v = f;
    r.c_v_end = s.v_end;
    r.c_faces = o.faces;
    r.c_pc = s.pc;
    r.c_crit = s.crit;
    with_op(&r, o.v_u);
    dfvid[j] = f;
    dstate[j] = l;
    dpoint[j] = vpoint[i];
    dfvid[j + 1u] = o.v_u;
    dstate[j + 1u] = r;
    dpoint[j + 1u] = Point(vec4<f32>(dequantize(o.position.xyz), 1.0), vec4<f32>(oct_decode(o.normal.xy), 0.0));
}
