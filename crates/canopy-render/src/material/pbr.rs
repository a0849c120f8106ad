//! glTF 2.0's metallic-roughness BRDF (the specification's appendix B): a GGX specular
//! lobe over a Lambertian base, mixed by `metallic` between
//! - a dielectric: `mix(base_color / π, specular, F(0.04))`, and
//! - a metal: `specular · F(base_color)`,
//!
//! with Schlick's Fresnel term at the half vector and `specular = D·G2 / (4 |n·l| |n·v|)`.
//!
//! Sampling picks the specular lobe (visible normals) or the cosine-weighted diffuse one
//! with a probability set by their estimated reflectance towards the viewer, and
//! [`Pbr::pdf`] is the density of that mixture, so MIS sees exactly what is drawn.

use super::ggx::Ggx;
use crate::sampling::luminance;
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, TAU};

/// Reflectance of a dielectric at normal incidence (index of refraction 1.5).
const DIELECTRIC_F0: f32 = 0.04;

/// A glTF metallic-roughness material at one point of a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pbr {
    /// Linear RGB in [0, 1]: the diffuse colour of a dielectric, the reflectance of a metal.
    pub base_color: Vec3,
    /// 0 dielectric, 1 metal; in between a linear blend.
    pub metallic: f32,
    /// Perceptual roughness in [0, 1]; the GGX width is its square.
    pub roughness: f32,
    /// Radiance the surface emits on both sides, beside what it reflects (glTF's
    /// emissive factor times its strength, times the emissive texture).
    pub emission: Vec3,
}

impl Pbr {
    fn ggx(&self) -> Ggx {
        Ggx::from_roughness(self.roughness)
    }

    /// Probability of drawing from the specular lobe for the view `wo` (local, `wo.z > 0`).
    fn specular_probability(&self, wo: Vec3) -> f32 {
        let fresnel = schlick_weight(wo.z);
        let dielectric_specular = DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * fresnel;
        let metal_specular = luminance(self.base_color + (Vec3::ONE - self.base_color) * fresnel);
        let specular = lerp(dielectric_specular, metal_specular, self.metallic);
        // The diffuse lobe's Fresnel factor is taken at the half vector, which can be far
        // from normal incidence even at grazing views: estimated at normal incidence, so
        // diffuse samples never carry weights much above the base colour.
        let diffuse = (1.0 - self.metallic) * (1.0 - DIELECTRIC_F0) * luminance(self.base_color);
        if specular + diffuse > 0.0 {
            specular / (specular + diffuse)
        } else {
            1.0
        }
    }

    /// BRDF times `wi.z` for the local directions `wo` (to the viewer) and `wi` (to the
    /// light), both above the surface; zero otherwise.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Vec3::ZERO;
        }
        let h = (wo + wi).normalize();
        let ggx = self.ggx();
        let specular = ggx.d(h) * ggx.g2(wo, wi) / (4.0 * wo.z * wi.z);
        let weight = schlick_weight(wo.dot(h).clamp(0.0, 1.0));
        let dielectric_fresnel = DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * weight;
        let metal_fresnel = self.base_color + (Vec3::ONE - self.base_color) * weight;
        let dielectric = self.base_color * ((1.0 - dielectric_fresnel) * FRAC_1_PI)
            + Vec3::splat(dielectric_fresnel * specular);
        let metal = metal_fresnel * specular;
        (dielectric * (1.0 - self.metallic) + metal * self.metallic) * wi.z
    }

    /// Density per solid angle with which [`Pbr::sample`] draws `wi` for the view `wo`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let p = self.specular_probability(wo);
        let h = (wo + wi).normalize();
        p * self.ggx().reflection_pdf(wo, h) + (1.0 - p) * wi.z * FRAC_1_PI
    }

    /// A direction to the light for the view `wo` from the uniform numbers `choice` and
    /// `u`, or `None` when the drawn direction falls below the surface.
    pub fn sample(&self, wo: Vec3, choice: f32, u: Vec2) -> Option<Vec3> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = if choice < self.specular_probability(wo) {
            let h = self.ggx().sample_visible_normal(wo, u);
            2.0 * wo.dot(h) * h - wo
        } else {
            cosine_hemisphere(u)
        };
        (wi.z > 0.0).then_some(wi)
    }
}

/// `(1 − cos)^5`, the weight of Schlick's Fresnel approximation.
#[inline]
fn schlick_weight(cos: f32) -> f32 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

#[inline]
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// Cosine-weighted direction about +z (Malley's method).
#[inline]
fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let r = u.x.sqrt();
    let (sin, cos) = (TAU * u.y).sin_cos();
    Vec3::new(r * cos, r * sin, (1.0 - u.x).max(0.0).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::tests::stratified_sphere as sphere;
    use crate::rng::Rng;
    use crate::sampling::uniform_sphere;

    fn materials() -> Vec<Pbr> {
        let mut all = Vec::new();
        for roughness in [0.05, 0.3, 0.6, 1.0] {
            for metallic in [0.0, 0.4, 1.0] {
                all.push(Pbr {
                    base_color: Vec3::new(0.9, 0.5, 0.1),
                    metallic,
                    roughness,
                    emission: Vec3::ZERO,
                });
            }
        }
        all
    }

    fn random_view(rng: &mut Rng) -> Vec3 {
        let w = uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        Vec3::new(w.x, w.y, w.z.abs().max(0.02)).normalize()
    }

    #[test]
    fn density_integrates_to_the_chance_of_staying_above_the_surface() {
        // ∫ pdf = 1 − P(drawn below); the latter is measured by drawing.
        let n = 1200;
        let mut rng = Rng::for_sample(5, 6, 7);
        for m in materials().into_iter().filter(|m| m.roughness >= 0.3) {
            for _ in 0..3 {
                let wo = random_view(&mut rng);
                let total: f64 = sphere(n).map(|wi| m.pdf(wo, wi) as f64).sum();
                let integral = total * 4.0 * std::f64::consts::PI / (n * n) as f64;
                let draws = 20_000;
                let above = (0..draws)
                    .filter(|_| {
                        let (c, u) = (rng.next_f32(), Vec2::new(rng.next_f32(), rng.next_f32()));
                        m.sample(wo, c, u).is_some()
                    })
                    .count() as f64
                    / draws as f64;
                assert!(
                    (integral - above).abs() < 0.015,
                    "{m:?} {wo}: ∫pdf {integral} vs {above}"
                );
            }
        }
    }

    #[test]
    fn sampling_follows_the_density() {
        // A histogram of drawn directions over (cosθ, φ) cells against ∫ pdf per cell.
        let (rows, cols) = (16, 32);
        let mut rng = Rng::for_sample(9, 9, 9);
        // The narrowest lobe is left out: midpoint quadrature cannot integrate its spike.
        for m in materials().into_iter().filter(|m| m.roughness >= 0.3) {
            let wo = random_view(&mut rng);
            let draws = 200_000;
            let mut counts = vec![0u32; rows * cols];
            for _ in 0..draws {
                let (c, u) = (rng.next_f32(), Vec2::new(rng.next_f32(), rng.next_f32()));
                if let Some(wi) = m.sample(wo, c, u) {
                    let row = ((wi.z * rows as f32) as usize).min(rows - 1);
                    let phi = wi.y.atan2(wi.x).rem_euclid(TAU);
                    let col = ((phi / TAU * cols as f32) as usize).min(cols - 1);
                    counts[row * cols + col] += 1;
                }
            }
            // Expected counts by midpoint quadrature inside each cell (z and φ uniform in
            // solid angle: dω = dz dφ).
            let sub = 12;
            let mut worst = 0.0f64;
            for row in 0..rows {
                for col in 0..cols {
                    let mut mass = 0.0f64;
                    for i in 0..sub {
                        for j in 0..sub {
                            let z = (row as f32 + (i as f32 + 0.5) / sub as f32) / rows as f32;
                            let phi =
                                (col as f32 + (j as f32 + 0.5) / sub as f32) / cols as f32 * TAU;
                            let s = (1.0 - z * z).max(0.0).sqrt();
                            let wi = Vec3::new(s * phi.cos(), s * phi.sin(), z);
                            mass += m.pdf(wo, wi) as f64;
                        }
                    }
                    let cell = (1.0 / rows as f64) * (TAU as f64 / cols as f64);
                    let expected = mass / (sub * sub) as f64 * cell * draws as f64;
                    let observed = counts[row * cols + col] as f64;
                    // Within 5 standard deviations plus the quadrature's error on peaks.
                    let allowed = 5.0 * expected.sqrt() + 0.02 * expected + 3.0;
                    worst = worst.max((observed - expected).abs() / allowed);
                }
            }
            assert!(
                worst <= 1.0,
                "{m:?} {wo}: worst cell at {worst} of its allowance"
            );
        }
    }

    #[test]
    fn sampled_directions_have_weights_eval_over_pdf_and_stay_finite() {
        let mut rng = Rng::for_sample(1, 1, 1);
        for m in materials() {
            for _ in 0..5000 {
                let wo = random_view(&mut rng);
                let (c, u) = (rng.next_f32(), Vec2::new(rng.next_f32(), rng.next_f32()));
                let Some(wi) = m.sample(wo, c, u) else {
                    continue;
                };
                let (f, pdf) = (m.eval(wo, wi), m.pdf(wo, wi));
                assert!(pdf > 0.0 && f.is_finite(), "{m:?} {wo} {wi}");
                // Single-scattering GGX never reflects more than arrives.
                assert!(
                    (f / pdf).max_element() < 4.0,
                    "{m:?} {wo} {wi}: {}",
                    f / pdf
                );
            }
        }
    }

    /// Directional albedo ∫ eval dω for the view `wo`, by stratified quadrature.
    fn albedo(m: &Pbr, wo: Vec3) -> Vec3 {
        let n = 1500;
        let total: glam::DVec3 = sphere(n).map(|wi| m.eval(wo, wi).as_dvec3()).sum();
        (total * (4.0 * std::f64::consts::PI / (n * n) as f64)).as_vec3()
    }

    #[test]
    fn white_metal_loses_only_what_single_scattering_loses() {
        // A white metal (F = 1) reflects everything as α → 0 and loses energy to the
        // multiple scattering GGX leaves out as roughness grows. At α = 1, D = 1/π and
        // the albedo at normal incidence has a closed form: with μ = cos θ_i and
        // G2 = 2μ / (1 + μ), E = ½ ∫₀¹ 2μ / (1 + μ) dμ = 1 − ln 2.
        let white = |roughness| Pbr {
            base_color: Vec3::ONE,
            metallic: 1.0,
            roughness,
            emission: Vec3::ZERO,
        };
        let e = |r| albedo(&white(r), Vec3::Z).x;
        let (smooth, mid, rough) = (e(0.25), e(0.6), e(1.0));
        assert!(smooth > 0.99 && smooth <= 1.001, "{smooth}");
        assert!(
            (rough - (1.0 - std::f32::consts::LN_2)).abs() < 2e-3,
            "{rough}"
        );
        assert!(smooth > mid && mid > rough, "{smooth} {mid} {rough}");
        // At grazing views more is lost.
        let grazing = albedo(&white(0.6), Vec3::new(0.95, 0.0, 0.312).normalize()).x;
        assert!(grazing < mid, "{grazing} vs {mid}");
    }

    #[test]
    fn a_white_dielectric_reflects_almost_everything_and_never_more() {
        let m = Pbr {
            base_color: Vec3::ONE,
            metallic: 0.0,
            roughness: 0.5,
            emission: Vec3::ZERO,
        };
        let e = albedo(&m, Vec3::new(0.3, 0.1, 0.9).normalize()).x;
        assert!(e > 0.9 && e <= 1.0, "{e}");
    }
}
