//! A small deterministic generator (xorshift) for the wide tree's unit tests, so that
//! they need no seed crate.

use glam::Vec3;

pub(crate) struct Numbers(pub u64);

impl Numbers {
    /// The next number in [0, 1).
    pub fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A point of the cube `[-scale, scale]^3`.
    pub fn vec(&mut self, scale: f32) -> Vec3 {
        Vec3::new(self.next(), self.next(), self.next()) * 2.0 * scale - Vec3::splat(scale)
    }
}
