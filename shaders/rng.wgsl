// rng.wgsl: per-sample random numbers for every bokehfit shader (design.md §5).
// A PCG hash (O'Neill's PCG-RXS-M-XS 32-bit output on one LCG step, as in
// Jarzynski and Olano, "Hash Functions for GPU Rendering", JCGT 2020) of
// (pixel, sample, dimension). NumPy twins: bokehfit/rng.py.

fn pcg_hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Random bits for one (pixel, sample, dimension): nested hashes, so that
// neighbouring indices give unrelated streams.
fn rand_bits(pixel: u32, sample: u32, dimension: u32) -> u32 {
    return pcg_hash(pixel ^ pcg_hash(sample ^ pcg_hash(dimension)));
}

// Top 24 bits scaled by 2^-24: uniform on [0, 1), never 1.0 (an f32 holds
// every multiple of 2^-24 below 1 exactly).
fn bits_to_unit_float(bits: u32) -> f32 {
    return f32(bits >> 8u) * 0x1p-24f;
}

fn rand_unit_float(pixel: u32, sample: u32, dimension: u32) -> f32 {
    return bits_to_unit_float(rand_bits(pixel, sample, dimension));
}
