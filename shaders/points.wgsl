// points.wgsl: point lights on black seen through the shaped aperture, by splatting.
// A point light makes no image in a path tracer (a ray never hits it), so each
// light is drawn forwards instead: every sample is a point of the aperture
// (stratified: one jittered sample per cell of a strata × strata grid over u);
// the lens ray from it through the light meets the focus plane, and that hit's
// pinhole projection (camera.wgsl) is counted in the pixel it falls in. The
// expected count per pixel is the exact area-coverage kernel of design.md §6,
// centred on the light's pinhole projection.
// `splat` counts one light's samples in `counts` (u32 atomics: WGSL has no float
// atomics); `resolve` then adds counts × the light's weight to the float32
// accumulation buffer and clears the counts for the next light.

// #include "rng.wgsl"
// #include "shape_ids"
// #include "apertures.wgsl"
// #include "RenderParams"
// #include "PointParams"
// #include "camera.wgsl"

@group(0) @binding(0) var<uniform> params: RenderParams;
@group(0) @binding(1) var<uniform> light: PointParams;
@group(0) @binding(2) var<storage, read_write> counts: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> accum: array<vec4f>;

// Largest f32 below 1: a jittered cell's far edge must stay inside [0, 1).
const ONE_MINUS_EPSILON: f32 = 0x1.fffffep-1f;

fn stratified_u(i: u32) -> vec2f {
    let stream = light.stream ^ pcg_hash(params.seed);
    let jitter = vec2f(rand_unit_float(stream, i, 0u), rand_unit_float(stream, i, 1u));
    let cell = vec2f(f32(i % light.strata), f32(i / light.strata));
    return min((cell + jitter) / f32(light.strata), vec2f(ONE_MINUS_EPSILON));
}

@compute @workgroup_size(256)
fn splat(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    let threads = groups.x * 256u;
    for (var k = gid.x; k < light.count; k += threads) {
        let a = aperture_point(stratified_u(light.first + k));
        // The lens ray from (a, 0) through the light (slopes s = (x/z, y/z), 1/depth
        // w) meets the focus plane z = d_f at a·(1 − d_f·w) + s·d_f, whose pinhole
        // slopes are a·(1/d_f − w) + s. Behind the focus plane (w < 1/d_f) the
        // aperture is upright; in front of it the factor is negative: turned by 180°.
        let slope = a * (1.0 / params.focus_distance - light.inv_depth) + vec2f(light.slope_x, light.slope_y);
        let xy = pinhole_image_xy(slope);
        let col = floor(xy.x) - f32(params.tile_x);
        let row = floor(xy.y) - f32(params.tile_y);
        if (col >= 0.0 && col < f32(params.tile_width) && row >= 0.0 && row < f32(params.tile_height)) {
            atomicAdd(&counts[u32(row) * params.tile_width + u32(col)], 1u);
        }
    }
}

@compute @workgroup_size(256)
fn resolve(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    let threads = groups.x * 256u;
    let pixels = params.tile_width * params.tile_height;
    let weight = vec3f(light.weight_r, light.weight_g, light.weight_b);
    for (var i = gid.x; i < pixels; i += threads) {
        let count = atomicLoad(&counts[i]);
        if (count != 0u) {
            accum[i] += vec4f(weight * f32(count), 0.0);
            atomicStore(&counts[i], 0u);
        }
    }
}
