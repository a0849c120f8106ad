// canopy's per-sample random streams, the same numbers as canopy-render's `Rng`: pcg4d
// (Jarzynski & Olano 2020) of (pixel, sample, seed key, counter), four words per hash.

fn pcg4d(input: vec4<u32>) -> vec4<u32> {
    var v = input * 1664525u + 1013904223u;
    v.x += v.y * v.w;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v.w += v.y * v.z;
    v ^= v >> vec4<u32>(16u);
    v.x += v.y * v.w;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v.w += v.y * v.z;
    return v;
}

struct Rng {
    key: vec3<u32>,
    counter: u32,
    words: vec4<u32>,
    next: u32,
}

// `seed_key` is the seed folded to 32 bits on the host (`fold64`); pixel and sample
// indices below 2^32 fold to themselves.
fn rng_for_sample(seed_key: u32, pixel: u32, sample: u32) -> Rng {
    return Rng(vec3<u32>(pixel, sample, seed_key), 0u, vec4<u32>(0u), 4u);
}

fn next_u32(rng: ptr<function, Rng>) -> u32 {
    if ((*rng).next == 4u) {
        (*rng).words = pcg4d(vec4<u32>((*rng).key, (*rng).counter));
        (*rng).counter += 1u;
        (*rng).next = 0u;
    }
    let word = (*rng).words[(*rng).next];
    (*rng).next += 1u;
    return word;
}

// Uniform in [0, 1).
fn next_f32(rng: ptr<function, Rng>) -> f32 {
    return f32(next_u32(rng) >> 8u) * (1.0 / 16777216.0);
}

const TAU: f32 = 6.283185307179586;

fn unit_vector(rng: ptr<function, Rng>) -> vec3<f32> {
    let z = 1.0 - 2.0 * next_f32(rng);
    let r = sqrt(max(1.0 - z * z, 0.0));
    let phi = TAU * next_f32(rng);
    return vec3<f32>(r * cos(phi), r * sin(phi), z);
}

fn in_unit_disk(rng: ptr<function, Rng>) -> vec2<f32> {
    let r = sqrt(next_f32(rng));
    let phi = TAU * next_f32(rng);
    return vec2<f32>(r * cos(phi), r * sin(phi));
}
