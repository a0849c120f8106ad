//! Deterministic per-sample random numbers.
//!
//! Each sample gets its own stream, keyed by (seed, pixel, sample index) only, so an image
//! does not depend on how pixels are spread over threads. The streams are counter-based
//! and use 32-bit arithmetic only, so the GPU (WGSL has no 64-bit integers) draws exactly
//! the same numbers: canopy-gpu's `rng.wgsl` is the same generator.
//!
//! With the [`Sampler::Sobol`] sampler a stream's first [`SOBOL_DIMENSIONS`] numbers
//! (the camera's pixel and lens samples and the first vertices' light and BSDF samples)
//! come from a pixel's own randomised Sobol sequence instead: the samples of a pixel then
//! cover each pair of dimensions evenly (a (0, m, 2)-net for every 2^m samples), and the
//! pixel's noise falls well below that of independent numbers. Every pair of dimensions is
//! a separately scrambled copy of the Sobol sequence's first two dimensions, its sample
//! order shuffled and its points Owen-scrambled by hashing (Burley, "Practical Hash-based
//! Owen Scrambling", JCGT 2020), as pbrt-v4's padded Sobol sampler does. Each point alone
//! is uniform, so the estimate stays unbiased whatever the number of samples.

use glam::{Vec2, Vec3};

/// How the numbers of a sample's stream are made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Sampler {
    /// The pixel's scrambled Sobol points for the first [`SOBOL_DIMENSIONS`] numbers,
    /// independent numbers after.
    #[default]
    Sobol,
    /// Independent numbers for every dimension.
    Independent,
}

impl Sampler {
    pub const ALL: [Sampler; 2] = [Sampler::Sobol, Sampler::Independent];

    pub fn name(self) -> &'static str {
        match self {
            Sampler::Sobol => "sobol",
            Sampler::Independent => "independent",
        }
    }

    /// Numbers of a stream that come from Sobol points.
    pub fn sobol_dimensions(self) -> u32 {
        match self {
            Sampler::Sobol => SOBOL_DIMENSIONS,
            Sampler::Independent => 0,
        }
    }
}

impl std::fmt::Display for Sampler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Sampler {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Sampler::ALL
            .into_iter()
            .find(|i| i.name() == s)
            .ok_or_else(|| format!("unknown sampler `{s}`, expected one of: sobol, independent"))
    }
}

/// Numbers of a [`Sampler::Sobol`] stream taken from Sobol points: the camera's pixel and
/// lens pairs and the first two or three vertices' light and BSDF samples. Later
/// vertices carry little of a pixel's variance (paper-1, paper-5 and the Cornell box had
/// the same noise with 12, 16, 24 and 32), and each pair costs a few hashes.
pub const SOBOL_DIMENSIONS: u32 = 12;
// A stream counts its Sobol dimensions in a byte.
const _: () = assert!(SOBOL_DIMENSIONS <= u8::MAX as u32);

/// Words of a stream: first the sampler's Sobol dimensions, then `pcg4d` (Jarzynski &
/// Olano, "Hash Functions for GPU Rendering", JCGT 2020) of (pixel, sample, seed key,
/// counter), four words per hash.
#[derive(Clone, Debug)]
pub struct Rng {
    key: [u32; 3],
    counter: u32,
    /// The last hash's words, of which `next` is the next to give. While the stream
    /// draws Sobol pairs no hash is made (`next` is 4), and `words[0]` keeps the second
    /// number of the pair whose first was just drawn.
    words: [u32; 4],
    next: u8,
    /// Sobol dimensions drawn so far (or skipped to start a pair), and how many the
    /// stream has. Bytes, so that a path and its stream fit 128 bytes in the renderer's
    /// stream, which copies them inline (a 144-byte copy was a call to `memmove`).
    dimension: u8,
    sobol_dimensions: u8,
}

/// A 32-bit integer hash (Wellons' "lowbias32"), to fold 64-bit keys into 32 bits.
#[inline]
pub fn lowbias32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

/// Folds a 64-bit key into 32 bits (the identity below 2^32).
#[inline]
pub fn fold64(x: u64) -> u32 {
    x as u32 ^ lowbias32((x >> 32) as u32)
}

/// The pcg4d hash: four 32-bit words in, four out.
#[inline]
pub fn pcg4d(mut v: [u32; 4]) -> [u32; 4] {
    for x in &mut v {
        *x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
    }
    let mix = |v: &mut [u32; 4]| {
        v[0] = v[0].wrapping_add(v[1].wrapping_mul(v[3]));
        v[1] = v[1].wrapping_add(v[2].wrapping_mul(v[0]));
        v[2] = v[2].wrapping_add(v[0].wrapping_mul(v[1]));
        v[3] = v[3].wrapping_add(v[1].wrapping_mul(v[2]));
    };
    mix(&mut v);
    for x in &mut v {
        *x ^= *x >> 16;
    }
    mix(&mut v);
    v
}

/// [`pcg4d`] of many inputs at once, `v[word][lane]`: the same operations lane by lane,
/// written as loops over lanes so that they compile to vector instructions.
#[inline(always)]
pub fn pcg4d_lanes<const L: usize>(v: &mut [[u32; L]; 4]) {
    for word in v.iter_mut() {
        for x in word.iter_mut() {
            *x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        }
    }
    let mix = |v: &mut [[u32; L]; 4]| {
        let [a, b, c, d] = v;
        let lanes = a
            .iter_mut()
            .zip(b.iter_mut())
            .zip(c.iter_mut())
            .zip(d.iter_mut());
        for (((a, b), c), d) in lanes {
            *a = a.wrapping_add(b.wrapping_mul(*d));
            *b = b.wrapping_add(c.wrapping_mul(*a));
            *c = c.wrapping_add(a.wrapping_mul(*b));
            *d = d.wrapping_add(b.wrapping_mul(*c));
        }
    };
    mix(v);
    for word in v.iter_mut() {
        for x in word.iter_mut() {
            *x ^= *x >> 16;
        }
    }
    mix(v);
}

/// Burley's hash-based permutation, in which each output bit depends only on the input
/// bits below it.
#[inline(always)]
fn laine_karras_permutation(mut x: u32, seed: u32) -> u32 {
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x
}

/// A nested uniform (Owen) scramble of the base-2 digits of `x`, most significant first:
/// each bit is flipped by a hash of the bits above it.
#[inline(always)]
pub fn owen_scramble(x: u32, seed: u32) -> u32 {
    laine_karras_permutation(x.reverse_bits(), seed).reverse_bits()
}

/// The second dimension of the Sobol sequence, bit-reversed, for every byte value of each
/// byte of the index (the dimension is linear over the index's bits). Its direction
/// numbers come from the polynomial x + 1: each is the one before xor itself shifted right.
const SOBOL_SECOND_REVERSED: [[u32; 256]; 4] = {
    let mut directions = [0u32; 32];
    directions[0] = 1 << 31;
    let mut bit = 1;
    while bit < 32 {
        directions[bit] = directions[bit - 1] ^ (directions[bit - 1] >> 1);
        bit += 1;
    }
    let mut table = [[0u32; 256]; 4];
    let mut byte = 0;
    while byte < 4 {
        let mut value = 0;
        while value < 256 {
            let mut x = 0u32;
            let mut b = 0;
            while b < 8 {
                if value >> b & 1 == 1 {
                    x ^= directions[byte * 8 + b];
                }
                b += 1;
            }
            table[byte][value] = x.reverse_bits();
            value += 1;
        }
        byte += 1;
    }
    table
};

/// The Sobol sequence's second dimension at `index`, bit-reversed.
#[inline(always)]
fn sobol_second_reversed(index: u32) -> u32 {
    let [a, b, c, d] = index.to_le_bytes();
    let t = &SOBOL_SECOND_REVERSED;
    t[0][a as usize] ^ t[1][b as usize] ^ t[2][c as usize] ^ t[3][d as usize]
}

/// Point `index` of the Sobol sequence's first two dimensions, as 32-bit fractions.
pub fn sobol_point(index: u32) -> [u32; 2] {
    [
        index.reverse_bits(),
        sobol_second_reversed(index).reverse_bits(),
    ]
}

/// Sample `sample` of a copy of [`sobol_point`]'s sequence made by three hashes: the
/// sample order shuffled (`seeds[0]`) and each coordinate Owen-scrambled.
#[inline(always)]
fn scrambled_sobol_point(sample: u32, seeds: [u32; 3]) -> [u32; 2] {
    let index = owen_scramble(sample, seeds[0]);
    // owen_scramble(x) is reverse(permutation(reverse(x))), and both coordinates are at
    // hand reversed: the first is reverse(index), the table holds the second reversed.
    let x = laine_karras_permutation(index, seeds[1]).reverse_bits();
    let y = laine_karras_permutation(sobol_second_reversed(index), seeds[2]).reverse_bits();
    [x, y]
}

/// The words of Sobol pair `pair` of the stream `key` ([`Rng::key`]): the pixel's own
/// copy of the sequence (hashed from pixel, seed and pair), its samples in shuffled
/// order, each point Owen-scrambled.
#[inline(always)]
pub fn sobol_pair(key: [u32; 3], pair: u32) -> [u32; 2] {
    let [pixel, sample, seed] = key;
    let [a, b, c, _] = pcg4d([pixel, seed, pair, SOBOL_TAG]);
    scrambled_sobol_point(sample, [a, b, c])
}

/// [`sobol_pair`]`(key, 0)` of many keys at once, `keys[word][lane]`: the same
/// operations lane by lane, in loops over lanes that compile to vector instructions.
#[inline(always)]
pub fn first_sobol_pairs<const L: usize>(keys: &[[u32; L]; 3]) -> [[u32; L]; 2] {
    let mut hashes = [keys[0], keys[2], [0; L], [SOBOL_TAG; L]];
    pcg4d_lanes(&mut hashes);
    let mut pairs = [[0; L]; 2];
    for lane in 0..L {
        let seeds = [0, 1, 2].map(|k| hashes[k][lane]);
        [pairs[0][lane], pairs[1][lane]] = scrambled_sobol_point(keys[1][lane], seeds);
    }
    pairs
}

/// The fourth word of the hash that seeds a Sobol pair: keeps it apart from the
/// independent stream's hashes (whose fourth word is a small counter).
const SOBOL_TAG: u32 = 0x50b0_1d5e;

/// The float [`Rng::next_f32`] makes of `word`.
#[inline(always)]
pub fn unit_f32(word: u32) -> f32 {
    (word >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

impl Rng {
    /// The independent generator of one sample of one pixel.
    pub fn for_sample(seed: u64, pixel: u64, sample: u64) -> Self {
        Self::for_sample_with(Sampler::Independent, seed, pixel, sample)
    }

    /// The generator of one sample of one pixel, drawing as `sampler` says.
    pub fn for_sample_with(sampler: Sampler, seed: u64, pixel: u64, sample: u64) -> Self {
        Self {
            key: Self::key(seed, pixel, sample),
            counter: 0,
            words: [0; 4],
            next: 4,
            dimension: 0,
            sobol_dimensions: sampler.sobol_dimensions() as u8,
        }
    }

    /// The key of a sample's stream: its first four independent words are
    /// `pcg4d([key[0], key[1], key[2], 0])`, its first Sobol pair is
    /// [`sobol_pair`]`(key, 0)`.
    #[inline(always)]
    pub fn key(seed: u64, pixel: u64, sample: u64) -> [u32; 3] {
        [fold64(pixel), fold64(sample), fold64(seed)]
    }

    /// The independent generator of `key` ([`Rng::key`]) that has drawn `drawn` (at most
    /// 4) of its first four words, `words`, computed by the caller.
    #[inline(always)]
    pub fn after_first_words(key: [u32; 3], words: [u32; 4], drawn: u32) -> Self {
        debug_assert!(drawn <= 4);
        Self {
            key,
            counter: 1,
            words,
            next: drawn as u8,
            dimension: 0,
            sobol_dimensions: 0,
        }
    }

    /// The [`Sampler::Sobol`] generator of `key` that has drawn its first Sobol pair,
    /// computed by the caller.
    #[inline(always)]
    pub fn after_first_sobol_pair(key: [u32; 3]) -> Self {
        let mut rng = Self::for_sample_with(Sampler::Sobol, 0, 0, 0);
        rng.key = key;
        rng.dimension = 2;
        rng
    }

    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        if self.dimension < self.sobol_dimensions {
            return self.next_sobol();
        }
        if self.next == 4 {
            let [a, b, c] = self.key;
            self.words = pcg4d([a, b, c, self.counter]);
            self.counter = self.counter.wrapping_add(1);
            self.next = 0;
        }
        let word = self.words[self.next as usize];
        self.next += 1;
        word
    }

    #[inline]
    fn next_sobol(&mut self) -> u32 {
        let dimension = self.dimension;
        self.dimension += 1;
        if dimension % 2 == 1 {
            return self.words[0];
        }
        let [first, second] = sobol_pair(self.key, u32::from(dimension / 2));
        self.words[0] = second;
        first
    }

    /// Two numbers uniform in `[0, 1)`, for a 2D sample. Within the Sobol dimensions they
    /// are one pair (a number left over from a pair is skipped), so the pixel's samples
    /// cover the square evenly.
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        if self.dimension % 2 == 1 && self.dimension < self.sobol_dimensions {
            self.dimension += 1;
        }
        let u = self.next_f32();
        Vec2::new(u, self.next_f32())
    }

    /// Uniform in `[0, 1)`.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        unit_f32(self.next_u32())
    }

    /// Uniform on the unit sphere.
    #[inline]
    pub fn unit_vector(&mut self) -> Vec3 {
        crate::sampling::unit_vector(self.next_2d())
    }

    /// Uniform in the unit disk.
    #[inline]
    pub fn in_unit_disk(&mut self) -> Vec2 {
        let u = self.next_2d();
        let r = u.x.sqrt();
        let phi = std::f32::consts::TAU * u.y;
        let (s, c) = phi.sin_cos();
        Vec2::new(r * c, r * s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hashing_in_lanes_is_hashing_each_lane() {
        let mut words = [[0u32; 5]; 4];
        let inputs: [[u32; 4]; 5] = [
            [0, 0, 0, 0],
            [1, 2, 3, 4],
            [u32::MAX, 7, 0x8000_0000, 1],
            [fold64(123_456_789_012), 77, 5, 0],
            [0xdead_beef, 0x1234_5678, 9, 0xffff],
        ];
        for (lane, input) in inputs.iter().enumerate() {
            for (word, &x) in input.iter().enumerate() {
                words[word][lane] = x;
            }
        }
        pcg4d_lanes(&mut words);
        for (lane, input) in inputs.iter().enumerate() {
            let expected = pcg4d(*input);
            assert_eq!(
                [0, 1, 2, 3].map(|w| words[w][lane]),
                expected,
                "lane {lane}"
            );
        }
    }

    /// Whether the points, `2^m` of them, put one point in every cell of every grid of
    /// `2^a x 2^(m - a)` cells: a (0, m, 2)-net in base 2.
    fn is_net(points: &[[u32; 2]]) -> bool {
        let m = points.len().trailing_zeros();
        assert_eq!(points.len(), 1 << m);
        (0..=m).all(|a| {
            let mut seen = vec![false; points.len()];
            points.iter().all(|&[x, y]| {
                let column = x.checked_shr(32 - a).unwrap_or(0) as usize;
                let row = y.checked_shr(32 - (m - a)).unwrap_or(0) as usize;
                !std::mem::replace(&mut seen[column << (m - a) | row], true)
            })
        })
    }

    #[test]
    fn the_sobol_points_are_nets_before_and_after_scrambling() {
        let plain: Vec<[u32; 2]> = (0..256).map(sobol_point).collect();
        for m in 0..=8 {
            assert!(is_net(&plain[..1 << m]), "2^{m} plain points");
        }
        // A pixel's samples of each pair, from the first on and from later aligned blocks.
        for (pixel, seed, pair) in [(0, 0, 0), (7, 1, 0), (123_456, 9, 3), (5, 2, 5)] {
            let key = Rng::key(seed, pixel, 0);
            let point = |sample: u32| sobol_pair([key[0], sample, key[2]], pair);
            for m in 0..=8 {
                for block in [0, 1, 3] {
                    let points: Vec<_> = (block << m..(block + 1) << m).map(point).collect();
                    assert!(
                        is_net(&points),
                        "pixel {pixel}, pair {pair}: block {block} of 2^{m}"
                    );
                }
            }
        }
        // Independent numbers are no net (this test can fail).
        let mut rng = Rng::for_sample(0, 0, 0);
        let random: Vec<[u32; 2]> = (0..64).map(|_| [rng.next_u32(), rng.next_u32()]).collect();
        assert!(!is_net(&random));
    }

    #[test]
    fn pairs_and_pixels_get_unrelated_copies_of_the_sequence() {
        let key = Rng::key(3, 77, 0);
        let first = |pixel: u32, pair: u32| -> Vec<f64> {
            (0..1024)
                .map(|sample| sobol_pair([pixel, sample, key[2]], pair)[0] as f64 / 2f64.powi(32))
                .collect()
        };
        let correlation = |a: &[f64], b: &[f64]| {
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            let (ma, mb) = (mean(a), mean(b));
            let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
            let var = |v: &[f64], m: f64| v.iter().map(|x| (x - m) * (x - m)).sum::<f64>();
            cov / (var(a, ma) * var(b, mb)).sqrt()
        };
        let base = first(key[0], 0);
        for other in [first(key[0], 1), first(key[0], 2), first(key[0] + 1, 0)] {
            assert!(correlation(&base, &other).abs() < 0.1);
        }
        assert!((base.iter().sum::<f64>() / 1024.0 - 0.5).abs() < 0.01);
    }

    #[test]
    fn sobol_streams_draw_pairs_then_independent_words() {
        let mut sobol = Rng::for_sample_with(Sampler::Sobol, 4, 5, 6);
        let key = Rng::key(4, 5, 6);
        // A 1D draw, then a 2D one: the pair's second number is skipped.
        assert_eq!(sobol.next_u32(), sobol_pair(key, 0)[0]);
        let u = sobol.next_2d();
        assert_eq!(u, Vec2::from(sobol_pair(key, 1).map(unit_f32)));
        for dimension in 4..SOBOL_DIMENSIONS {
            assert_eq!(
                sobol.next_u32(),
                sobol_pair(key, dimension / 2)[dimension as usize % 2]
            );
        }
        // Past them, the independent stream's words from its first on.
        let mut independent = Rng::for_sample(4, 5, 6);
        for _ in 0..9 {
            assert_eq!(sobol.next_u32(), independent.next_u32());
        }
        // An independent stream never skips.
        let mut a = Rng::for_sample(4, 5, 6);
        let mut b = Rng::for_sample(4, 5, 6);
        let words: Vec<u32> = (0..4).map(|_| b.next_u32()).collect();
        a.next_u32();
        assert_eq!(
            a.next_2d(),
            Vec2::new(unit_f32(words[1]), unit_f32(words[2]))
        );
        assert_eq!(a.next_u32(), words[3]);
    }

    #[test]
    fn the_first_pairs_in_lanes_are_the_pairs_one_at_a_time() {
        let keys: Vec<[u32; 3]> = (0..5)
            .map(|i| Rng::key(i * 31, i * 1_000_003, i * 7))
            .collect();
        let mut lanes = [[0u32; 5]; 3];
        for (lane, key) in keys.iter().enumerate() {
            for word in 0..3 {
                lanes[word][lane] = key[word];
            }
        }
        let pairs = first_sobol_pairs(&lanes);
        for (lane, &key) in keys.iter().enumerate() {
            assert_eq!([pairs[0][lane], pairs[1][lane]], sobol_pair(key, 0));
        }
    }

    #[test]
    fn same_key_gives_same_stream() {
        let a: Vec<u32> = (0..8)
            .map({
                let mut r = Rng::for_sample(1, 2, 3);
                move |_| r.next_u32()
            })
            .collect();
        let b: Vec<u32> = (0..8)
            .map({
                let mut r = Rng::for_sample(1, 2, 3);
                move |_| r.next_u32()
            })
            .collect();
        assert_eq!(a, b);
    }

    #[test]
    fn a_stream_does_not_repeat_its_words_soon() {
        let mut rng = Rng::for_sample(3, 4, 5);
        let words: std::collections::HashSet<u32> = (0..4096).map(|_| rng.next_u32()).collect();
        assert!(words.len() > 4090, "{}", words.len());
    }

    #[test]
    fn fold64_is_the_identity_below_two_to_the_32() {
        for x in [0u64, 1, 12345, u32::MAX as u64] {
            assert_eq!(fold64(x), x as u32);
        }
        assert_ne!(fold64(1 << 32), 0);
    }

    #[test]
    fn neighbouring_keys_give_different_streams() {
        let first = |s, p, i| Rng::for_sample(s, p, i).next_u32();
        assert_ne!(first(1, 2, 3), first(1, 2, 4));
        assert_ne!(first(1, 2, 3), first(1, 3, 3));
        assert_ne!(first(1, 2, 3), first(2, 2, 3));
    }

    #[test]
    fn floats_are_in_unit_interval_with_mean_one_half() {
        let mut rng = Rng::for_sample(7, 0, 0);
        let n = 100_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            let x = rng.next_f32();
            assert!((0.0..1.0).contains(&x));
            sum += x as f64;
        }
        assert!((sum / n as f64 - 0.5).abs() < 0.01);
    }

    #[test]
    fn unit_vectors_have_unit_length_and_zero_mean() {
        let mut rng = Rng::for_sample(7, 1, 0);
        let mut sum = Vec3::ZERO;
        for _ in 0..100_000 {
            let v = rng.unit_vector();
            assert!((v.length() - 1.0).abs() < 1e-5);
            sum += v;
        }
        assert!((sum / 100_000.0).length() < 0.01);
    }
}
