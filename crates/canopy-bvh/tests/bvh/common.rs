//! What several test binaries share.

/// A xorshift stream of numbers in [0, 1] from `seed`.
pub fn uniform(mut state: u32) -> impl FnMut() -> f32 {
    move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state as f32 / u32::MAX as f32
    }
}
