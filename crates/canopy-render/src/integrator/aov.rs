//! What a camera sample sees for the AOVs ([`crate::aov`]): its first hit, and the first
//! surface that is not a mirror or glass along the bounces the path would sample.

use super::path::{Tracer, Work};
use super::Probe;
use crate::aov::AovSample;
use crate::material::Facing;
use crate::rng::Rng;
use canopy_bvh::Ray;
use glam::Vec3;

impl Tracer<'_> {
    /// The AOV sample of the camera ray `ray`, drawing glass's choice between reflection
    /// and refraction from `rng` as a path would.
    pub fn aov_sample<P: Probe>(&self, ray: Ray, rng: &mut Rng, work: &mut Work<P>) -> AovSample {
        let scene = self.scene;
        let mut ray = ray;
        let mut weight = Vec3::ONE;
        let mut sample: Option<AovSample> = None;
        // At most as many bounces as a path has segments.
        for segment in 1..=scene.settings.max_depth {
            work.rays += 1;
            let Some(hit) = self.intersect(&ray, rng, work) else {
                let background = scene
                    .background
                    .radiance(ray.dir)
                    .clamp(Vec3::ZERO, Vec3::ONE);
                let escaped = AovSample::escaped(weight * background);
                return match sample {
                    Some(first) => AovSample {
                        albedo: escaped.albedo,
                        normal: escaped.normal,
                        ..first
                    },
                    None => escaped,
                };
            };
            let (surface, material) = scene.shade(&ray, &hit);
            let first = *sample.get_or_insert(AovSample {
                albedo: Vec3::ZERO,
                normal: Vec3::ZERO,
                depth: hit.t * ray.dir.length(),
                position: surface.p,
                instance: hit.inst,
                primitive: hit.prim,
            });
            let seen = AovSample {
                albedo: weight * material.albedo(),
                normal: Facing::new(ray.dir, &surface).shading,
                ..first
            };
            if !material.is_delta() || segment == scene.settings.max_depth {
                return seen;
            }
            match material.sample(ray.dir, &surface, rng) {
                Some(bounce) => {
                    weight *= bounce.weight;
                    ray = super::path::spawn_ray(&surface, bounce.direction);
                }
                None => return seen,
            }
        }
        sample.unwrap_or(AovSample::escaped(Vec3::ZERO))
    }
}
