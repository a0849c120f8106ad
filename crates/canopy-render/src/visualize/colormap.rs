//! The Turbo colour map (Mikhailov, Google 2019), by its published polynomial fit.

use glam::Vec3;

/// sRGB colour of `x` in [0, 1] (clamped): dark blue through green and yellow to dark red.
pub fn turbo(x: f32) -> Vec3 {
    let x = x.clamp(0.0, 1.0);
    let x2 = x * x;
    let x3 = x2 * x;
    let x4 = x2 * x2;
    let x5 = x4 * x;
    let r = 0.135_721_38 + 4.615_392_6 * x - 42.660_32 * x2 + 132.131_08 * x3 - 152.942_4 * x4
        + 59.286_38 * x5;
    let g = 0.091_402_61 + 2.194_188_4 * x + 4.842_966_6 * x2 - 14.185_033 * x3
        + 4.277_299_3 * x4
        + 2.829_566 * x5;
    let b = 0.106_673_3 + 12.641_946 * x - 60.582_05 * x2 + 110.362_77 * x3 - 89.903_11 * x4
        + 27.348_25 * x5;
    Vec3::new(r, g, b).clamp(Vec3::ZERO, Vec3::ONE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_from_dark_through_blue_and_green_to_red() {
        assert!(
            turbo(0.0).max_element() < 0.2,
            "starts dark: {}",
            turbo(0.0)
        );
        let blue = turbo(0.1);
        assert!(blue.z > blue.x && blue.z > blue.y, "{blue}");
        assert!(turbo(0.5).y > 0.8, "middle is green: {}", turbo(0.5));
        let red = turbo(1.0);
        assert!(red.x > red.y && red.x > red.z, "{red}");
    }
}
