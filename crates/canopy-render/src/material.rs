//! Materials: how a surface scatters and emits light.

use crate::geometry::Surface;
use crate::rng::Rng;
use glam::Vec3;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Material {
    /// Ideal diffuse reflector, sampled by cosine (normal + random unit vector).
    Lambertian { albedo: Vec3 },
    /// Mirror reflection perturbed by `fuzz` (0 = perfect mirror).
    Metal { albedo: Vec3, fuzz: f32 },
    /// Glass-like: Snell refraction, total internal reflection and Schlick's
    /// approximation of the Fresnel reflectance. Attenuates nothing.
    Dielectric { ior: f32 },
    /// A diffuse emitter, emitting `radiance` on both sides; it scatters nothing.
    Emissive { radiance: Vec3 },
}

/// What a scattering event hands back to the integrator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scatter {
    pub attenuation: Vec3,
    pub direction: Vec3,
}

impl Material {
    /// Light emitted towards the viewer.
    #[inline]
    pub fn emitted(&self) -> Vec3 {
        match self {
            Material::Emissive { radiance } => *radiance,
            _ => Vec3::ZERO,
        }
    }

    /// Samples the scattered direction for a ray arriving along the unit vector `dir`,
    /// or `None` when the path ends here (absorbed or emitter).
    pub fn scatter(&self, dir: Vec3, surface: &Surface, rng: &mut Rng) -> Option<Scatter> {
        let geometric = surface.geometric_normal;
        let entering = dir.dot(geometric) < 0.0;
        // Normals facing the incoming ray.
        let (facing_geometric, facing_shading) = if entering {
            (geometric, surface.shading_normal)
        } else {
            (-geometric, -surface.shading_normal)
        };
        match *self {
            Material::Lambertian { albedo } => {
                let d = facing_shading + rng.unit_vector();
                // The sum can vanish (or dip under a smooth mesh's true surface).
                let direction = if d.length_squared() < 1e-12 || d.dot(facing_geometric) <= 0.0 {
                    facing_shading
                } else {
                    d.normalize()
                };
                Some(Scatter {
                    attenuation: albedo,
                    direction,
                })
            }
            Material::Metal { albedo, fuzz } => {
                let reflected = reflect(dir, facing_shading);
                let direction = (reflected + fuzz * rng.unit_vector()).normalize_or_zero();
                (direction.dot(facing_geometric) > 0.0).then_some(Scatter {
                    attenuation: albedo,
                    direction,
                })
            }
            Material::Dielectric { ior } => {
                let eta = if entering { 1.0 / ior } else { ior };
                let cos_theta = (-dir).dot(facing_shading).min(1.0);
                let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
                let total_internal = eta * sin_theta > 1.0;
                let direction = if total_internal || schlick(cos_theta, eta) > rng.next_f32() {
                    reflect(dir, facing_shading)
                } else {
                    refract(dir, facing_shading, eta, cos_theta)
                };
                Some(Scatter {
                    attenuation: Vec3::ONE,
                    direction: direction.normalize(),
                })
            }
            Material::Emissive { .. } => None,
        }
    }
}

#[inline]
fn reflect(v: Vec3, n: Vec3) -> Vec3 {
    v - 2.0 * v.dot(n) * n
}

/// Refraction of unit `v` through a surface with unit normal `n` facing it.
#[inline]
fn refract(v: Vec3, n: Vec3, eta: f32, cos_theta: f32) -> Vec3 {
    let perpendicular = eta * (v + cos_theta * n);
    let parallel = -(1.0 - perpendicular.length_squared()).abs().sqrt() * n;
    perpendicular + parallel
}

/// Schlick's approximation of the Fresnel reflectance.
#[inline]
fn schlick(cos_theta: f32, eta: f32) -> f32 {
    let r0 = ((1.0 - eta) / (1.0 + eta)).powi(2);
    r0 + (1.0 - r0) * (1.0 - cos_theta).powi(5)
}

#[cfg(test)]
mod tests {
    use super::*;

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
            let s = m.scatter(-Vec3::Y, &surface_facing_up(), &mut rng).unwrap();
            assert!(s.direction.y >= 0.0);
            assert!((s.direction.length() - 1.0).abs() < 1e-5);
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
            .scatter(d, &surface_facing_up(), &mut Rng::for_sample(0, 0, 0))
            .unwrap();
        assert!((s.direction - Vec3::new(1.0, 1.0, 0.0).normalize()).length() < 1e-6);
    }

    #[test]
    fn glass_at_normal_incidence_mostly_refracts_straight_through() {
        let m = Material::Dielectric { ior: 1.5 };
        let mut rng = Rng::for_sample(0, 0, 0);
        let through = (0..1000)
            .filter(|_| {
                let s = m.scatter(-Vec3::Y, &surface_facing_up(), &mut rng).unwrap();
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
            let s = m.scatter(d, &surface_facing_up(), &mut rng).unwrap();
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
            .scatter(
                -Vec3::Y,
                &surface_facing_up(),
                &mut Rng::for_sample(0, 0, 0)
            )
            .is_none());
    }
}
