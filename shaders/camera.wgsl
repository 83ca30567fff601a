// camera.wgsl: the renderer camera of design.md §4 ("Renderer camera (seed)").
// A pinhole ray through a point of the pixel meets the focus plane (the plane
// perpendicular to the view axis at params.focus_distance); the lens ray leaves
// a point of the aperture (sample_aperture of apertures.wgsl, rotated by the
// angle, scaled to the equal-area size (f/N)·√π/2) and goes to that hit.
// Camera space: x right, y up (the aperture frame of design.md §2, seen from
// behind the camera), z forward along the view axis; metres. A point at depth
// d then blurs into the aperture's shape scaled by A·f·|d − d_f| / (d·d_f) on
// the sensor: upright behind the focus plane, turned by 180° in front of it.
// Needs: apertures.wgsl and a uniform `params: RenderParams` (bokehfit/scene/gpu.py).

struct Ray {
    origin: vec3f,
    direction: vec3f,
}

// Point of the aperture in camera space (x right, y up; metres).
fn aperture_point(u: vec2f) -> vec2f {
    let p = sample_aperture(params.shape, u, params.blades, params.aspect);
    return params.aperture_scale * rotate(p, params.cos_angle, params.sin_angle);
}

// Pinhole direction (x/z, y/z, 1) of a point of the image, given in pixels from
// the top-left corner of the whole image (row downward, design.md §2).
fn pinhole_direction(image_xy: vec2f) -> vec3f {
    let ndc = vec2f(
        2.0 * image_xy.x / f32(params.image_width) - 1.0,
        1.0 - 2.0 * image_xy.y / f32(params.image_height),
    );
    return vec3f(ndc.x * params.tan_half_x, ndc.y * params.tan_half_y, 1.0);
}

// Inverse of pinhole_direction: image position (pixels) of the slopes (x/z, y/z).
fn pinhole_image_xy(slope: vec2f) -> vec2f {
    let ndc = slope / vec2f(params.tan_half_x, params.tan_half_y);
    return vec2f(
        0.5 * (ndc.x + 1.0) * f32(params.image_width),
        0.5 * (1.0 - ndc.y) * f32(params.image_height),
    );
}

fn camera_to_world(v: vec3f) -> vec3f {
    let right = vec3f(params.right_x, params.right_y, params.right_z);
    let up = vec3f(params.up_x, params.up_y, params.up_z);
    let forward = vec3f(params.forward_x, params.forward_y, params.forward_z);
    return v.x * right + v.y * up + v.z * forward;
}

// World-space lens ray through the image point image_xy and the aperture point of u_lens.
fn camera_ray(image_xy: vec2f, u_lens: vec2f) -> Ray {
    let focus_hit = params.focus_distance * pinhole_direction(image_xy);
    let lens = vec3f(aperture_point(u_lens), 0.0);
    // |focus_hit − lens| ≥ focus_distance > 0 (the z components differ by it): no zero vector.
    let direction = normalize(focus_hit - lens);
    let position = vec3f(params.position_x, params.position_y, params.position_z);
    return Ray(position + camera_to_world(lens), camera_to_world(direction));
}
