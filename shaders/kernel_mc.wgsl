// kernel_mc.wgsl: Monte-Carlo point-light defocus kernel (design.md §6).
// One point light seen through the lens: each sample is a point of the
// aperture, scaled to the disc's size, rotated and (near side) turned by 180
// degrees, and counted in the pixel it lands in. The kernel is the histogram.
// Samples are stratified on a strata x strata jittered grid over u (one per
// cell), or independent when params.stratified == 0.

// #include "rng.wgsl"
// #include "shape_ids"
// #include "apertures.wgsl"
// #include "KernelParams"

@group(0) @binding(0) var<uniform> params: KernelParams;
@group(0) @binding(1) var<storage, read_write> counts: array<atomic<u32>>;

// Largest f32 below 1: a jittered cell's far edge must stay inside [0, 1).
const ONE_MINUS_EPSILON: f32 = 0x1.fffffep-1f;

fn sample_u(i: u32) -> vec2f {
    let jitter = vec2f(rand_unit_float(params.seed, i, 0u), rand_unit_float(params.seed, i, 1u));
    if (params.stratified == 0u) {
        return jitter;
    }
    let cell = vec2f(f32(i % params.strata), f32(i / params.strata));
    return min((cell + jitter) / f32(params.strata), vec2f(ONE_MINUS_EPSILON));
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    let threads = groups.x * 256u;
    let centre = 0.5 * f32(params.size - 1u);
    for (var i = gid.x; i < params.samples; i += threads) {
        let p = params.scale * rotate(
            sample_aperture(params.shape, sample_u(i), params.blades, params.aspect),
            params.cos_angle, params.sin_angle);
        // Pixel-centre coordinates, y up on screen (design.md §2).
        let col = floor(centre + p.x + 0.5);
        let row = floor(centre - p.y + 0.5);
        let n = f32(params.size);
        if (col >= 0.0 && col < n && row >= 0.0 && row < n) {
            atomicAdd(&counts[u32(row) * params.size + u32(col)], 1u);
        }
    }
}
