//! The film: linear radiance per pixel, and its conversion to 8-bit sRGB.

use glam::Vec3;

#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    pub width: u32,
    pub height: u32,
    /// Mean radiance per pixel, row by row from the top.
    pub pixels: Vec<Vec3>,
}

impl Film {
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            pixels: vec![Vec3::ZERO; width as usize * height as usize],
        }
    }

    #[inline]
    pub fn pixel(&self, x: u32, y: u32) -> Vec3 {
        self.pixels[y as usize * self.width as usize + x as usize]
    }

    /// 8-bit sRGB, clamped, row by row from the top.
    pub fn to_srgb8(&self) -> Vec<u8> {
        self.pixels
            .iter()
            .flat_map(|p| {
                p.to_array()
                    .map(|c| (linear_to_srgb(c) * 255.0 + 0.5) as u8)
            })
            .collect()
    }
}

/// The sRGB transfer function on a value clamped to [0, 1].
#[inline]
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// The inverse of [`linear_to_srgb`] (the sRGB decoding of textures and drawn colours),
/// for a value in [0, 1].
#[inline]
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_end_points_and_midtone() {
        assert_eq!(linear_to_srgb(0.0), 0.0);
        assert!((linear_to_srgb(1.0) - 1.0).abs() < 1e-6);
        assert!((linear_to_srgb(0.214) - 0.5).abs() < 0.01);
        assert_eq!(linear_to_srgb(7.0), linear_to_srgb(1.0));
        assert_eq!(linear_to_srgb(f32::NAN), 0.0);
    }
}
