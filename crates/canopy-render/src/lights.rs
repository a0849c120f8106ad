//! The scene's emitters as lights: every primitive with an emissive material, chosen in
//! proportion to its power, then a point on it drawn by its shape.

use crate::geometry::{Shape, SurfaceSample};
use crate::rng::Rng;
use crate::sampling::{luminance, Distribution1D};
use crate::scene::{Scene, PRIMITIVES_INSTANCE};
use canopy_bvh::Hit;
use glam::{Vec2, Vec3};
use std::borrow::Cow;

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

/// The emitters of a scene, ready to be sampled: every emissive primitive, and every
/// triangle of an emissive mesh instance, each named by (instance, primitive) as a hit
/// names it ([`crate::scene::PRIMITIVES_INSTANCE`] for the scene's own primitives).
#[derive(Clone, Debug, Default)]
pub struct Lights {
    /// (instance, primitive) of each light.
    emitters: Vec<(u32, u32)>,
    /// Choice of light, in proportion to luminance times area; `None` without lights.
    choice: Option<Distribution1D>,
    /// Light index of each of the scene's primitives, [`Lights::NONE`] where it is not one.
    light_of_prim: Vec<u32>,
    /// For each mesh instance, the light index of its first triangle (its triangles are
    /// lights in order), or [`Lights::NONE`] when its material does not emit.
    first_light_of_instance: Vec<u32>,
}

impl Lights {
    const NONE: u32 = u32::MAX;

    /// Every emissive primitive of positive power becomes a light, then every triangle
    /// of each emissive mesh instance (in world space; one of no power is never chosen).
    pub fn new(scene: &Scene) -> Self {
        let mut emitters = Vec::new();
        let mut power = Vec::new();
        let mut light_of_prim = vec![Self::NONE; scene.primitives.len()];
        for (index, primitive) in scene.primitives.iter().enumerate() {
            let emitted = scene.materials[primitive.material as usize].emitted();
            let p = luminance(emitted) * primitive.shape.area();
            if p.is_finite() && p > 0.0 {
                light_of_prim[index] = emitters.len() as u32;
                emitters.push((PRIMITIVES_INSTANCE, index as u32));
                power.push(p);
            }
        }
        let mut first_light_of_instance = vec![Self::NONE; scene.instances.len()];
        for (k, instance) in scene.instances.iter().enumerate() {
            let radiance = luminance(scene.materials[instance.material as usize].emitted());
            if !(radiance.is_finite() && radiance > 0.0) {
                continue;
            }
            first_light_of_instance[k] = emitters.len() as u32;
            let triangles = scene.meshes[instance.mesh as usize].mesh.indices().len() as u32;
            for prim in 0..triangles {
                emitters.push((k as u32 + 1, prim));
                power.push(radiance * scene.instance_triangle(instance, prim).area());
            }
        }
        Self {
            emitters,
            choice: Distribution1D::new(power),
            light_of_prim,
            first_light_of_instance,
        }
    }

    pub fn len(&self) -> usize {
        self.emitters.len()
    }

    pub fn is_empty(&self) -> bool {
        self.emitters.is_empty()
    }

    /// The (instance, primitive) of each light, in light order.
    pub fn emitters(&self) -> &[(u32, u32)] {
        &self.emitters
    }

    /// The distribution lights are chosen by (their power); `None` without lights.
    pub fn choice(&self) -> Option<&Distribution1D> {
        self.choice.as_ref()
    }

    /// The shape and material of light `light`, in world space.
    fn shape_of<'s>(&self, scene: &'s Scene, light: usize) -> (Cow<'s, Shape>, u32) {
        let (inst, prim) = self.emitters[light];
        match scene.instance_of(inst) {
            None => {
                let primitive = &scene.primitives[prim as usize];
                (Cow::Borrowed(&primitive.shape), primitive.material)
            }
            Some(instance) => (
                Cow::Owned(Shape::Triangle(scene.instance_triangle(instance, prim))),
                instance.material,
            ),
        }
    }

    /// Chooses a light and a point on it for light arriving at `reference`; `None` when
    /// there are no lights or the point drawn cannot send light there.
    pub fn sample(&self, scene: &Scene, reference: Vec3, rng: &mut Rng) -> Option<LightSample> {
        let choice = self.choice.as_ref()?;
        let (light, _) = choice.sample(rng.next_f32());
        let u = Vec2::new(rng.next_f32(), rng.next_f32());
        let (shape, material) = self.shape_of(scene, light);
        let point = shape.sample_toward(reference, u)?;
        Some(LightSample {
            point,
            radiance: scene.materials[material as usize].emitted(),
            pdf: point.pdf * choice.pmf(light),
        })
    }

    /// The light index of what `hit` found, if it is a light.
    fn light_of(&self, hit: &Hit) -> Option<usize> {
        let light = match hit.inst {
            PRIMITIVES_INSTANCE => *self.light_of_prim.get(hit.prim as usize)?,
            inst => match *self.first_light_of_instance.get(inst as usize - 1)? {
                Self::NONE => Self::NONE,
                first => first + hit.prim,
            },
        };
        (light != Self::NONE).then_some(light as usize)
    }

    /// The density [`Lights::sample`] has for the point `p` (normal `normal`) that a ray
    /// from `reference` hit first (`hit`); zero if what it hit is not a light.
    pub fn pdf(&self, scene: &Scene, hit: &Hit, reference: Vec3, p: Vec3, normal: Vec3) -> f32 {
        let (Some(choice), Some(light)) = (&self.choice, self.light_of(hit)) else {
            return 0.0;
        };
        let (shape, _) = self.shape_of(scene, light);
        choice.pmf(light) * shape.pdf_toward(reference, p, normal)
    }
}
