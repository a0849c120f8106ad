//! Deterministic per-sample random numbers.
//!
//! Each sample gets its own generator seeded from (seed, pixel, sample index) only, so an
//! image does not depend on how pixels are spread over threads.

use glam::{Vec2, Vec3};

/// PCG32 (O'Neill 2014, XSH-RR output): small state, good statistics, fast.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

/// SplitMix64 finaliser: a bijective mix used to derive well-spread seeds.
#[inline]
fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl Rng {
    /// The generator of one sample of one pixel.
    pub fn for_sample(seed: u64, pixel: u64, sample: u64) -> Self {
        let key = splitmix64(splitmix64(splitmix64(seed) ^ pixel) ^ sample);
        let mut rng = Self {
            state: 0,
            inc: (splitmix64(key) << 1) | 1,
        };
        rng.next_u32();
        rng.state = rng.state.wrapping_add(key);
        rng.next_u32();
        rng
    }

    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        xorshifted.rotate_right((old >> 59) as u32)
    }

    /// Uniform in `[0, 1)`.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
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
