// apertures.wgsl: uniform-area aperture samplers (design.md §3, §5).
// Each sample_<shape>(u) maps u in [0, 1)^2 to the unit-area shape at angle 0;
// its NumPy twin of the same name is in bokehfit/apertures/samplers.py and the
// tests compare the two. Polygons are fans of equal-area triangles: u.x picks
// the triangle and the position along its outer edge (continuous across
// triangles, so stratified u stays stratified), sqrt(u.y) the distance from
// the centre (uniform over each triangle).
// Needs: the SHAPE_* constants (generated include "shape_ids").

const PI: f32 = 3.14159265358979;
// 1/sqrt(pi): radius of the unit-area disc.
const CIRCLE_RADIUS: f32 = 0.5641895835477563;
// Unit-area star: pentagon of circumradius STAR_INNER_RADIUS with an equilateral
// triangle flush on each side; derivation in samplers.py (_star_radii).
const STAR_OUTER_RADIUS: f32 = 0.7884710176081364;
const STAR_INNER_RADIUS: f32 = 0.4315444902122231;

// sqrt(2 / (n sin(2 pi / n))): circumradius of the unit-area regular n-gon.
fn ngon_circumradius(n: u32) -> f32 {
    let nf = f32(n);
    return sqrt(2.0 / (nf * sin(2.0 * PI / nf)));
}

// Point of the fan triangle (centre, v_k, v_k+1): vertex k at angle 2 pi k / n.
fn sample_radial_fan(u: vec2f, n: u32, r_even: f32, r_odd: f32) -> vec2f {
    let nf = f32(n);
    let scaled = u.x * nf;
    let k = min(u32(floor(scaled)), n - 1u);
    let t = scaled - f32(k);
    let k1 = (k + 1u) % n;
    let a0 = 2.0 * PI * f32(k) / nf;
    let a1 = 2.0 * PI * f32(k + 1u) / nf;
    let r0 = select(r_even, r_odd, (k & 1u) == 1u);
    let r1 = select(r_even, r_odd, (k1 & 1u) == 1u);
    let edge = (1.0 - t) * r0 * vec2f(cos(a0), sin(a0)) + t * r1 * vec2f(cos(a1), sin(a1));
    return sqrt(u.y) * edge;
}

fn sample_ngon(u: vec2f, n: u32) -> vec2f {
    let r = ngon_circumradius(n);
    return sample_radial_fan(u, n, r, r);
}

fn sample_triangle(u: vec2f) -> vec2f { return sample_ngon(u, 3u); }
fn sample_pentagon(u: vec2f) -> vec2f { return sample_ngon(u, 5u); }
fn sample_hexagon(u: vec2f) -> vec2f { return sample_ngon(u, 6u); }

fn sample_star(u: vec2f) -> vec2f {
    return sample_radial_fan(u, 10u, STAR_OUTER_RADIUS, STAR_INNER_RADIUS);
}

fn sample_square(u: vec2f) -> vec2f {
    return u - vec2f(0.5);
}

fn sample_slit(u: vec2f, aspect: f32) -> vec2f {
    return vec2f((u.x - 0.5) * aspect, (u.y - 0.5) / aspect);
}

// Shirley and Chiu's concentric map. |a| > |b| implies a != 0; in the other
// branch b == 0 means a == b == 0, handled first: no division by zero.
fn sample_circle(u: vec2f) -> vec2f {
    let a = 2.0 * u.x - 1.0;
    let b = 2.0 * u.y - 1.0;
    if (a == 0.0 && b == 0.0) {
        return vec2f(0.0);
    }
    var r: f32;
    var phi: f32;
    if (abs(a) > abs(b)) {
        r = a;
        phi = (PI / 4.0) * (b / a);
    } else {
        r = b;
        phi = PI / 2.0 - (PI / 4.0) * (a / b);
    }
    return CIRCLE_RADIUS * r * vec2f(cos(phi), sin(phi));
}

// Dispatch on the sampler family (SHAPE_* ids generated from the Python registry).
fn sample_aperture(shape: u32, u: vec2f, blades: u32, aspect: f32) -> vec2f {
    switch shape {
        case SHAPE_SQUARE: { return sample_square(u); }
        case SHAPE_SLIT: { return sample_slit(u, aspect); }
        case SHAPE_NGON: { return sample_ngon(u, blades); }
        case SHAPE_STAR: { return sample_star(u); }
        default: { return sample_circle(u); }
    }
}

// Rotate counter-clockwise by the angle whose cosine and sine are given: p' = R p.
fn rotate(p: vec2f, cos_a: f32, sin_a: f32) -> vec2f {
    return vec2f(cos_a * p.x - sin_a * p.y, sin_a * p.x + cos_a * p.y);
}
