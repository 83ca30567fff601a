// tonemap.wgsl: the display transform of renders, linear light to 8-bit sRGB.
// NumPy twins: tone_map_srgb8 in bokehfit/scene/images.py (the PNGs of `bokehfit render`)
// and srgb_encode in bokehfit/io/colour.py. The viewer's page shows its frames through
// this one function (display.wgsl), so the page and a PNG of the same render agree.
//
// Scaled by 2^exposure_ev, clipped to [0, 1], rounded to 16 bits (the level that indexes
// the NumPy twin's table, srgb_display_lut), sRGB-encoded (IEC 61966-2-1) and rounded to
// 8 bits; both roundings take halves to even, as NumPy's do. The twins agree but where
// float32 rounding puts a value on the other side of a rounding boundary (one code value;
// tests/test_tonemap.py). Non-finite input is the adapter's business (the NumPy twin maps
// NaN to 0 and +inf to 255); the renderers write finite radiance.

fn srgb_encode(c: vec3f) -> vec3f {
    let low = 12.92 * c;
    let high = 1.055 * pow(max(c, vec3f(0.0)), vec3f(1.0 / 2.4)) - 0.055;
    return select(high, low, c <= vec3f(0.0031308));
}

// The 8-bit sRGB code (0 to 255) of each channel of one linear pixel.
fn tone_map_srgb8(linear: vec3f, exposure_ev: f32) -> vec3u {
    let scaled = clamp(linear * exp2(exposure_ev), vec3f(0.0), vec3f(1.0));
    let level = round(scaled * 65535.0) / 65535.0;
    return vec3u(round(clamp(srgb_encode(level), vec3f(0.0), vec3f(1.0)) * 255.0));
}
