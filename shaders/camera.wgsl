// camera.wgsl: the renderer camera of design.md §4 ("Renderer camera (seed)").
// A pinhole ray through a point of the pixel meets the focus plane (the plane
// perpendicular to the view axis at params.focus_distance); the lens ray leaves
// a point of the aperture (sample_aperture_params of apertures.wgsl: the shape
// rotated, with the real-lens features of design.md §3b, scaled to the equal-area
// size (f/N)·√π/2) and goes to that hit.
// Camera space: x right, y up (the aperture frame of design.md §2, seen from
// behind the camera), z forward along the view axis; metres. A point at depth
// d then blurs into the aperture's shape scaled by A·f·|d − d_f| / (d·d_f) on
// the sensor: upright behind the focus plane, turned by 180° in front of it.
// Needs: apertures.wgsl, a uniform `params: RenderParams` and the generated
// `lens_aperture()` (bokehfit/scene/renderer.py).

struct Ray {
    origin: vec3f,
    direction: vec3f,
}

// The lens's aperture as a disc at field position q shows it, on the near side of the
// focus plane or the far one (design.md §3b): a near disc shows −rim and −chromatic.
// Its 180° turn, the vignetting cut's included, needs nothing here: the lens ray's
// geometry makes it.
fn aperture_seen(q: vec2f, near: bool) -> ApertureParams {
    var a = lens_aperture();
    a.field_position = q;
    if (near) {
        a.rim = -a.rim;
        a.chromatic_red = -a.chromatic_red;
        a.chromatic_blue = -a.chromatic_blue;
    }
    return a;
}

// Point of the aperture a in camera space (x right, y up; metres) in .xy, and its
// weight (0 where the vignetting stops it) in .z, for one colour channel (CHANNEL_*).
fn aperture_point(u: vec2f, a: ApertureParams, channel: u32) -> vec3f {
    let s = sample_aperture_params(u, a, channel);
    return vec3f(params.aperture_scale * s.xy, s.z);
}

// Field position q of a point of the image (pixels from the top-left corner): its
// offset from the image centre in half-diagonals, y up (design.md §3b).
fn field_position(image_xy: vec2f) -> vec2f {
    let size = vec2f(params.image_size);
    let offset = image_xy - 0.5 * size;
    return image_to_aperture(offset.yx) / (0.5 * length(size));
}

// Pinhole direction (x/z, y/z, 1) of a point of the image, given in pixels from
// the top-left corner of the whole image (row downward, design.md §2).
fn pinhole_direction(image_xy: vec2f) -> vec3f {
    let half_size = 0.5 * vec2f(params.image_size);
    let ndc = image_to_aperture((image_xy - half_size).yx) / half_size;
    return vec3f(ndc * params.tan_half, 1.0);
}

// Inverse of pinhole_direction: image position (pixels) of the slopes (x/z, y/z).
fn pinhole_image_xy(slope: vec2f) -> vec2f {
    let ndc = slope / params.tan_half;
    let half_size = 0.5 * vec2f(params.image_size);
    return half_size + aperture_to_image(ndc * half_size).yx;
}

fn camera_to_world(v: vec3f) -> vec3f {
    return v.x * params.right + v.y * params.up + v.z * params.forward;
}

// World-space lens ray through the image point image_xy and the aperture point lens_xy
// (camera space, metres: aperture_point).
fn camera_ray(image_xy: vec2f, lens_xy: vec2f) -> Ray {
    let focus_hit = params.focus_distance * pinhole_direction(image_xy);
    let lens = vec3f(lens_xy, 0.0);
    // |focus_hit − lens| ≥ focus_distance > 0 (the z components differ by it): no zero vector.
    let direction = normalize(focus_hit - lens);
    return Ray(params.position + camera_to_world(lens), camera_to_world(direction));
}
