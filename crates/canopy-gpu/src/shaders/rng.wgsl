// canopy's per-sample random streams, the same numbers as canopy-render's `Rng`: first
// the stream's Sobol dimensions (a pixel's own scrambled copy of the Sobol sequence's
// first two dimensions for each pair), then pcg4d (Jarzynski & Olano 2020) of (pixel,
// sample, seed key, counter), four words per hash.

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

// Burley's hash-based permutation (each output bit depends on the input bits below it).
fn laine_karras_permutation(input: u32, seed: u32) -> u32 {
    var x = input + seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}

// The Sobol sequence's second dimension at `index`, bit-reversed (the CPU reads it from
// tables of bytes; the same bits).
fn sobol_second_reversed(index: u32) -> u32 {
    var direction = 0x80000000u;
    var x = 0u;
    for (var bit = 0u; bit < 32u; bit++) {
        if (((index >> bit) & 1u) == 1u) {
            x ^= direction;
        }
        direction ^= direction >> 1u;
    }
    return reverseBits(x);
}

const SOBOL_TAG: u32 = 0x50b01d5eu;

// Pair `pair` of the stream's Sobol dimensions: the sample's shuffled index, its point,
// each coordinate Owen-scrambled (rng.rs: `sobol_pair`).
fn sobol_pair(key: vec3<u32>, pair: u32) -> vec2<u32> {
    let seeds = pcg4d(vec4<u32>(key.x, key.z, pair, SOBOL_TAG));
    let index = reverseBits(laine_karras_permutation(reverseBits(key.y), seeds.x));
    let x = reverseBits(laine_karras_permutation(index, seeds.y));
    let y = reverseBits(laine_karras_permutation(sobol_second_reversed(index), seeds.z));
    return vec2<u32>(x, y);
}

struct Rng {
    key: vec3<u32>,
    counter: u32,
    words: vec4<u32>,
    next: u32,
    dimension: u32,
    sobol_dimensions: u32,
    pending: u32,
}

// `seed_key` is the seed folded to 32 bits on the host (`fold64`); pixel and sample
// indices below 2^32 fold to themselves. `sobol_dimensions` is 0 for independent numbers.
fn rng_for_sample(seed_key: u32, pixel: u32, sample: u32, sobol_dimensions: u32) -> Rng {
    return Rng(vec3<u32>(pixel, sample, seed_key), 0u, vec4<u32>(0u), 4u, 0u, sobol_dimensions, 0u);
}

fn next_u32(rng: ptr<function, Rng>) -> u32 {
    if ((*rng).dimension < (*rng).sobol_dimensions) {
        let dimension = (*rng).dimension;
        (*rng).dimension += 1u;
        if ((dimension & 1u) == 1u) {
            return (*rng).pending;
        }
        let pair = sobol_pair((*rng).key, dimension / 2u);
        (*rng).pending = pair.y;
        return pair.x;
    }
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

// Two numbers for a 2D sample: one Sobol pair (a number left over is skipped) while the
// stream's Sobol dimensions last.
fn next_2d(rng: ptr<function, Rng>) -> vec2<f32> {
    if (((*rng).dimension & 1u) == 1u && (*rng).dimension < (*rng).sobol_dimensions) {
        (*rng).dimension += 1u;
    }
    let u = next_f32(rng);
    return vec2<f32>(u, next_f32(rng));
}

const TAU: f32 = 6.283185307179586;

fn unit_vector(rng: ptr<function, Rng>) -> vec3<f32> {
    let u = next_2d(rng);
    let z = 1.0 - 2.0 * u.x;
    let r = sqrt(max(1.0 - z * z, 0.0));
    let phi = TAU * u.y;
    return vec3<f32>(r * cos(phi), r * sin(phi), z);
}

fn in_unit_disk(rng: ptr<function, Rng>) -> vec2<f32> {
    let u = next_2d(rng);
    let r = sqrt(u.x);
    let phi = TAU * u.y;
    return vec2<f32>(r * cos(phi), r * sin(phi));
}
