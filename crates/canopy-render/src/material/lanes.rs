//! The BSDF samples of the report's three materials (Lambertian, metal, glass) as
//! functions of the drawn numbers alone, written with no branch that a compiler cannot
//! turn into a select and no library call. [`Material::sample`](super::Material::sample)
//! calls them for one path; the wavefront integrator's scatter stage calls them in loops
//! over SIMD lanes, a stage's vertices grouped by material. Being one source compiled
//! twice, with IEEE operations only (Rust never fuses them), both give the same bits.

use super::{fuzz, reflect, refract, schlick};
use crate::sampling::unit_vector;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// A drawn direction before the material's weight is attached: the direction, its
/// density (per solid angle; zero for a delta lobe) and whether the path goes on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaneSample {
    pub direction: Vec3,
    pub pdf: f32,
    pub scatters: bool,
}

/// The lobes sampled in lanes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lobe {
    Lambertian,
    Metal,
    Dielectric,
}

impl Lobe {
    pub const ALL: [Lobe; 3] = [Lobe::Lambertian, Lobe::Metal, Lobe::Dielectric];
}

/// What a vertex's sample in lanes is drawn from besides its ray and normals: the lobe,
/// its parameter (the metal's fuzz, the glass's relative index) and the drawn numbers (a
/// direction's pair, or the glass's choice in `u.x`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaneParams {
    pub lobe: Lobe,
    pub param: f32,
    pub u: Vec2,
}

impl LaneParams {
    /// The sample for a ray along `dir` at normals `shading` and `geometric` facing it.
    #[inline(always)]
    pub fn sample(&self, dir: Vec3, shading: Vec3, geometric: Vec3) -> LaneSample {
        match self.lobe {
            Lobe::Lambertian => lambertian(shading, geometric, self.u),
            Lobe::Metal => metal(dir, shading, geometric, self.param, self.u),
            Lobe::Dielectric => dielectric(dir, shading, self.param, self.u.x),
        }
    }
}

/// Lambertian: the shading normal plus a uniform unit vector (from `u`), which is
/// cosine-distributed about the normal. `shading` and `geometric` face the arriving ray.
#[inline(always)]
pub fn lambertian(shading: Vec3, geometric: Vec3, u: Vec2) -> LaneSample {
    let d = shading + unit_vector(u);
    let direction = if d.length_squared() < 1e-12 {
        shading
    } else {
        d.normalize()
    };
    let cos = direction.dot(shading);
    LaneSample {
        direction,
        pdf: cos * FRAC_1_PI,
        scatters: (direction.dot(geometric) > 0.0) & (cos > 0.0),
    }
}

/// Fuzzy metal: the mirror direction of `dir` plus `fuzz` times a uniform unit vector
/// (from `u`), normalised; a perfect mirror where `fuzz` is zero.
#[inline(always)]
pub fn metal(dir: Vec3, shading: Vec3, geometric: Vec3, fuzz: f32, u: Vec2) -> LaneSample {
    let reflected = reflect(dir, shading);
    let direction = (reflected + fuzz * unit_vector(u)).normalize_or_zero();
    let delta = fuzz == 0.0;
    let pdf = if delta {
        0.0
    } else {
        fuzz::pdf(reflected, fuzz, direction)
    };
    // A direction on the very edge of the lobe can round to density 0 (where the true
    // density is unbounded): absorbed, like any sample without one.
    LaneSample {
        direction,
        pdf,
        scatters: (direction.dot(geometric) > 0.0) & (delta | (pdf > 0.0)),
    }
}

/// Glass of relative index `eta` (the far side's over the near side's): reflected where
/// total internal reflection forces it or with Schlick's probability (against `choice`),
/// refracted otherwise. Always a delta direction.
#[inline(always)]
pub fn dielectric(dir: Vec3, shading: Vec3, eta: f32, choice: f32) -> LaneSample {
    let cos_theta = (-dir).dot(shading).min(1.0);
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let total_internal = eta * sin_theta > 1.0;
    let direction = if total_internal | (schlick(cos_theta, eta) > choice) {
        reflect(dir, shading)
    } else {
        refract(dir, shading, eta, cos_theta)
    };
    LaneSample {
        direction: direction.normalize(),
        pdf: 0.0,
        scatters: true,
    }
}
