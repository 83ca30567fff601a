// scene.wgsl: what the path tracer's scenes are made of (bokehfit/scene/geometry.py).
// Analytic shapes only (no BVH: a Cornell box has a dozen of them): quads
// (parallelograms origin + α·u + β·v, 0 ≤ α, β ≤ 1), boxes turned about the
// vertical axis, spheres. Materials: Lambertian diffuse (optionally with a
// procedural checker-and-grid texture), perfect mirror, and one-sided area
// emitter (black, emitting on the side of cross(u, v)). Emitting quads come
// first in `quads` (light_count of them) so that next-event estimation can
// pick one; planar mirror quads follow (mirror_count of them), so that it can
// also reach a light through one mirror reflection (a virtual light).
// The scene itself is generated WGSL (bokehfit/scene/wgsl.py, include "scene"):
// the constants LIGHT_COUNT and MIRROR_COUNT, the private arrays `materials` and
// `nee_quads` (the lights, then the planar mirrors), and
// `fn intersect_scene(ray: Ray, t_max: f32) -> Hit`, the closest hit with
// 0 < t < t_max (t == NO_HIT when none), unrolled over the shapes with their
// values as literals, so that the shader compiler folds every constant.
// Needs: camera.wgsl (Ray) and the generated Material, Quad, Box, Sphere structs.

const MATERIAL_DIFFUSE: u32 = 0u;
const MATERIAL_MIRROR: u32 = 1u;
const MATERIAL_EMITTER: u32 = 2u;

// Distance that lifts a new ray's origin off its surface, metres: far above the
// f32 rounding of positions within a few metres (≈ 1e-7 m), far below any
// feature of the scenes (≥ 1 mm).
const RAY_EPSILON: f32 = 1e-5;
const NO_HIT: f32 = 3.0e38;

struct Hit {
    t: f32,
    normal: vec3f,      // geometric normal, unit, not yet turned towards the ray
    material: u32,
    uv: vec2f,          // texture coordinates, metres along the quad's edges
    object: u32,        // quad index; OBJECT_OTHER for boxes and spheres
}

const OBJECT_OTHER: u32 = 0xffffffffu;

// Diffuse albedo at a point: the base colour, darkened on every other checker
// square, and line_albedo on the thin grid lines (a line starts at every
// multiple of line_spacing and is line_width wide). NumPy twin: Material.albedo_at.
fn surface_albedo(m: Material, uv: vec2f) -> vec3f {
    var albedo = m.albedo;
    if (m.checker_size > 0.0) {
        let cell = floor(uv / m.checker_size);
        if (abs(cell.x + cell.y) % 2.0 == 1.0) {
            albedo *= m.checker_contrast;
        }
    }
    if (m.line_spacing > 0.0) {
        let along = fract(uv / m.line_spacing) * m.line_spacing;
        if (along.x < m.line_width || along.y < m.line_width) {
            albedo = vec3f(m.line_albedo);
        }
    }
    return albedo;
}

fn intersect_quad(ray: Ray, q: Quad, index: u32, t_max: f32, best: ptr<function, Hit>) {
    let o = q.origin;
    let u = q.u;
    let v = q.v;
    let n = cross(u, v);
    let denom = dot(n, ray.direction);
    if (abs(denom) < 1e-20) {
        return;  // parallel to the plane (and guards the division)
    }
    let t = dot(n, o - ray.origin) / denom;
    if (t <= 0.0 || t >= min(t_max, (*best).t)) {
        return;
    }
    let p = ray.origin + t * ray.direction - o;
    // p = α u + β v: α = n·(p × v)/|n|², β = n·(u × p)/|n|² (|n| > 0: quads are validated).
    let w = n / dot(n, n);
    let alpha = dot(w, cross(p, v));
    let beta = dot(w, cross(u, p));
    if (alpha < 0.0 || alpha > 1.0 || beta < 0.0 || beta > 1.0) {
        return;
    }
    (*best).t = t;
    (*best).normal = normalize(n);
    (*best).material = q.material;
    (*best).uv = vec2f(alpha * length(u), beta * length(v));
    (*best).object = index;
}

// Box of half-size b.half about b.center, its local x axis along (axis_xz.x, 0, axis_xz.y).
fn intersect_box(ray: Ray, b: Box, t_max: f32, best: ptr<function, Hit>) {
    let ax = vec3f(b.axis_xz.x, 0.0, b.axis_xz.y);
    let az = vec3f(-b.axis_xz.y, 0.0, b.axis_xz.x);
    let rel = ray.origin - b.center;
    let o = vec3f(dot(rel, ax), rel.y, dot(rel, az));
    var d = vec3f(dot(ray.direction, ax), ray.direction.y, dot(ray.direction, az));
    // Keep every component away from 0 so that 1/d stays finite (WGSL has no inf).
    d = select(d, select(vec3f(-1e-20), vec3f(1e-20), d >= vec3f(0.0)), abs(d) < vec3f(1e-20));
    let inv = 1.0 / d;
    let h = b.half;
    let t0 = (-h - o) * inv;
    let t1 = (h - o) * inv;
    let near = min(t0, t1);
    let far = max(t0, t1);
    let t_near = max(max(near.x, near.y), near.z);
    let t_far = min(min(far.x, far.y), far.z);
    if (t_far < t_near || t_far <= 0.0) {
        return;
    }
    let t = select(t_far, t_near, t_near > 0.0);
    if (t >= min(t_max, (*best).t)) {
        return;
    }
    // The face hit is the one where the local point lies farthest out, relative to h.
    let p = (o + t * d) / h;
    let a = abs(p);
    var local = vec3f(0.0, 0.0, sign(p.z));
    if (a.x >= a.y && a.x >= a.z) {
        local = vec3f(sign(p.x), 0.0, 0.0);
    } else if (a.y >= a.z) {
        local = vec3f(0.0, sign(p.y), 0.0);
    }
    (*best).t = t;
    (*best).normal = local.x * ax + vec3f(0.0, local.y, 0.0) + local.z * az;
    (*best).material = b.material;
    (*best).uv = vec2f(0.0);
    (*best).object = OBJECT_OTHER;
}

fn intersect_sphere(ray: Ray, s: Sphere, t_max: f32, best: ptr<function, Hit>) {
    let c = s.center;
    let oc = ray.origin - c;
    let b = dot(oc, ray.direction);
    // Distance² from the centre to the line, computed from the perpendicular part
    // (no cancellation between b² and |oc|² for a small, distant sphere).
    let perp = oc - b * ray.direction;
    let disc = s.radius * s.radius - dot(perp, perp);
    if (disc < 0.0) {
        return;
    }
    let root = sqrt(disc);
    var t = -b - root;
    if (t <= 0.0) {
        t = -b + root;
    }
    if (t <= 0.0 || t >= min(t_max, (*best).t)) {
        return;
    }
    (*best).t = t;
    (*best).normal = (ray.origin + t * ray.direction - c) / s.radius;
    (*best).material = s.material;
    (*best).uv = vec2f(0.0);
    (*best).object = OBJECT_OTHER;
}

fn no_hit() -> Hit {
    return Hit(NO_HIT, vec3f(0.0, 1.0, 0.0), 0u, vec2f(0.0), OBJECT_OTHER);
}
