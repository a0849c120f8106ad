//! What a camera sample sees for the AOVs ([`crate::aov`]): its first hit, and the first
//! surface that is not a mirror or glass along the bounces its path samples. A path
//! carries an [`AovTrack`] through its vertices (both schedules), so the AOVs cost no
//! rays of their own; [`Tracer::aov_sample`] traces them alone, for the GPU's samples.

use super::path::{Tracer, Work};
use super::Probe;
use crate::aov::AovSample;
use crate::geometry::Surface;
use crate::material::{Facing, Material};
use crate::rng::Rng;
use canopy_bvh::{Hit, Ray};
use glam::Vec3;

/// What a path has seen for the AOVs so far.
#[derive(Clone, Copy, Debug)]
pub(super) struct AovTrack {
    /// The product of the mirrors' and glass's albedos passed so far.
    weight: Vec3,
    /// Whether the surface the AOVs show has been found (or the ray escaped).
    done: bool,
    pub sample: AovSample,
}

impl Default for AovTrack {
    fn default() -> Self {
        Self {
            weight: Vec3::ONE,
            done: false,
            sample: AovSample::escaped(Vec3::ZERO),
        }
    }
}

impl AovTrack {
    /// The path's segment along `dir` escaped into a background of colour `background`.
    #[inline]
    pub fn escaped(&mut self, background: Vec3) {
        if !self.done {
            self.sample.albedo = self.weight * background.clamp(Vec3::ZERO, Vec3::ONE);
            self.sample.normal = Vec3::ZERO;
            self.done = true;
        }
    }

    /// The path's segment `ray` (the camera ray where `first`) ended at `hit`, whose
    /// surface and material are these. A mirror or glass passes the search on, tinting
    /// what lies beyond by its albedo; any other surface ends it.
    #[inline]
    pub fn hit(
        &mut self,
        ray: &Ray,
        hit: &Hit,
        surface: &Surface,
        material: &Material,
        first: bool,
    ) {
        if self.done {
            return;
        }
        if first {
            self.sample.depth = hit.t * ray.dir.length();
            self.sample.position = surface.p;
            (self.sample.instance, self.sample.primitive) = (hit.inst, hit.prim);
        }
        let albedo = material.albedo();
        self.sample.albedo = self.weight * albedo;
        self.sample.normal = Facing::new(ray.dir, surface).shading;
        match material.is_delta() {
            // A mirror's or glass's sample carries its albedo as its weight.
            true => self.weight *= albedo,
            false => self.done = true,
        }
    }
}

impl Tracer<'_> {
    /// The AOV sample of the camera ray `ray` traced alone (no radiance): the path's
    /// own walk through mirrors and glass, drawing from `rng` what it draws there (glass's
    /// choice, roulette), so the AOVs are those a path-traced sample shows.
    pub fn aov_sample<P: Probe>(&self, ray: Ray, rng: &mut Rng, work: &mut Work<P>) -> AovSample {
        let scene = self.scene;
        let settings = scene.settings;
        let mut track = AovTrack::default();
        let mut ray = ray;
        let mut throughput = Vec3::ONE;
        for segment in 1..=settings.max_depth {
            work.rays += 1;
            let Some(hit) = self.intersect(&ray, rng, work) else {
                track.escaped(scene.background.radiance(ray.dir));
                break;
            };
            let (surface, material) = scene.shade(&ray, &hit);
            track.hit(&ray, &hit, &surface, &material, segment == 1);
            // A path ends at an emitter and at its last segment, as it does here.
            if track.done || !material.scatters() || segment == settings.max_depth {
                break;
            }
            let Some(bounce) = material.sample(ray.dir, &surface, rng) else {
                break;
            };
            throughput *= bounce.weight;
            if !self.survives_roulette(&mut throughput, segment, rng) || throughput == Vec3::ZERO {
                break;
            }
            ray = super::path::spawn_ray(&surface, bounce.direction);
        }
        track.sample
    }
}
