// apertures.wgsl: uniform-area aperture samplers (design.md §3, §5).
// Each sample_<shape>(u) maps u in [0, 1)^2 to the unit-area shape at angle 0;
// its NumPy twin of the same name is in bokehfit/apertures/samplers.py and the
// tests compare the two. Polygons are fans of equal-area triangles: u.x picks
// the triangle and the position along its outer edge (continuous across
// triangles, so stratified u stays stratified), sqrt(u.y) the distance from
// the centre (uniform over each triangle).
// Needs: the SHAPE_* and CHANNEL_* constants and the ApertureParams struct
// (generated include "shape_ids"), and mask_table_value(i) (generated include
// "mask_table": the CDF tables of a mask in a storage buffer where a shader binds
// them, kernel_mc.wgsl, pathtrace.wgsl and points.wgsl; in the test harnesses of
// single samplers a stub, and the mask shape is not drawn there).

// #include "mask_table"

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

// --- densities and inverses beside the samplers (twins in samplers.py, pbrt-v4 style) ------

// Float32 slack of the inside tests below: points this far outside (in unit-area units or
// barycentric weight) still count as inside, as rounding can put an edge's points there.
const INSIDE_TOLERANCE: f32 = 1e-6;

fn cross2(v: vec2f, w: vec2f) -> f32 {
    return v.x * w.y - v.y * w.x;
}

// Uniform point of triangle (a, b, c): sqrt(u.y) from a towards edge bc, u.x along it.
fn sample_uniform_triangle(u: vec2f, a: vec2f, b: vec2f, c: vec2f) -> vec2f {
    return a + sqrt(u.y) * ((1.0 - u.x) * (b - a) + u.x * (c - a));
}

// Barycentric weights of p for (a, b, c); the triangle must not be degenerate.
fn triangle_barycentric(p: vec2f, a: vec2f, b: vec2f, c: vec2f) -> vec3f {
    let d = cross2(b - a, c - a);
    let wb = cross2(p - a, c - a) / d;
    let wc = cross2(b - a, p - a) / d;
    return vec3f(1.0 - wb - wc, wb, wc);
}

fn uniform_triangle_pdf(p: vec2f, a: vec2f, b: vec2f, c: vec2f) -> f32 {
    let bary = triangle_barycentric(p, a, b, c);
    let inside = all(bary >= vec3f(-INSIDE_TOLERANCE));
    return select(0.0, 2.0 / abs(cross2(b - a, c - a)), inside);
}

fn invert_uniform_triangle_sample(p: vec2f, a: vec2f, b: vec2f, c: vec2f) -> vec2f {
    let bary = triangle_barycentric(p, a, b, c);
    let s = 1.0 - bary.x;
    return vec2f(select(0.0, bary.z / select(1.0, s, s > 0.0), s > 0.0), s * s);
}

fn circle_pdf(p: vec2f) -> f32 {
    return select(0.0, 1.0, length(p) <= CIRCLE_RADIUS * (1.0 + INSIDE_TOLERANCE));
}

// Inverse of the concentric map: |x| > |y| was its first branch (a = +-|p|/R, atan(y/x) =
// (pi/4) b/a), else b = +-|p|/R and atan(x/y) = (pi/4) a/b; y == 0 there means p == 0.
fn invert_circle_sample(p: vec2f) -> vec2f {
    let r = length(p) / CIRCLE_RADIUS;
    if (abs(p.x) > abs(p.y)) {
        let a = select(-r, r, p.x > 0.0);
        return 0.5 * (vec2f(a, a * atan(p.y / p.x) * (4.0 / PI)) + 1.0);
    }
    if (p.y == 0.0) {
        return vec2f(0.5);
    }
    let b = select(-r, r, p.y > 0.0);
    return 0.5 * (vec2f(b * atan(p.x / p.y) * (4.0 / PI), b) + 1.0);
}

// Inverse of sample_radial_fan: u in .xy and p's radial fraction (1 on the outline) in .z.
// The ray through p meets edge v_k -> v_k+1 at t = (v_k x p) / ((v_k - v_k+1) x p).
fn invert_radial_fan(p: vec2f, n: u32, r_even: f32, r_odd: f32) -> vec3f {
    let nf = f32(n);
    var theta = atan2(p.y, p.x);
    if (theta < 0.0) {
        theta += 2.0 * PI;
    }
    let k = min(u32(floor(theta * nf / (2.0 * PI))), n - 1u);
    let k1 = (k + 1u) % n;
    let a0 = 2.0 * PI * f32(k) / nf;
    let a1 = 2.0 * PI * f32(k + 1u) / nf;
    let v0 = select(r_even, r_odd, (k & 1u) == 1u) * vec2f(cos(a0), sin(a0));
    let v1 = select(r_even, r_odd, (k1 & 1u) == 1u) * vec2f(cos(a1), sin(a1));
    let d = cross2(v0 - v1, p);
    var t = 0.0;
    if (d != 0.0) {  // 0 only at p == 0
        t = clamp(cross2(v0, p) / d, 0.0, 1.0);
    }
    let fraction = length(p) / length(mix(v0, v1, t));
    var u0 = (f32(k) + t) / nf;
    if (u0 >= 1.0) {
        u0 -= 1.0;  // the +x edge wraps to 0
    }
    return vec3f(u0, fraction * fraction, fraction);
}

fn star_pdf(p: vec2f) -> f32 {
    let fraction = invert_radial_fan(p, 10u, STAR_OUTER_RADIUS, STAR_INNER_RADIUS).z;
    return select(0.0, 1.0, fraction <= 1.0 + INSIDE_TOLERANCE);
}

fn invert_star_sample(p: vec2f) -> vec2f {
    return invert_radial_fan(p, 10u, STAR_OUTER_RADIUS, STAR_INNER_RADIUS).xy;
}

// --- custom mask (design.md §3b); twin of sample_mask in bokehfit/apertures/mask.py -------
// The table (MaskTable.gpu_table) holds the marginal CDF over the rows (height + 1 values,
// bottom row first), then each row's conditional CDF over the columns (width + 1 values).

// Last index i in [0, n) with table[start + i] <= u (the CDF starts at 0 and ends at 1 > u),
// and the position of u inside that cell.
fn sample_cdf(start: u32, n: u32, u: f32) -> vec2f {
    var low = 0u;
    var high = n;
    while (high - low > 1u) {
        let middle = (low + high) / 2u;
        if (mask_table_value(start + middle) <= u) {
            low = middle;
        } else {
            high = middle;
        }
    }
    let c0 = mask_table_value(start + low);
    let width = mask_table_value(start + low + 1u) - c0;
    let fraction = select(0.0, (u - c0) / select(1.0, width, width > 0.0), width > 0.0);
    return vec2f(f32(low), fraction);
}

fn sample_mask(u: vec2f, width: u32, height: u32, cell: f32) -> vec2f {
    let row = sample_cdf(0u, height, u.y);
    let col = sample_cdf(height + 1u + u32(row.x) * (width + 1u), width, u.x);
    let x = (col.x + col.y - f32(0.5 * f32(width))) * cell;
    let y = (row.x + row.y - f32(0.5 * f32(height))) * cell;
    return vec2f(x, y);
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

// The one conversion between image offsets (row, col), row downward, and the aperture
// frame (x, y), y up (design.md §2): x = col, y = -row. Twins of image_to_aperture and
// aperture_to_image in bokehfit/apertures/shapes.py; nothing else flips an axis.
fn image_to_aperture(offset_rc: vec2f) -> vec2f {
    return vec2f(offset_rc.y, -offset_rc.x);
}

fn aperture_to_image(p: vec2f) -> vec2f {
    return vec2f(-p.y, p.x);
}

// --- real-lens features (design.md §3b); twins in bokehfit/apertures/samplers.py ----------

// Safeguarded Newton steps of sample_rounded_ngon (ROUNDED_NGON_NEWTON_STEPS in samplers.py).
const ROUNDED_NGON_NEWTON_STEPS: u32 = 6u;
// Below this roundness the rounded samplers use the straight polygon (ROUNDNESS_POLYGON).
const ROUNDNESS_POLYGON: f32 = 1e-7;

// x - sin(x) without cancellation: Taylor series (to x^15, by Horner) for |x| < 1, the
// coefficients 1/3!, -1/5!, ..., 1/15! of _SERIES in samplers.py.
fn x_minus_sin(x: f32) -> f32 {
    if (abs(x) >= 1.0) {
        return x - sin(x);
    }
    let x2 = x * x;
    var series = 1.0 / 1307674368000.0;
    series = series * x2 - 1.0 / 6227020800.0;
    series = series * x2 + 1.0 / 39916800.0;
    series = series * x2 - 1.0 / 362880.0;
    series = series * x2 + 1.0 / 5040.0;
    series = series * x2 - 1.0 / 120.0;
    series = series * x2 + 1.0 / 6.0;
    return x * x2 * series;
}

// Half angle of each blade arc, asin(roundness sin(pi/n)). Lavapipe's asin is off by ~1e-4
// just above 0.5 (roundness 1 of the hexagon) and its atan2 by ~2e-5 relative, which would
// move the arcs' ends off the vertices; one Newton step on sin (accurate to 6e-8) from the
// atan2 guess squares that error away.
fn rounded_ngon_half_angle(n: u32, roundness: f32) -> f32 {
    let s = roundness * sin(PI / f32(n));
    let guess = atan2(s, sqrt((1.0 - s) * (1.0 + s)));
    return guess - (sin(guess) - s) / cos(guess);
}

// Circumradius of the unit-area rounded n-gon: 1 / sqrt(n (sin cos(pi/n) + (2a - sin 2a) / (2 r^2))).
fn rounded_ngon_circumradius(n: u32, roundness: f32) -> f32 {
    if (roundness < ROUNDNESS_POLYGON) {
        return ngon_circumradius(n);
    }
    let nf = f32(n);
    let alpha = rounded_ngon_half_angle(n, roundness);
    let segment = x_minus_sin(2.0 * alpha) / (2.0 * roundness * roundness);
    return 1.0 / sqrt(nf * (sin(PI / nf) * cos(PI / nf) + segment));
}

// Area between the centre, a blade's first vertex and its arc up to the arc angle psi
// (twin of _arc_sector_area): the triangle (a q.y + h q.x)/2 plus the circular segment.
fn rounded_ngon_sector_area(psi: f32, alpha: f32, rho: f32, apothem: f32, half_chord: f32) -> f32 {
    let qx = apothem + 2.0 * rho * sin(0.5 * (alpha + psi)) * sin(0.5 * (alpha - psi));
    let qy = rho * sin(psi);
    return 0.5 * (apothem * qy + half_chord * qx) + 0.5 * rho * rho * x_minus_sin(psi + alpha);
}

// Uniform point of the unit-area rounded n-gon at angle 0: u.x picks the blade's sector and
// the arc angle psi whose sector area is t/n (Newton, bisection where a step leaves the
// bracket), sqrt(u.y) the distance. Same maths as the NumPy twin (_arc_sector_area).
fn sample_rounded_ngon(u: vec2f, n: u32, roundness: f32) -> vec2f {
    if (roundness < ROUNDNESS_POLYGON) {
        return sample_ngon(u, n);
    }
    let nf = f32(n);
    let radius = rounded_ngon_circumradius(n, roundness);
    let alpha = rounded_ngon_half_angle(n, roundness);
    let rho = radius / roundness;
    let half_chord = radius * sin(PI / nf);
    let apothem = radius * cos(PI / nf);
    let scaled = u.x * nf;
    let k = min(floor(scaled), nf - 1.0);
    let target_area = (scaled - k) / nf;
    var low = -alpha;
    var high = alpha;
    var psi = -alpha + 2.0 * alpha * (scaled - k);
    let one_minus_base = 2.0 * sin(0.5 * alpha) * sin(0.5 * alpha);
    for (var i = 0u; i < ROUNDED_NGON_NEWTON_STEPS; i++) {
        let f = rounded_ngon_sector_area(psi, alpha, rho, apothem, half_chord) - target_area;
        let sp = sin(0.5 * psi);
        let slope = 0.5 * rho * (rho * (one_minus_base + 2.0 * cos(alpha) * sp * sp) + apothem * cos(psi));
        if (f > 0.0) {
            high = psi;
        } else {
            low = psi;
        }
        let next_psi = psi - f / slope;
        psi = select(0.5 * (low + high), next_psi, next_psi >= low && next_psi <= high);
    }
    let qx = apothem + 2.0 * rho * sin(0.5 * (alpha + psi)) * sin(0.5 * (alpha - psi));
    let qy = rho * sin(psi);
    let phi = 2.0 * PI * (k + 0.5) / nf;
    return sqrt(u.y) * rotate(vec2f(qx, qy), cos(phi), sin(phi));
}

// p's blade sector k (.x), its direction's angle from the sector's middle (.y), the arc angle
// psi of that direction (.z; 0 for the polygon) and p's radial fraction (.w, 1 on the
// outline). Twin of _rounded_ngon_polar: the ray t (cos, sin) meets the arc's circle
// (centre (c, 0)) at t = (rho^2 - c^2) / (sqrt(rho^2 - c^2 sin^2) - c cos).
fn rounded_ngon_polar(p: vec2f, n: u32, roundness: f32) -> vec4f {
    let nf = f32(n);
    var theta = atan2(p.y, p.x);
    if (theta < 0.0) {
        theta += 2.0 * PI;
    }
    let k = min(floor(theta * nf / (2.0 * PI)), nf - 1.0);
    let local = theta - 2.0 * PI * (k + 0.5) / nf;
    if (roundness < ROUNDNESS_POLYGON) {
        let apothem = ngon_circumradius(n) * cos(PI / nf);
        return vec4f(k, local, 0.0, length(p) * cos(local) / apothem);
    }
    let radius = rounded_ngon_circumradius(n, roundness);
    let alpha = rounded_ngon_half_angle(n, roundness);
    let rho = radius / roundness;
    let plus = radius * cos(PI / nf) + 2.0 * rho * sin(0.5 * alpha) * sin(0.5 * alpha);  // rho + c
    let minus = 2.0 * rho - plus;  // rho - c
    let c = plus - rho;
    let cs = c * sin(local);
    let distance = plus * minus / (sqrt(rho * rho - cs * cs) - c * cos(local));
    // q - (c, 0) = rho (cos psi, sin psi); atan2 rather than lavapipe's imprecise asin.
    let psi = atan2(distance * sin(local), distance * cos(local) - c);
    return vec4f(k, local, psi, length(p) / distance);
}

fn rounded_ngon_pdf(p: vec2f, n: u32, roundness: f32) -> f32 {
    return select(0.0, 1.0, rounded_ngon_polar(p, n, roundness).w <= 1.0 + INSIDE_TOLERANCE);
}

// Inverse of sample_rounded_ngon for p inside the shape.
fn invert_rounded_ngon_sample(p: vec2f, n: u32, roundness: f32) -> vec2f {
    let polar = rounded_ngon_polar(p, n, roundness);
    let nf = f32(n);
    var t: f32;
    if (roundness < ROUNDNESS_POLYGON) {
        // The straight fan: tan of the angle from the middle over tan of the half span.
        t = 0.5 * (1.0 + tan(polar.y) / tan(PI / nf));
    } else {
        let radius = rounded_ngon_circumradius(n, roundness);
        let alpha = rounded_ngon_half_angle(n, roundness);
        t = nf * rounded_ngon_sector_area(polar.z, alpha, radius / roundness, radius * cos(PI / nf), radius * sin(PI / nf));
    }
    var u0 = (polar.x + t) / nf;
    if (u0 >= 1.0) {
        u0 -= 1.0;  // the +x edge wraps to 0
    }
    return vec2f(u0, polar.w * polar.w);
}

// Radial fraction in [0, 1) with CDF (1 - rim) r^2 + rim r^4 (the rim profile), from uniform s.
fn rim_radius(s: f32, rim: f32) -> f32 {
    let a = 1.0 - rim;
    // The denominator is 0 only at rim = 1 and s = 0, where the radius is 0.
    let denominator = a + sqrt(a * a + 4.0 * rim * s);
    let positive = denominator > 0.0;
    return select(0.0, sqrt(2.0 * s / select(1.0, denominator, positive)), positive);
}

// Anamorphic squeeze at unit area: (x / sqrt(squeeze), y * sqrt(squeeze)).
fn apply_squeeze(p: vec2f, squeeze: f32) -> vec2f {
    let root = sqrt(squeeze);
    return vec2f(p.x / root, p.y * root);
}

// 1 inside the barrel's circle (radius * R0 about shift * R0 * q), 0 outside.
fn vignetting_weight(p: vec2f, field_position: vec2f, radius: f32, shift: f32) -> f32 {
    let offset = p - shift * CIRCLE_RADIUS * field_position;
    let r = radius * CIRCLE_RADIUS;
    return select(0.0, 1.0, dot(offset, offset) <= r * r);
}

// The whole aperture of ApertureParams (generated from APERTURE_PARAM_FIELDS): the point in
// .xy and its weight (0 where the barrel stops it) in .z; channel is a CHANNEL_* id.
// Twin of Aperture.sample in bokehfit/apertures/shapes.py.
fn sample_aperture_params(u: vec2f, params: ApertureParams, channel: u32) -> vec3f {
    var v = u;
    var p: vec2f;
    let fan = params.shape == SHAPE_NGON || params.shape == SHAPE_STAR
        || (params.shape == SHAPE_SQUARE && params.roundness != 0.0);
    if (params.shape == SHAPE_MASK) {
        p = sample_mask(u, params.mask_width, params.mask_height, params.mask_cell);
    } else if (fan) {
        if (params.rim != 0.0) {
            let r = rim_radius(u.y, params.rim);
            v = vec2f(u.x, r * r);
        }
        if (params.shape == SHAPE_STAR) {
            p = sample_star(v);
        } else if (params.shape == SHAPE_SQUARE) {
            // The rounded square is the rounded ngon 4 turned by 45 degrees.
            p = rotate(sample_rounded_ngon(v, 4u, params.roundness), cos(PI / 4.0), sin(PI / 4.0));
        } else {
            p = sample_rounded_ngon(v, params.blades, params.roundness);
        }
    } else {
        p = sample_aperture(params.shape, u, params.blades, params.aspect);
        if (params.rim != 0.0) {
            var fraction: f32;
            if (params.shape == SHAPE_CIRCLE) {
                fraction = length(p) / CIRCLE_RADIUS;
            } else {
                let half_size = select(vec2f(0.5), vec2f(0.5 * params.aspect, 0.5 / params.aspect), params.shape == SHAPE_SLIT);
                fraction = max(abs(p.x) / half_size.x, abs(p.y) / half_size.y);
            }
            if (fraction > 0.0) {
                p = p * (rim_radius(fraction * fraction, params.rim) / fraction);
            }
        }
    }
    p = rotate(p, params.cos_angle, params.sin_angle);
    if (params.squeeze != 1.0) {
        p = apply_squeeze(p, params.squeeze);
    }
    var weight = 1.0;
    if (params.vignetting_radius > 0.0) {
        weight = vignetting_weight(p, params.field_position, params.vignetting_radius, params.vignetting_shift);
    }
    var scale = 1.0;
    if (channel == CHANNEL_RED) {
        scale = 1.0 + params.chromatic_red;
    } else if (channel == CHANNEL_BLUE) {
        scale = 1.0 + params.chromatic_blue;
    }
    return vec3f(p * scale, weight);
}
