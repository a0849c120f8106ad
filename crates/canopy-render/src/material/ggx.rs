//! The GGX (Trowbridge–Reitz) microfacet distribution, isotropic, in a local frame whose
//! +z is the shading normal: the normal distribution `D`, Smith's masking `G1` and the
//! height-correlated masking-shadowing `G2` (the glTF specification's choice, Heitz 2014),
//! and sampling of the normals visible from a direction (Heitz 2018, "Sampling the GGX
//! Distribution of Visible Normals").

use glam::{Vec2, Vec3};
use std::f32::consts::{PI, TAU};

/// Smallest width used: a glTF roughness of 0 is a mirror, which a lobe evaluated in
/// floats can only approach.
pub const MIN_ALPHA: f32 = 1e-3;

/// An isotropic GGX distribution of width `alpha` (glTF: roughness squared).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ggx {
    alpha: f32,
}

impl Ggx {
    pub fn from_roughness(roughness: f32) -> Self {
        Self {
            alpha: (roughness * roughness).max(MIN_ALPHA),
        }
    }

    pub fn alpha(&self) -> f32 {
        self.alpha
    }

    /// Density of microfacet normals per projected area: `D(h)`, `h.z > 0`.
    #[inline]
    pub fn d(&self, h: Vec3) -> f32 {
        if h.z <= 0.0 {
            return 0.0;
        }
        // sin²θ + α² cos²θ, with sin² from x and y: 1 − cos² cancels near the peak.
        let a2 = self.alpha * self.alpha;
        let t = (h.x * h.x + h.y * h.y) + a2 * h.z * h.z;
        a2 / (PI * t * t)
    }

    /// Smith's Λ for direction `w` (`w.z > 0`).
    #[inline]
    fn lambda(&self, w: Vec3) -> f32 {
        let cos2 = w.z * w.z;
        let sin2 = w.x * w.x + w.y * w.y;
        // α² tan²θ, written without the division by cos² that overflows at grazing angles.
        let a2_tan2 = self.alpha * self.alpha * sin2 / cos2;
        0.5 * ((1.0 + a2_tan2).sqrt() - 1.0)
    }

    /// The fraction of microfacets visible from `w`, Smith's `G1`.
    #[inline]
    pub fn g1(&self, w: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// Height-correlated masking and shadowing of the pair `wo`, `wi`.
    #[inline]
    pub fn g2(&self, wo: Vec3, wi: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(wo) + self.lambda(wi))
    }

    /// A microfacet normal drawn with the density of the normals visible from `wo`
    /// (`wo.z > 0`): `D_wo(h) = G1(wo) max(0, wo·h) D(h) / wo.z`.
    pub fn sample_visible_normal(&self, wo: Vec3, u: Vec2) -> Vec3 {
        // Stretch the view to the configuration of a unit-width distribution.
        let v = Vec3::new(self.alpha * wo.x, self.alpha * wo.y, wo.z).normalize();
        let len2 = v.x * v.x + v.y * v.y;
        let t1 = if len2 > 0.0 {
            Vec3::new(-v.y, v.x, 0.0) / len2.sqrt()
        } else {
            Vec3::X
        };
        let t2 = v.cross(t1);
        // A uniform point on the disk, its second half squeezed by the projection.
        let r = u.x.sqrt();
        let (sin, cos) = (TAU * u.y).sin_cos();
        let p1 = r * cos;
        let s = 0.5 * (1.0 + v.z);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * sin;
        let n = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * v;
        // Unstretch.
        Vec3::new(self.alpha * n.x, self.alpha * n.y, n.z.max(1e-6)).normalize()
    }

    /// Density per solid angle of `wi = reflect(-wo, h)` when `h` is drawn by
    /// [`Ggx::sample_visible_normal`]: `D_wo(h) / (4 wo·h)`.
    #[inline]
    pub fn reflection_pdf(&self, wo: Vec3, h: Vec3) -> f32 {
        if wo.z <= 0.0 {
            return 0.0;
        }
        self.g1(wo) * self.d(h) / (4.0 * wo.z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::tests::stratified_sphere as sphere;
    use crate::sampling::uniform_sphere;

    #[test]
    fn projected_normal_density_integrates_to_one() {
        // ∫ D(h) cosθ dω = 1, and ∫ D_wo(h) dω = 1 for any view.
        for roughness in [0.3, 0.6, 1.0] {
            let ggx = Ggx::from_roughness(roughness);
            let n = 1000;
            let dw = 4.0 * std::f64::consts::PI / (n * n) as f64;
            let total: f64 = sphere(n).map(|h| (ggx.d(h) * h.z.max(0.0)) as f64).sum();
            assert!(
                (total * dw - 1.0).abs() < 2e-3,
                "{roughness}: {}",
                total * dw
            );
            for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(-0.3, 0.9, 0.2)] {
                let wo = wo.normalize();
                let visible: f64 = sphere(n)
                    .map(|h| (ggx.g1(wo) * wo.dot(h).max(0.0) * ggx.d(h) / wo.z) as f64)
                    .sum();
                assert!(
                    (visible * dw - 1.0).abs() < 5e-3,
                    "{roughness} {wo}: {}",
                    visible * dw
                );
            }
        }
    }

    #[test]
    fn visible_normals_are_drawn_towards_the_view_and_above_the_surface() {
        let ggx = Ggx::from_roughness(0.7);
        let mut rng = crate::rng::Rng::for_sample(1, 2, 3);
        for _ in 0..10_000 {
            let wo = uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
            let wo = Vec3::new(wo.x, wo.y, wo.z.abs().max(1e-3)).normalize();
            let h = ggx.sample_visible_normal(wo, Vec2::new(rng.next_f32(), rng.next_f32()));
            assert!((h.length() - 1.0).abs() < 1e-5 && h.z > 0.0, "{h}");
            assert!(wo.dot(h) > -1e-4, "{wo} {h}");
        }
    }

    #[test]
    fn height_correlated_masking_lies_between_separable_and_the_minimum() {
        let ggx = Ggx::from_roughness(0.8);
        let (a, b) = (Vec3::new(0.8, 0.0, 0.6), Vec3::new(0.0, 0.28, 0.96));
        let g2 = ggx.g2(a, b);
        assert!(g2 >= ggx.g1(a) * ggx.g1(b) && g2 <= ggx.g1(a).min(ggx.g1(b)));
        assert_eq!(ggx.g2(Vec3::Z, Vec3::Z), 1.0);
    }
}
