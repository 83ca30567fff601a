// viewer_points.js: the point-light view's WGSL, the one shader written in the viewer's page.

// Aperture samples per point light and batch, and the most workgroups of one point-light dispatch.
export const POINT_SAMPLES = 65536;
export const POINT_MAX_GROUPS = 4096;

// The point-light view: six point lights on black, each drawn by splatting aperture samples
// through it as `bokehfit render --scene points` does (points.wgsl), so that the aperture's
// shape is what one sees: upright in the top row (lights behind the focus plane), turned by
// 180° in the bottom row (in front of it). Appended to the served path tracer's WGSL, whose
// aperture and camera functions it calls; counts in u32 atomics (WGSL has no float atomics),
// then added to the accumulation buffer, which the tone map shows as it shows the path tracer's.
export const POINTS_WGSL = (binding, gain) => `
@group(0) @binding(${binding}) var<storage, read_write> point_counts: array<atomic<u32>>;
// Aperture samples per light and batch, the lights, the plateau after the exposure.
const POINT_SAMPLES: u32 = ${POINT_SAMPLES}u;
const POINT_LIGHTS: u32 = 6u;
const POINT_GAIN: f32 = ${gain};

// The near row's 1/depth offset from the focus plane: its discs a fifth of the image wide.
fn point_offset() -> f32 {
    let lens_diameter = 2.0 * params.aperture_scale / sqrt(PI);  // equal-area aperture, metres
    return 0.4 * params.tan_half.x / lens_diameter;
}

// Light i: its pinhole slopes (x/z, y/z), 1/depth, and its disc's size over the near row's.
// The far row is as far as the near one is near, or at infinity where that is nearer: its
// discs are then smaller (a lens focused close blurs lights at infinity only so much).
fn point_light(i: u32) -> vec4f {
    let far = i < 3u;
    let x = 0.55 * (f32(i % 3u) - 1.0) * params.tan_half.x;
    let y = select(-0.45, 0.45, far) * params.tan_half.y;
    let offset = select(point_offset(), min(point_offset(), 1.0 / params.focus_distance), far);
    return vec4f(x, y, 1.0 / params.focus_distance + select(1.0, -1.0, far) * offset, offset / point_offset());
}

@compute @workgroup_size(64)
fn point_splat(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    for (var n = gid.x; n < POINT_SAMPLES * POINT_LIGHTS; n += groups.x * 64u) {
        let light = point_light(n / POINT_SAMPLES);
        // samples in proportion to the disc's area: every disc as bright
        if (f32(n % POINT_SAMPLES) >= f32(POINT_SAMPLES) * light.w * light.w) {
            continue;
        }
        let stream = (n / POINT_SAMPLES + 1u) ^ pcg_hash(params.seed);
        let index = params.sample_index * POINT_SAMPLES + n % POINT_SAMPLES;
        let u = vec2f(rand_unit_float(stream, index, 0u), rand_unit_float(stream, index, 1u));
        let near = light.z > 1.0 / params.focus_distance;
        let seen = aperture_seen(field_position(pinhole_image_xy(light.xy)), near);
        let drawn = aperture_point(u, seen, CHANNEL_GREEN);
        if (drawn.z > 0.0) {
            // the lens ray from the aperture point through the light, on the focus plane, seen from the pinhole
            let xy = pinhole_image_xy(drawn.xy * (1.0 / params.focus_distance - light.z) + light.xy);
            if (all(xy >= vec2f(0.0)) && all(xy < vec2f(params.image_size))) {
                atomicAdd(&point_counts[u32(xy.y) * params.image_size.x + u32(xy.x)], 1u);
            }
        }
    }
}

@compute @workgroup_size(64)
fn point_resolve(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    // A near disc's area in pixels (the aperture's area, scaled by the offset into slopes, then
    // pixels): counts × area / samples is 1 inside any disc.
    let offset = point_offset();
    let per_slope = vec2f(params.image_size) / (2.0 * params.tan_half);
    let area_px = params.aperture_scale * params.aperture_scale * offset * offset * per_slope.x * per_slope.y;
    let scale = POINT_GAIN * area_px / f32(POINT_SAMPLES);
    for (var i = gid.x; i < params.image_size.x * params.image_size.y; i += groups.x * 64u) {
        let count = atomicLoad(&point_counts[i]);
        atomicStore(&point_counts[i], 0u);
        accum[i] += vec4f(vec3f(scale * f32(count)), 1.0);
    }
}
`;
