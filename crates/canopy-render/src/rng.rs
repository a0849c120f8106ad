//! Deterministic per-sample random numbers.
//!
//! Each sample gets its own stream, keyed by (seed, pixel, sample index) only, so an image
//! does not depend on how pixels are spread over threads. The streams are counter-based
//! and use 32-bit arithmetic only, so the GPU (WGSL has no 64-bit integers) draws exactly
//! the same numbers: canopy-gpu's `rng.wgsl` is the same generator.

use glam::{Vec2, Vec3};

/// Words of a stream: `pcg4d` (Jarzynski & Olano, "Hash Functions for GPU Rendering",
/// JCGT 2020) of (pixel, sample, seed key, counter), four words per hash.
#[derive(Clone, Debug)]
pub struct Rng {
    key: [u32; 3],
    counter: u32,
    words: [u32; 4],
    next: usize,
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

/// The float [`Rng::next_f32`] makes of `word`.
#[inline(always)]
pub fn unit_f32(word: u32) -> f32 {
    (word >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

impl Rng {
    /// The generator of one sample of one pixel.
    pub fn for_sample(seed: u64, pixel: u64, sample: u64) -> Self {
        Self {
            key: Self::key(seed, pixel, sample),
            counter: 0,
            words: [0; 4],
            next: 4,
        }
    }

    /// The key of [`Rng::for_sample`]'s stream: its first four words are
    /// `pcg4d([key[0], key[1], key[2], 0])`.
    #[inline(always)]
    pub fn key(seed: u64, pixel: u64, sample: u64) -> [u32; 3] {
        [fold64(pixel), fold64(sample), fold64(seed)]
    }

    /// The generator of `key` ([`Rng::key`]) that has drawn `drawn` (at most 4) of its
    /// first four words, `words`, computed by the caller.
    #[inline(always)]
    pub fn after_first_words(key: [u32; 3], words: [u32; 4], drawn: usize) -> Self {
        debug_assert!(drawn <= 4);
        Self {
            key,
            counter: 1,
            words,
            next: drawn,
        }
    }

    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        if self.next == 4 {
            let [a, b, c] = self.key;
            self.words = pcg4d([a, b, c, self.counter]);
            self.counter = self.counter.wrapping_add(1);
            self.next = 0;
        }
        let word = self.words[self.next];
        self.next += 1;
        word
    }

    /// Uniform in `[0, 1)`.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        unit_f32(self.next_u32())
    }

    /// Uniform on the unit sphere.
    #[inline]
    pub fn unit_vector(&mut self) -> Vec3 {
        let z = 1.0 - 2.0 * self.next_f32();
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = std::f32::consts::TAU * self.next_f32();
        let (s, c) = phi.sin_cos();
        Vec3::new(r * c, r * s, z)
    }

    /// Uniform in the unit disk.
    #[inline]
    pub fn in_unit_disk(&mut self) -> Vec2 {
        let r = self.next_f32().sqrt();
        let phi = std::f32::consts::TAU * self.next_f32();
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
