// pathtrace.wgsl: progressive path tracer seen through a shaped thin-lens aperture.
// One dispatch adds one sample to every pixel of a tile: a jittered point of
// the pixel and a point of the aperture make the lens ray (camera.wgsl), which
// is traced through the scene (scene.wgsl) and its radiance added to the float32
// accumulation buffer (sum of samples in rgb, count in a).
//
// Light transport: diffuse vertices sample the area lights directly (next-event
// estimation, one light point per vertex) and continue in a cosine-distributed
// direction; mirrors reflect. A light hit by a ray is counted only when
// next-event estimation could not have reached it: on camera rays and after a
// mirror, not after a diffuse vertex. So no path is counted twice and none is
// left out. Optionally (MIRROR_COUNT > 0, generated) next-event estimation also
// reaches the lights through each planar mirror quad, as a virtual light; a
// light hit whose path since the last diffuse vertex is one planar-mirror
// reflection is then not counted either. Russian roulette from vertex
// params.rr_depth on, with survival probability min(max throughput, 0.95).
//
// Random numbers: rand_unit_float(pixel stream, sample index, dimension); the
// stream is the pixel's index in the whole image (so tiles do not change the
// image) XOR a hash of the seed. Dimensions: 0-1 pixel jitter, 2-3 aperture,
// then DIMS_PER_VERTEX per path vertex.
//
// Written for WebGPU as browsers implement it: no f64, no push constants,
// one uniform and one storage buffer, 64 invocations per workgroup.

// #include "rng.wgsl"
// #include "shape_ids"
// #include "apertures.wgsl"
// #include "RenderParams"
// #include "Material"
// #include "Quad"
// #include "Box"
// #include "Sphere"
// #include "camera.wgsl"
// #include "scene.wgsl"
// #include "scene"

@group(0) @binding(0) var<uniform> params: RenderParams;
@group(0) @binding(1) var<storage, read_write> accum: array<vec4f>;

const DIMS_PER_VERTEX: u32 = 6u;
const MAX_SURVIVAL: f32 = 0.95;

fn rand(stream: u32, dimension: u32) -> f32 {
    return rand_unit_float(stream, params.sample_index, dimension);
}

// Unit vectors t, b completing n to an orthonormal basis (Duff et al., "Building
// an Orthonormal Basis, Revisited", JCGT 2017); sign + n.z is never 0.
fn basis_t(n: vec3f) -> vec3f {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    return vec3f(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
}

fn basis_b(n: vec3f) -> vec3f {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    return vec3f(b, s + n.y * n.y * a, -n.y);
}

// Cosine-distributed direction about n (Malley's method on the concentric disc map
// of apertures.wgsl, scaled from the unit-area disc to the unit disc).
fn cosine_direction(n: vec3f, u: vec2f) -> vec3f {
    let d = sample_circle(u) / CIRCLE_RADIUS;
    let z = sqrt(max(0.0, 1.0 - dot(d, d)));
    return normalize(d.x * basis_t(n) + d.y * basis_b(n) + z * n);
}

// Cosine-weighted, unoccluded solid angle term cos_s·cos_l·area / r² of the light
// point y (area normal na = u × v, |na| = area) seen from p (normal n); 0 when
// either side faces away. wi is set to the unit direction from p to y.
fn light_geometry(p: vec3f, n: vec3f, y: vec3f, na: vec3f, wi: ptr<function, vec3f>) -> f32 {
    let to_light = y - p;
    let dist2 = dot(to_light, to_light);
    if (dist2 < 1e-12) {
        return 0.0;
    }
    *wi = to_light / sqrt(dist2);
    let cos_surface = dot(n, *wi);
    let cos_light_area = -dot(na, *wi);  // cos_l · area
    if (cos_surface <= 0.0 || cos_light_area <= 0.0) {
        return 0.0;
    }
    return cos_surface * cos_light_area / dist2;
}

// True when nothing lies between p + ε·n and the point at distance dist along wi.
fn unoccluded(p: vec3f, n: vec3f, wi: vec3f, dist: f32) -> bool {
    return intersect_scene(Ray(p + RAY_EPSILON * n, wi), dist * (1.0 - 1e-4) - RAY_EPSILON).t >= NO_HIT;
}

// Light from the point y of a light (area normal na) reflected once by planar mirror
// quad `index` to p: the mirror image y' of y is a virtual light, and the path
// p → mirror → y must be clear on both legs. Returns the geometry term times the
// mirror's reflectance.
fn via_mirror(p: vec3f, n: vec3f, y: vec3f, na: vec3f, index: u32) -> vec3f {
    let q = nee_quads[index];
    let o = vec3f(q.origin_x, q.origin_y, q.origin_z);
    let nm = normalize(cross(vec3f(q.u_x, q.u_y, q.u_z), vec3f(q.v_x, q.v_y, q.v_z)));
    let y_image = y - 2.0 * dot(y - o, nm) * nm;
    let na_image = na - 2.0 * dot(na, nm) * nm;
    var wi = vec3f(0.0);
    let g = light_geometry(p, n, y_image, na_image, &wi);
    if (g <= 0.0) {
        return vec3f(0.0);
    }
    // First leg: the first thing hit towards the virtual light must be this mirror.
    let hit = intersect_scene(Ray(p + RAY_EPSILON * n, wi), length(y_image - p));
    if (hit.object != index) {
        return vec3f(0.0);
    }
    let m = p + RAY_EPSILON * n + hit.t * wi;
    let side = select(-nm, nm, dot(nm, p - o) > 0.0);
    let to_light = y - m;
    let dist = length(to_light);
    if (dist <= RAY_EPSILON || !unoccluded(m, side, to_light / dist, dist)) {
        return vec3f(0.0);
    }
    return g * material_albedo(materials[q.material]);
}

// Radiance reflected towards the path by a Lambertian vertex (albedo left out):
// one point sampled uniformly on one emitting quad picked uniformly, reached
// directly and through each planar mirror.
fn direct_light(p: vec3f, n: vec3f, stream: u32, dim: u32) -> vec3f {
    if (LIGHT_COUNT == 0u) {
        return vec3f(0.0);
    }
    let k = min(u32(rand(stream, dim) * f32(LIGHT_COUNT)), max(LIGHT_COUNT, 1u) - 1u);
    let q = nee_quads[k];
    let u = vec3f(q.u_x, q.u_y, q.u_z);
    let v = vec3f(q.v_x, q.v_y, q.v_z);
    let y = vec3f(q.origin_x, q.origin_y, q.origin_z) + rand(stream, dim + 1u) * u + rand(stream, dim + 2u) * v;
    let na = cross(u, v);
    var total = vec3f(0.0);
    var wi = vec3f(0.0);
    let g = light_geometry(p, n, y, na, &wi);
    if (g > 0.0 && unoccluded(p, n, wi, length(y - p))) {
        total += vec3f(g);
    }
    for (var j = 0u; j < MIRROR_COUNT; j++) {
        total += via_mirror(p, n, y, na, LIGHT_COUNT + j);
    }
    // (1/π)·Le·G divided by the pdf 1/(count·area) of the light point (area is in G).
    return material_emission(materials[q.material]) * total * (f32(LIGHT_COUNT) / PI);
}

fn trace(first: Ray, stream: u32) -> vec3f {
    var ray = first;
    var throughput = vec3f(1.0);
    var radiance = vec3f(0.0);
    // `covered`: next-event estimation at the last diffuse vertex already counted a
    // light hit now (directly, or through one planar mirror: `via_mirror`).
    var covered = false;
    var mirrored = false;
    for (var depth = 0u; depth < params.max_depth; depth++) {
        let hit = intersect_scene(ray, NO_HIT);
        if (hit.t >= NO_HIT) {
            break;
        }
        let m = materials[hit.material];
        let front = dot(hit.normal, ray.direction) < 0.0;
        let n = select(-hit.normal, hit.normal, front);
        if (m.kind == MATERIAL_EMITTER) {
            if (!covered && front) {
                radiance += throughput * material_emission(m);
            }
            break;
        }
        let p = ray.origin + hit.t * ray.direction;
        let dim = 4u + depth * DIMS_PER_VERTEX;
        if (m.kind == MATERIAL_MIRROR) {
            let planar = hit.object >= LIGHT_COUNT && hit.object < LIGHT_COUNT + MIRROR_COUNT;
            covered = covered && planar && !mirrored;
            mirrored = true;
            throughput *= material_albedo(m);
            ray = Ray(p + RAY_EPSILON * n, reflect(ray.direction, n));
        } else {
            let albedo = surface_albedo(m, hit.uv);
            radiance += throughput * albedo * direct_light(p, n, stream, dim);
            throughput *= albedo;
            ray = Ray(p + RAY_EPSILON * n, cosine_direction(n, vec2f(rand(stream, dim + 3u), rand(stream, dim + 4u))));
            covered = true;
            mirrored = false;
        }
        if (depth + 1u >= params.rr_depth) {
            let survival = min(max(throughput.x, max(throughput.y, throughput.z)), MAX_SURVIVAL);
            // With survival == 0 every u in [0, 1) stops the path: no division by 0 below.
            if (rand(stream, dim + 5u) >= survival) {
                break;
            }
            throughput /= survival;
        }
    }
    return radiance;
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) gid: vec3u) {
    if (gid.x >= params.tile_width || gid.y >= params.tile_height) {
        return;
    }
    let col = params.tile_x + gid.x;
    let row = params.tile_y + gid.y;
    let stream = (row * params.image_width + col) ^ pcg_hash(params.seed);
    let jitter = vec2f(rand(stream, 0u), rand(stream, 1u));
    let ray = camera_ray(vec2f(f32(col), f32(row)) + jitter, vec2f(rand(stream, 2u), rand(stream, 3u)));
    let i = gid.y * params.tile_width + gid.x;
    accum[i] += vec4f(trace(ray, stream), 1.0);
}
