//! Materials: how a surface scatters and emits light.

mod fuzz;
pub mod ggx;
pub mod lanes;
mod pbr;

pub use pbr::Pbr;

use crate::geometry::Surface;
use crate::rng::Rng;
use crate::sampling::Frame;
use glam::{Vec2, Vec3};
use lanes::{LaneParams, LaneSample, Lobe};
use std::f32::consts::FRAC_1_PI;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Material {
    /// Ideal diffuse reflector, sampled by cosine (normal + random unit vector).
    Lambertian { albedo: Vec3 },
    /// Mirror reflection perturbed by `fuzz` (0 = perfect mirror): the mirror direction
    /// plus a uniform point on the sphere of radius `fuzz`, the lobe of "Ray Tracing in One
    /// Weekend", whose exact density is in [`fuzz`](self::fuzz).
    Metal { albedo: Vec3, fuzz: f32 },
    /// Glass-like: Snell refraction, total internal reflection and Schlick's
    /// approximation of the Fresnel reflectance. Attenuates nothing.
    Dielectric { ior: f32 },
    /// A diffuse emitter, emitting `radiance` on both sides; it scatters nothing.
    Emissive { radiance: Vec3 },
    /// glTF's metallic-roughness model: GGX over a Lambertian base (see [`Pbr`]).
    Pbr(Pbr),
}

/// A direction drawn from a material's scattering distribution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    /// Unit direction the path continues in.
    pub direction: Vec3,
    /// BSDF times cosine over the density: what the path's throughput is multiplied by.
    pub weight: Vec3,
    /// Density of `direction` per unit solid angle; meaningless when `delta`.
    pub pdf: f32,
    /// Drawn from a mirror or glass lobe: a single direction that light sampling can never
    /// hit, so an emitter found next gets its full weight.
    pub delta: bool,
}

/// The random numbers a material's sample is drawn from: `choice` picks a lobe (or
/// glass's reflection), `u` a direction. Drawn apart from the sample so that the wavefront
/// can draw each path's numbers, then sample a stage's vertices of one material together.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BsdfDraw {
    pub choice: f32,
    pub u: Vec2,
}

/// The normals of a hit turned to face the side the ray arrived from.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Facing {
    pub geometric: Vec3,
    pub shading: Vec3,
    pub entering: bool,
}

impl Facing {
    #[inline]
    pub fn new(dir: Vec3, surface: &Surface) -> Self {
        let entering = dir.dot(surface.geometric_normal) < 0.0;
        let (geometric, shading) = if entering {
            (surface.geometric_normal, surface.shading_normal)
        } else {
            (-surface.geometric_normal, -surface.shading_normal)
        };
        Self {
            geometric,
            shading,
            entering,
        }
    }
}

impl Material {
    /// Light emitted towards the viewer.
    #[inline]
    pub fn emitted(&self) -> Vec3 {
        match self {
            Material::Emissive { radiance } => *radiance,
            Material::Pbr(pbr) => pbr.emission,
            _ => Vec3::ZERO,
        }
    }

    /// The reflectance a denoiser's albedo image shows for this material, in [0, 1]:
    /// the diffuse colour, a metal's colour, the base colour of a glTF surface, white for
    /// glass, black for an emitter.
    pub fn albedo(&self) -> Vec3 {
        let albedo = match *self {
            Material::Lambertian { albedo } | Material::Metal { albedo, .. } => albedo,
            Material::Dielectric { .. } => Vec3::ONE,
            // It reflects nothing; and a black guide keeps a denoiser from bleeding a
            // bright lamp into the surface around it (measured on cornell at 16 spp:
            // relative error 0.0108 with a white guide, 0.0053 with black).
            Material::Emissive { .. } => Vec3::ZERO,
            Material::Pbr(pbr) => pbr.base_color,
        };
        albedo.clamp(Vec3::ZERO, Vec3::ONE)
    }

    /// Whether a path can continue from this material (emitters absorb).
    #[inline]
    pub fn scatters(&self) -> bool {
        !matches!(self, Material::Emissive { .. })
    }

    /// Whether every direction it scatters into is a single one (mirror, glass): light
    /// sampling cannot help there and is skipped.
    #[inline]
    pub fn is_delta(&self) -> bool {
        match *self {
            Material::Metal { fuzz, .. } => fuzz == 0.0,
            Material::Dielectric { .. } => true,
            Material::Lambertian { .. } | Material::Emissive { .. } | Material::Pbr(_) => false,
        }
    }

    /// Draws the direction a ray arriving along the unit vector `dir` continues in, or
    /// `None` when the path ends here (absorbed, an emitter, or drawn under the surface).
    ///
    /// Reflection never goes below the geometric surface: with smooth-shading normals a
    /// drawn direction can, and that sample is absorbed (its density stays counted, so
    /// [`Material::eval`] and [`Material::pdf`] describe exactly this distribution).
    #[inline]
    pub fn sample(&self, dir: Vec3, surface: &Surface, rng: &mut Rng) -> Option<BsdfSample> {
        let draw = self.draw(rng);
        self.sample_drawn(dir, surface, draw)
    }

    /// The random numbers [`Material::sample`] takes from `rng`.
    #[inline]
    pub fn draw(&self, rng: &mut Rng) -> BsdfDraw {
        match self {
            Material::Lambertian { .. } | Material::Metal { .. } => BsdfDraw {
                choice: 0.0,
                u: rng.next_2d(),
            },
            Material::Dielectric { .. } => BsdfDraw {
                choice: rng.next_f32(),
                u: Vec2::ZERO,
            },
            Material::Pbr(_) => {
                let choice = rng.next_f32();
                BsdfDraw {
                    choice,
                    u: rng.next_2d(),
                }
            }
            Material::Emissive { .. } => BsdfDraw::default(),
        }
    }

    /// [`Material::sample`] from the numbers `draw`.
    #[inline]
    pub fn sample_drawn(&self, dir: Vec3, surface: &Surface, draw: BsdfDraw) -> Option<BsdfSample> {
        let facing = Facing::new(dir, surface);
        if let Some(lane) = self.lane_params(&facing, draw) {
            return self.with_weight(lane.sample(dir, facing.shading, facing.geometric));
        }
        let Material::Pbr(pbr) = self else {
            return None; // an emitter
        };
        let frame = Frame::from_z(facing.shading);
        let wo = frame.to_local(-dir);
        let wi = pbr.sample(wo, draw.choice, draw.u)?;
        let pdf = pbr.pdf(wo, wi);
        let direction = frame.to_world(wi);
        (direction.dot(facing.geometric) > 0.0 && pdf > 0.0).then(|| BsdfSample {
            direction,
            weight: pbr.eval(wo, wi) / pdf,
            pdf,
            delta: false,
        })
    }

    /// How a Lambertian, metal or glass lobe's sample is drawn in [`lanes`] from the
    /// numbers `draw` at a hit seen as `facing`; `None` for other materials.
    #[inline]
    pub(crate) fn lane_params(&self, facing: &Facing, draw: BsdfDraw) -> Option<LaneParams> {
        let (lobe, param, u) = match *self {
            Material::Lambertian { .. } => (Lobe::Lambertian, 0.0, draw.u),
            Material::Metal { fuzz, .. } => (Lobe::Metal, fuzz, draw.u),
            Material::Dielectric { ior } => {
                let eta = if facing.entering { 1.0 / ior } else { ior };
                (Lobe::Dielectric, eta, Vec2::new(draw.choice, 0.0))
            }
            Material::Emissive { .. } | Material::Pbr(_) => return None,
        };
        Some(LaneParams { lobe, param, u })
    }

    /// The sample of a Lambertian, metal or glass lobe drawn in [`lanes`], with the
    /// material's weight; `None` where it does not scatter.
    #[inline]
    pub fn with_weight(&self, lane: LaneSample) -> Option<BsdfSample> {
        let (weight, delta) = match *self {
            Material::Lambertian { albedo } => (albedo, false),
            Material::Metal { albedo, fuzz } => (albedo, fuzz == 0.0),
            Material::Dielectric { .. } => (Vec3::ONE, true),
            Material::Emissive { .. } | Material::Pbr(_) => return None,
        };
        lane.scatters.then_some(BsdfSample {
            direction: lane.direction,
            weight,
            pdf: lane.pdf,
            delta,
        })
    }

    /// BSDF times cosine for light arriving from the unit direction `wi` and leaving
    /// against `dir` (zero for delta lobes, which no other direction can match).
    pub fn eval(&self, dir: Vec3, surface: &Surface, wi: Vec3) -> Vec3 {
        let facing = Facing::new(dir, surface);
        if wi.dot(facing.geometric) <= 0.0 {
            return Vec3::ZERO;
        }
        match *self {
            Material::Lambertian { albedo } => {
                albedo * (wi.dot(facing.shading).max(0.0) * FRAC_1_PI)
            }
            // The lobe is defined by its sampling: weight `albedo` for every direction.
            Material::Metal { albedo, fuzz } if fuzz > 0.0 => {
                albedo * fuzz::pdf(reflect(dir, facing.shading), fuzz, wi)
            }
            Material::Pbr(pbr) => {
                let frame = Frame::from_z(facing.shading);
                pbr.eval(frame.to_local(-dir), frame.to_local(wi))
            }
            _ => Vec3::ZERO,
        }
    }

    /// Density per solid angle with which [`Material::sample`] draws `wi` (zero for delta
    /// lobes).
    pub fn pdf(&self, dir: Vec3, surface: &Surface, wi: Vec3) -> f32 {
        let facing = Facing::new(dir, surface);
        match *self {
            Material::Lambertian { .. } => wi.dot(facing.shading).max(0.0) * FRAC_1_PI,
            Material::Metal { fuzz, .. } if fuzz > 0.0 => {
                fuzz::pdf(reflect(dir, facing.shading), fuzz, wi)
            }
            Material::Pbr(pbr) => {
                let frame = Frame::from_z(facing.shading);
                pbr.pdf(frame.to_local(-dir), frame.to_local(wi))
            }
            _ => 0.0,
        }
    }
}

#[inline(always)]
fn reflect(v: Vec3, n: Vec3) -> Vec3 {
    v - 2.0 * v.dot(n) * n
}

/// Refraction of unit `v` through a surface with unit normal `n` facing it.
#[inline(always)]
fn refract(v: Vec3, n: Vec3, eta: f32, cos_theta: f32) -> Vec3 {
    let perpendicular = eta * (v + cos_theta * n);
    let parallel = -(1.0 - perpendicular.length_squared()).abs().sqrt() * n;
    perpendicular + parallel
}

/// Schlick's approximation of the Fresnel reflectance (in multiplications, the same bits
/// in scalar and SIMD code).
#[inline(always)]
fn schlick(cos_theta: f32, eta: f32) -> f32 {
    let r = (1.0 - eta) / (1.0 + eta);
    let r0 = r * r;
    let m = 1.0 - cos_theta;
    let m2 = m * m;
    r0 + (1.0 - r0) * (m2 * m2 * m)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use glam::Vec2;

    /// Stratified directions over the whole sphere, equal-area cells of `4π / n²` sr,
    /// with the grid's poles on ±x so that lobes about +z fall where its cells are fine.
    pub(crate) fn stratified_sphere(n: usize) -> impl Iterator<Item = Vec3> {
        (0..n * n).map(move |k| {
            let u = Vec2::new(
                ((k / n) as f32 + 0.5) / n as f32,
                ((k % n) as f32 + 0.5) / n as f32,
            );
            let w = crate::sampling::uniform_sphere(u);
            Vec3::new(w.z, w.x, w.y)
        })
    }

    fn surface_facing_up() -> Surface {
        Surface {
            p: Vec3::ZERO,
            geometric_normal: Vec3::Y,
            shading_normal: Vec3::Y,
            error: 0.0,
        }
    }

    #[test]
    fn lambertian_scatters_into_the_upper_hemisphere() {
        let m = Material::Lambertian {
            albedo: Vec3::splat(0.5),
        };
        let mut rng = Rng::for_sample(0, 0, 0);
        for _ in 0..1000 {
            let s = m.sample(-Vec3::Y, &surface_facing_up(), &mut rng).unwrap();
            assert!(s.direction.y >= 0.0);
            assert!((s.direction.length() - 1.0).abs() < 1e-5);
        }
    }

    /// A tilted surface with a smooth-shading normal that differs from the geometric one.
    fn smooth_surface() -> Surface {
        Surface {
            p: Vec3::ZERO,
            geometric_normal: Vec3::Y,
            shading_normal: Vec3::new(0.3, 1.0, -0.2).normalize(),
            error: 0.0,
        }
    }

    #[test]
    fn sampled_weight_equals_eval_over_pdf() {
        let materials = [
            Material::Lambertian {
                albedo: Vec3::new(0.2, 0.5, 0.9),
            },
            Material::Metal {
                albedo: Vec3::new(0.9, 0.6, 0.3),
                fuzz: 0.4,
            },
            Material::Metal {
                albedo: Vec3::ONE,
                fuzz: 1.5,
            },
        ];
        let mut rng = Rng::for_sample(8, 8, 8);
        for m in materials {
            for surface in [surface_facing_up(), smooth_surface()] {
                for _ in 0..2000 {
                    let dir = (rng.unit_vector() - 2.0 * Vec3::Y).normalize();
                    let Some(s) = m.sample(dir, &surface, &mut rng) else {
                        continue;
                    };
                    assert!(!s.delta && s.pdf > 0.0, "{m:?} {dir} {s:?} {surface:?}");
                    let pdf = m.pdf(dir, &surface, s.direction);
                    let eval = m.eval(dir, &surface, s.direction);
                    assert!(
                        (pdf - s.pdf).abs() <= 1e-3 * pdf,
                        "{m:?}: {pdf} vs {}",
                        s.pdf
                    );
                    let weight = eval / pdf;
                    assert!(
                        (weight - s.weight).abs().max_element() < 1e-3,
                        "{m:?}: {weight} vs {}",
                        s.weight
                    );
                }
            }
        }
    }

    #[test]
    fn lambertian_reflects_its_albedo_and_nothing_below_the_surface() {
        // ∫ eval dω over the sphere = albedo (energy), by stratified directions.
        let m = Material::Lambertian {
            albedo: Vec3::splat(0.8),
        };
        let n = 300;
        let mut sum = 0.0f64;
        for i in 0..n {
            for j in 0..n {
                let u = glam::Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                let wi = crate::sampling::uniform_sphere(u);
                let f = m.eval(-Vec3::Y, &surface_facing_up(), wi);
                if wi.y <= 0.0 {
                    assert_eq!(f, Vec3::ZERO);
                }
                sum += f.x as f64;
            }
        }
        let energy = sum * 4.0 * std::f64::consts::PI / (n * n) as f64;
        assert!((energy - 0.8).abs() < 1e-3, "{energy}");
    }

    #[test]
    fn delta_lobes_are_never_evaluated() {
        for m in [
            Material::Dielectric { ior: 1.5 },
            Material::Metal {
                albedo: Vec3::ONE,
                fuzz: 0.0,
            },
        ] {
            assert!(m.is_delta());
            let d = Vec3::new(1.0, -1.0, 0.0).normalize();
            let s = m
                .sample(d, &surface_facing_up(), &mut Rng::for_sample(0, 0, 0))
                .unwrap();
            assert!(s.delta);
            assert_eq!(m.eval(d, &surface_facing_up(), s.direction), Vec3::ZERO);
            assert_eq!(m.pdf(d, &surface_facing_up(), s.direction), 0.0);
        }
    }

    #[test]
    fn perfect_mirror_reflects() {
        let m = Material::Metal {
            albedo: Vec3::ONE,
            fuzz: 0.0,
        };
        let d = Vec3::new(1.0, -1.0, 0.0).normalize();
        let s = m
            .sample(d, &surface_facing_up(), &mut Rng::for_sample(0, 0, 0))
            .unwrap();
        assert!((s.direction - Vec3::new(1.0, 1.0, 0.0).normalize()).length() < 1e-6);
    }

    #[test]
    fn glass_at_normal_incidence_mostly_refracts_straight_through() {
        let m = Material::Dielectric { ior: 1.5 };
        let mut rng = Rng::for_sample(0, 0, 0);
        let through = (0..1000)
            .filter(|_| {
                let s = m.sample(-Vec3::Y, &surface_facing_up(), &mut rng).unwrap();
                (s.direction + Vec3::Y).length() < 1e-5
            })
            .count();
        // Schlick gives 4% reflectance at normal incidence for ior 1.5.
        assert!((930..=990).contains(&through), "{through}");
    }

    #[test]
    fn grazing_exit_from_glass_is_totally_reflected() {
        let m = Material::Dielectric { ior: 1.5 };
        // Leaving the glass (travelling along the outward normal's side) at a grazing angle.
        let d = Vec3::new(1.0, 0.2, 0.0).normalize();
        let mut rng = Rng::for_sample(0, 0, 0);
        for _ in 0..100 {
            let s = m.sample(d, &surface_facing_up(), &mut rng).unwrap();
            assert!(s.direction.y < 0.0, "must stay inside: {:?}", s.direction);
        }
    }

    #[test]
    fn emitter_emits_and_does_not_scatter() {
        let m = Material::Emissive {
            radiance: Vec3::splat(4.0),
        };
        assert_eq!(m.emitted(), Vec3::splat(4.0));
        assert!(m
            .sample(
                -Vec3::Y,
                &surface_facing_up(),
                &mut Rng::for_sample(0, 0, 0)
            )
            .is_none());
    }
}
