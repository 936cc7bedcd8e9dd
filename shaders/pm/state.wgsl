// Algorithm 1, vertex state update: per active vertex, 2 (split), 1 (keep) or 0 (collapse)
// into `vcnt`, and the number of faces its split creates into `fcnt`. Thread n writes the
// zero that ends both arrays, so that their exclusive scans end in the totals.

@group(0) @binding(1) var<storage, read> vfvid: array<u32>;
@group(0) @binding(2) var<storage, read> vstate: array<VState>;
@group(0) @binding(3) var<storage, read> vpoint: array<Point>;
@group(0) @binding(4) var<storage, read_write> vcnt: array<u32>;
@group(0) @binding(5) var<storage, read_write> fcnt: array<u32>;
// The depth pyramid of occlusion culling: the number of levels, per level its width, height
// and first word, then the levels' cells, the farthest depth (f32 bits) in each.
@group(0) @binding(6) var<storage, read> occ: array<u32>;

// Whether a bounding sphere was hidden in the frame of the depth pyramid (the paper's
// occlusion culling one frame late, here of vertices' spheres): its box projected with that
// frame's view-projection lies inside the pyramid's rectangle and behind the farthest depth
// of every cell it covers, at the level where it spans at most two cells a side. A sphere
// that reaches behind the eye or past the rectangle is not occluded.
fn occluded(center: vec3<f32>, r: f32) -> bool {
    if (P.occ_size.w == 0.0) {
        return false;
    }
    var lo = vec2<f32>(3.0e38);
    var hi = vec2<f32>(-3.0e38);
    var zmin = 3.0e38;
    for (var k = 0u; k < 8u; k++) {
        let c = center + vec3<f32>(select(-r, r, (k & 1u) != 0u), select(-r, r, (k & 2u) != 0u),
                                   select(-r, r, (k & 4u) != 0u));
        let q = P.occ_vp * vec4<f32>(c, 1.0);
        if (q.w <= 0.0) {
            return false;
        }
        lo = min(lo, q.xy / q.w);
        hi = max(hi, q.xy / q.w);
        zmin = min(zmin, q.z / q.w);
    }
    if (zmin <= 0.0) {
        return false;
    }
    let x0 = (lo.x + 1.0) * 0.5 * P.occ_size.x;
    let x1 = (hi.x + 1.0) * 0.5 * P.occ_size.x;
    let y0 = (1.0 - hi.y) * 0.5 * P.occ_size.y;
    let y1 = (1.0 - lo.y) * 0.5 * P.occ_size.y;
    if (x0 < P.occ_rect.x || y0 < P.occ_rect.y || x1 > P.occ_rect.z || y1 > P.occ_rect.w) {
        return false;
    }
    let levels = occ[0];
    var level = 0u;
    var side = P.occ_size.z;
    while (level + 1u < levels && max(x1 - x0, y1 - y0) > side) {
        level++;
        side *= 2.0;
    }
    let w = occ[1u + 3u * level];
    let h = occ[2u + 3u * level];
    let at = occ[3u + 3u * level];
    let cx0 = min(u32((x0 - P.occ_rect.x) / side), w - 1u);
    let cx1 = min(u32((x1 - P.occ_rect.x) / side), w - 1u);
    let cy0 = min(u32((y0 - P.occ_rect.y) / side), h - 1u);
    let cy1 = min(u32((y1 - P.occ_rect.y) / side), h - 1u);
    var far = 0.0;
    for (var cy = cy0; cy <= cy1; cy++) {
        for (var cx = cx0; cx <= cx1; cx++) {
            far = max(far, bitcast<f32>(occ[at + cy * w + cx]));
        }
    }
    return zmin > far;
}

// The refinement test, and not hidden (occlusion culling on).
fn wants_split(center: vec3<f32>, normal: vec3<f32>, crit: vec4<f32>) -> bool {
    return needs_split(center, normal, crit) && !occluded(center, crit.w);
}

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
    if (s.addr != NONE && s.flags == 0u && P.mode != 2u
        && (P.mode == 1u || wants_split(vpoint[i].pos.xyz, vpoint[i].nrm.xyz, s.crit))) {
        state = 2u;
        faces = s.faces;
    } else if (P.mode != 1u) {
        let t = target_of(s);
        if (t != NONE && i > 0u && vfvid[i - 1u] == t && (i + 1u == n || target_of(vstate[i + 1u]) != f)) {
            // The collapse's criteria are the creator's; its vertex is the target, the
            // previous one.
            if (!wants_split(vpoint[i - 1u].pos.xyz, vpoint[i - 1u].nrm.xyz, s.c_crit)) {
                state = 0u;
            }
        }
    }
    vcnt[i] = state;
    fcnt[i] = faces;
}
