//! The scene's emitters as lights: every primitive with an emissive material, chosen in
//! proportion to its power, then a point on it drawn by its shape.

use crate::geometry::SurfaceSample;
use crate::rng::Rng;
use crate::sampling::{luminance, Distribution1D};
use crate::scene::Scene;
use glam::{Vec2, Vec3};

/// A point on a light, drawn for a point that wants its light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSample {
    /// The point on the light's surface, its normal and rounding error.
    pub point: SurfaceSample,
    /// Radiance it sends towards the reference point (emitters are two-sided).
    pub radiance: Vec3,
    /// Density per solid angle at the reference point, the choice of light included.
    pub pdf: f32,
}

/// The emitters of a scene, ready to be sampled.
#[derive(Clone, Debug, Default)]
pub struct Lights {
    /// Primitive index of each light.
    prims: Vec<u32>,
    /// Choice of light, in proportion to luminance times area; `None` without lights.
    choice: Option<Distribution1D>,
    /// Light index of each primitive, [`Lights::NONE`] for primitives that are not lights.
    light_of_prim: Vec<u32>,
}

impl Lights {
    const NONE: u32 = u32::MAX;

    /// Every emissive primitive of positive power becomes a light.
    pub fn new(scene: &Scene) -> Self {
        let mut prims = Vec::new();
        let mut power = Vec::new();
        let mut light_of_prim = vec![Self::NONE; scene.primitives.len()];
        for (index, primitive) in scene.primitives.iter().enumerate() {
            let emitted = scene.materials[primitive.material as usize].emitted();
            let p = luminance(emitted) * primitive.shape.area();
            if p.is_finite() && p > 0.0 {
                light_of_prim[index] = prims.len() as u32;
                prims.push(index as u32);
                power.push(p);
            }
        }
        Self {
            prims,
            choice: Distribution1D::new(power),
            light_of_prim,
        }
    }

    pub fn len(&self) -> usize {
        self.prims.len()
    }

    pub fn is_empty(&self) -> bool {
        self.prims.is_empty()
    }

    /// The primitive of each light, in light order.
    pub fn prims(&self) -> &[u32] {
        &self.prims
    }

    /// The distribution lights are chosen by (their power); `None` without lights.
    pub fn choice(&self) -> Option<&Distribution1D> {
        self.choice.as_ref()
    }

    /// Chooses a light and a point on it for light arriving at `reference`; `None` when
    /// there are no lights or the point drawn cannot send light there.
    pub fn sample(&self, scene: &Scene, reference: Vec3, rng: &mut Rng) -> Option<LightSample> {
        let choice = self.choice.as_ref()?;
        let (light, _) = choice.sample(rng.next_f32());
        let u = Vec2::new(rng.next_f32(), rng.next_f32());
        let primitive = &scene.primitives[self.prims[light] as usize];
        let point = primitive.shape.sample_toward(reference, u)?;
        Some(LightSample {
            point,
            radiance: scene.materials[primitive.material as usize].emitted(),
            pdf: point.pdf * choice.pmf(light),
        })
    }

    /// The density [`Lights::sample`] has for the point `p` (normal `normal`) of primitive
    /// `prim` that a ray from `reference` hit first; zero if `prim` is not a light.
    pub fn pdf(&self, scene: &Scene, prim: u32, reference: Vec3, p: Vec3, normal: Vec3) -> f32 {
        let (Some(choice), Some(&light)) = (&self.choice, self.light_of_prim.get(prim as usize))
        else {
            return 0.0;
        };
        if light == Self::NONE {
            return 0.0;
        }
        let shape = &scene.primitives[prim as usize].shape;
        choice.pmf(light as usize) * shape.pdf_toward(reference, p, normal)
    }
}
