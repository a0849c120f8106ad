//! The scene's lights: every primitive with an emissive material, and the punctual
//! lights (point, spot, directional) glTF files bring. One is chosen in proportion to
//! its power, then a point on it drawn by its shape (a punctual light is its own point).

use crate::geometry::{Rectangle, Shape, SurfaceSample};
use crate::rng::Rng;
use crate::sampling::{luminance, uniform_triangle, Distribution1D};
use crate::scene::{Scene, PRIMITIVES_INSTANCE};
use canopy_bvh::Hit;
use glam::Vec3;

/// A light without area (glTF's `KHR_lights_punctual`), placed in the world. Its
/// strengths are taken in canopy's units (a white sky has radiance 1), as glTF viewers
/// take them: a point or spot light of intensity `I` lights a surface facing it at
/// distance `d` with irradiance `I / d²`, a directional one with `irradiance`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PunctualLight {
    Point {
        position: Vec3,
        intensity: Vec3,
    },
    /// A point light shining along unit `direction`, full within the inner cone and
    /// fading to nothing at the outer one (the specification's smooth falloff).
    Spot {
        position: Vec3,
        direction: Vec3,
        intensity: Vec3,
        cos_inner: f32,
        cos_outer: f32,
    },
    /// Light from infinitely far away travelling along unit `direction`.
    Directional {
        direction: Vec3,
        irradiance: Vec3,
    },
}

impl PunctualLight {
    /// Why it cannot be rendered, if it cannot.
    pub fn check(&self) -> Result<(), String> {
        let (strength, position, direction) = match *self {
            PunctualLight::Point {
                position,
                intensity,
            } => (intensity, Some(position), None),
            PunctualLight::Spot {
                position,
                direction,
                intensity,
                cos_inner,
                cos_outer,
            } => {
                if !(cos_outer < cos_inner && (-1.0..=1.0).contains(&cos_outer) && cos_inner <= 1.0)
                {
                    return Err(format!(
                        "a spot light's outer cone must be wider than its inner one (cosines {cos_outer} and {cos_inner})"
                    ));
                }
                (intensity, Some(position), Some(direction))
            }
            PunctualLight::Directional {
                direction,
                irradiance,
            } => (irradiance, None, Some(direction)),
        };
        if !(strength.is_finite() && strength.min_element() >= 0.0) {
            return Err(format!(
                "a light's strength must be finite and >= 0, not {strength}"
            ));
        }
        if position.is_some_and(|p| !p.is_finite()) {
            return Err("a light's position must be finite".into());
        }
        if direction.is_some_and(|d| !d.is_finite() || (d.length() - 1.0).abs() > 1e-3) {
            return Err("a light's direction must be a unit vector".into());
        }
        Ok(())
    }

    /// Luminance of the power it sends into a scene of radius `radius` (for choosing).
    fn power(&self, radius: f32) -> f32 {
        use std::f32::consts::PI;
        match *self {
            PunctualLight::Point { intensity, .. } => 4.0 * PI * luminance(intensity),
            PunctualLight::Spot {
                intensity,
                cos_inner,
                cos_outer,
                ..
            } => 2.0 * PI * (1.0 - 0.5 * (cos_inner + cos_outer)) * luminance(intensity),
            PunctualLight::Directional { irradiance, .. } => {
                PI * radius * radius * luminance(irradiance)
            }
        }
    }

    /// The light at `reference`: where it comes from (a point `radius` away for a
    /// directional light), and the radiance-like quantity the integrator multiplies by
    /// the BSDF (irradiance at normal incidence).
    fn toward(&self, reference: Vec3, radius: f32) -> Option<(Vec3, Vec3)> {
        match *self {
            PunctualLight::Point {
                position,
                intensity,
            } => {
                let d2 = position.distance_squared(reference);
                (d2 > 0.0).then(|| (position, intensity / d2))
            }
            PunctualLight::Spot {
                position,
                direction,
                intensity,
                cos_inner,
                cos_outer,
            } => {
                let to_reference = reference - position;
                let d2 = to_reference.length_squared();
                if d2 <= 0.0 {
                    return None;
                }
                let cd = direction.dot(to_reference / d2.sqrt());
                let scale = spot_falloff_scale(cos_inner, cos_outer);
                let falloff = ((cd - cos_outer) * scale).clamp(0.0, 1.0);
                let falloff = falloff * falloff;
                (falloff > 0.0).then(|| (position, intensity * (falloff / d2)))
            }
            PunctualLight::Directional {
                direction,
                irradiance,
            } => Some((reference - 2.0 * radius * direction, irradiance)),
        }
    }
}

/// The factor a spot light's falloff is scaled by: one over the width of the band
/// between its cones (in cosines), kept finite for a band of no width.
pub fn spot_falloff_scale(cos_inner: f32, cos_outer: f32) -> f32 {
    1.0 / (cos_inner - cos_outer).max(1e-3)
}

/// A point on a light, drawn for a point that wants its light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSample {
    /// The point on the light's surface, its normal and rounding error.
    pub point: SurfaceSample,
    /// Radiance it sends towards the reference point (emitters are two-sided); for a
    /// punctual light, the irradiance it brings there.
    pub radiance: Vec3,
    /// Density per solid angle at the reference point, the choice of light included; for
    /// a punctual light, the probability of choosing it.
    pub pdf: f32,
    /// A punctual light: no other strategy can find it, so it is not weighted by MIS.
    pub delta: bool,
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
    /// For each of the scene's primitives that is a light (lights `0..` in order), the
    /// index in `rectangles` of its rectangle, [`Lights::NONE`] where it is not a flat
    /// box; stops at the last such light.
    rectangle_of: Vec<u32>,
    /// The rectangles of flat boxes that are lights, with their radiance.
    rectangles: Vec<(Rectangle, Vec3)>,
    /// The scene's punctual lights, after the emitters in light order.
    punctual: Vec<PunctualLight>,
    /// Radius of a sphere around the scene (where directional light starts from).
    radius: f32,
}

impl Lights {
    const NONE: u32 = u32::MAX;

    /// Every emissive primitive of positive power becomes a light, then every triangle
    /// of each emissive mesh instance (in world space; one of no power is never chosen).
    pub fn new(scene: &Scene) -> Self {
        let mut emitters = Vec::new();
        let mut power = Vec::new();
        let mut light_of_prim = vec![Self::NONE; scene.primitives.len()];
        let (mut rectangle_of, mut rectangles) = (Vec::new(), Vec::new());
        // Each material's emitted luminance, zero where it cannot light: a render makes
        // its lights at every pass, and asking each of a large mesh's primitives its
        // material's emission and area took the lit dragon (202k triangles) 15M
        // instructions a pass.
        let emitting: Vec<f32> = scene
            .materials
            .iter()
            .map(|m| luminance(m.emitted()))
            .map(|l| if l.is_finite() && l > 0.0 { l } else { 0.0 })
            .collect();
        for (index, primitive) in scene.primitives.iter().enumerate() {
            let radiance = emitting[primitive.material as usize];
            if radiance == 0.0 {
                continue;
            }
            let p = radiance * primitive.shape.area();
            if p.is_finite() && p > 0.0 {
                let light = emitters.len();
                if let Some(rectangle) = match &primitive.shape {
                    Shape::Cuboid(cuboid) => cuboid.rectangle(),
                    _ => None,
                } {
                    rectangle_of.resize(light, Self::NONE);
                    rectangle_of.push(rectangles.len() as u32);
                    // A primitive's emission has no texture coordinates to vary by.
                    let emitted = scene.emitted_at(
                        primitive.material,
                        PRIMITIVES_INSTANCE,
                        index as u32,
                        0.0,
                        0.0,
                    );
                    rectangles.push((rectangle, emitted));
                }
                light_of_prim[index] = light as u32;
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
        // A sphere about the origin holding the scene, for directional light (the box is
        // a pass over every primitive: only taken when there is such a light).
        let radius = match scene.lights.is_empty() {
            true => 1.0,
            false => {
                let bounds = scene.bounds();
                match bounds.is_empty() {
                    true => 1.0,
                    false => {
                        bounds.center().length()
                            + (0.5 * (bounds.max - bounds.min).length()).max(1.0)
                    }
                }
            }
        };
        for light in &scene.lights {
            power.push(light.power(radius));
        }
        Self {
            emitters,
            choice: Distribution1D::new(power),
            light_of_prim,
            first_light_of_instance,
            rectangle_of,
            rectangles,
            punctual: scene.lights.clone(),
            radius,
        }
    }

    /// Lights of both kinds.
    pub fn len(&self) -> usize {
        self.emitters.len() + self.punctual.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The (instance, primitive) of each light, in light order.
    pub fn emitters(&self) -> &[(u32, u32)] {
        &self.emitters
    }

    /// The punctual lights, lights `emitters().len()..` in light order.
    pub fn punctual(&self) -> &[PunctualLight] {
        &self.punctual
    }

    /// Radius of the sphere about the origin holding the scene, from which directional
    /// light is aimed at a point (from twice this far).
    pub fn radius(&self) -> f32 {
        self.radius
    }

    /// The distribution lights are chosen by (their power); `None` without lights.
    pub fn choice(&self) -> Option<&Distribution1D> {
        self.choice.as_ref()
    }

    /// `f` of the shape and material of light `light`, in world space. The shape is
    /// lent, not returned: returned, the enum was copied through memory in pieces
    /// narrower than its reads (a failed store forward at every light sample, about a
    /// third of `Lights::sample`'s time on the Cornell box).
    #[inline(always)]
    fn with_shape<R>(&self, scene: &Scene, light: usize, f: impl FnOnce(&Shape, u32) -> R) -> R {
        let (inst, prim) = self.emitters[light];
        match scene.instance_of(inst) {
            None => {
                let primitive = &scene.primitives[prim as usize];
                f(&primitive.shape, primitive.material)
            }
            Some(instance) => f(
                &Shape::Triangle(scene.instance_triangle(instance, prim)),
                instance.material,
            ),
        }
    }

    /// Chooses a light and a point on it for light arriving at `reference`; `None` when
    /// there are no lights or the point drawn cannot send light there.
    pub fn sample(&self, scene: &Scene, reference: Vec3, rng: &mut Rng) -> Option<LightSample> {
        let choice = self.choice.as_ref()?;
        let (light, _) = choice.sample(rng.next_f32());
        let u = rng.next_2d();
        if let Some(&r) = self.rectangle_of.get(light).filter(|&&r| r != Self::NONE) {
            let (rectangle, radiance) = &self.rectangles[r as usize];
            let point = rectangle.sample_toward(reference, u)?;
            return Some(LightSample {
                point,
                radiance: *radiance,
                pdf: point.pdf * choice.pmf(light),
                delta: false,
            });
        }
        if let Some(punctual) = self.punctual.get(light.wrapping_sub(self.emitters.len())) {
            let (p, irradiance) = punctual.toward(reference, self.radius)?;
            return Some(LightSample {
                point: SurfaceSample {
                    p,
                    normal: (reference - p).normalize_or_zero(),
                    error: 0.0,
                    pdf: 1.0,
                },
                radiance: irradiance,
                pdf: choice.pmf(light),
                delta: true,
            });
        }
        let (point, material) = self.with_shape(scene, light, |shape, material| {
            Some((shape.sample_toward(reference, u)?, material))
        })?;
        // The point's barycentrics, for an emissive texture (triangles only have them).
        let [_, b1, b2] = uniform_triangle(u);
        let (inst, prim) = self.emitters[light];
        Some(LightSample {
            point,
            radiance: scene.emitted_at(material, inst, prim, b1, b2),
            pdf: point.pdf * choice.pmf(light),
            delta: false,
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
        choice.pmf(light)
            * self.with_shape(scene, light, |shape, _| {
                shape.pdf_toward(reference, p, normal)
            })
    }
}
