// Tile renderer (worker/src/render.rs), two pipelines drawn under the tile's scissor rect:
// - clear: resets the tile to transparent black and the far depth;
// - mesh: smooth-shaded, two-sided Lambert + ambient under a headlight, in the vertex
//   colours where the mesh has them (alpha 1 at every vertex) and a fixed light grey where
//   it has none (alpha 0 at every vertex, so the grey is exact, not interpolated). Opaque:
//   every covered pixel gets alpha 1.

// One triangle over the whole viewport, (-1,-1) (3,-1) (-1,3) in NDC, at the far plane:
// depth 1, the value the mesh's `less` depth test starts from.
@vertex
fn clear_vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let corner = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(corner * 2.0 - 1.0, 1.0, 1.0);
}

@fragment
fn clear_fs() -> @location(0) vec4<f32> {
    return vec4<f32>(0.0);
}

struct Frame {
    // World to clip space: the whole frame's projection times view, for every tile.
    view_proj: mat4x4<f32>,
    // The headlight, homogeneous: the eye times some nonzero w for a perspective camera,
    // a direction (w = 0) for an orthographic one. Its scale and sign do not matter.
    eye: vec4<f32>,
}

@group(0) @binding(0) var<uniform> frame: Frame;

struct VertexOutput {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
}

fn transform(position: vec3<f32>, normal: vec3<f32>, color: vec4<f32>) -> VertexOutput {
    var out: VertexOutput;
    out.clip = frame.view_proj * vec4<f32>(position, 1.0);
    out.world = position;
    out.normal = normal;
    out.color = color;
    return out;
}

@vertex
fn vs_main(
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
) -> VertexOutput {
    return transform(position, normal, color);
}

// The progressive mesh adapted on the GPU (worker/src/pm_adapt/), drawn from its own buffers:
// the index buffer holds active-vertex indices, and each vertex pulls its position and normal.
struct PmPoint {
    pos: vec4<f32>,
    nrm: vec4<f32>,
}

@group(1) @binding(0) var<storage, read> pm_points: array<PmPoint>;

@vertex
fn vs_pulled(@builtin(vertex_index) i: u32) -> VertexOutput {
    let p = pm_points[i];
    return transform(p.pos.xyz, p.nrm.xyz, vec4<f32>(0.0));
}

const BASE: vec3<f32> = vec3<f32>(0.8, 0.8, 0.8);
const AMBIENT: f32 = 0.2;

@fragment
fn fs_main(in: VertexOutput) -> @location(0) vec4<f32> {
    let to_light = frame.eye.xyz - in.world * frame.eye.w;
    let nn = dot(in.normal, in.normal);
    let ll = dot(to_light, to_light);
    // Two-sided (abs): meshes may be inconsistently oriented and are drawn without culling.
    // A zero normal, or a fragment at the eye, is lit fully rather than turned into NaN.
    var diffuse = 1.0;
    if (nn > 0.0 && ll > 0.0) {
        diffuse = min(abs(dot(in.normal, to_light)) * inverseSqrt(nn * ll), 1.0);
    }
    var base = BASE;
    if (in.color.a > 0.5) {
        base = in.color.rgb;
    }
    return vec4<f32>(base * (AMBIENT + (1.0 - AMBIENT) * diffuse), 1.0);
}
