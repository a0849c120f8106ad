//! The scene's lights as the GPU samples them: `canopy_render::lights::Lights`'s table
//! (emitters, then punctual lights, chosen by power), its CDF normalised to f32.

use bytemuck::{Pod, Zeroable};
use canopy_render::geometry::Shape;
use canopy_render::lights::{spot_falloff_scale, Lights, PunctualLight};
use canopy_render::scene::Primitive;
use canopy_render::Scene;

use crate::scene::GpuPrimitive;

/// No light: a primitive's or an instance's light index when it emits nothing.
pub(crate) const NO_LIGHT: u32 = u32::MAX;

/// A light for the GPU: 16 bytes; WGSL `Light` in `path.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub(crate) struct GpuLight {
    /// The primitive record it samples (world space), or for a punctual light its index
    /// in the punctual table.
    pub record: u32,
    /// Probability of choosing it.
    pub pmf: f32,
    /// End of its slice of the cumulative distribution, normalised to 1.
    pub cdf_end: f32,
    /// 1 for a punctual light, 0 for an emitter.
    pub punctual: u32,
}

/// A point, spot or directional light for the GPU: 64 bytes; WGSL `Punctual` in
/// `path.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub(crate) struct GpuPunctual {
    /// xyz: the position (point and spot); w: a spot's outer cone's cosine.
    position: [f32; 4],
    /// xyz: the unit direction light travels (spot and directional); w: a spot's
    /// falloff scale ([`spot_falloff_scale`]).
    direction: [f32; 4],
    /// xyz: intensity (point, spot) or irradiance (directional); w: the radius of the
    /// scene's sphere, which directional light comes from twice as far.
    strength: [f32; 4],
    /// x: 0 point, 1 spot, 2 directional.
    kind: [u32; 4],
}

impl GpuPunctual {
    fn new(light: &PunctualLight, radius: f32) -> Self {
        let v = |v: glam::Vec3, w: f32| [v.x, v.y, v.z, w];
        let zero = glam::Vec3::ZERO;
        let (kind, position, direction, strength) = match *light {
            PunctualLight::Point {
                position,
                intensity,
            } => (0, v(position, 0.0), v(zero, 0.0), intensity),
            PunctualLight::Spot {
                position,
                direction,
                intensity,
                cos_inner,
                cos_outer,
            } => (
                1,
                v(position, cos_outer),
                v(direction, spot_falloff_scale(cos_inner, cos_outer)),
                intensity,
            ),
            PunctualLight::Directional {
                direction,
                irradiance,
            } => (2, v(zero, 0.0), v(direction, 0.0), irradiance),
        };
        Self {
            position,
            direction,
            strength: v(strength, radius),
            kind: [kind, 0, 0, 0],
        }
    }
}

/// Everything the kernels need to sample the lights and to weigh a hit on one.
pub(crate) struct GpuLights {
    pub table: Vec<GpuLight>,
    /// Each of the scene's primitives' light index, or [`NO_LIGHT`].
    pub light_of_prim: Vec<u32>,
    /// Each instance's first light (instance 0 the scene's primitives), or [`NO_LIGHT`].
    pub first_of_instance: Vec<u32>,
    pub punctual: Vec<GpuPunctual>,
}

/// The scene's lights as the GPU samples them. An instance's emitting triangles are
/// sampled in world space: their world triangles are appended to `primitives`, with the
/// texture data of the mesh's triangle (mesh `m`'s triangles start at `mesh_first[m]`;
/// a scene without instances passes none).
pub(crate) fn gpu_lights(
    scene: &Scene,
    primitives: &mut Vec<GpuPrimitive>,
    mesh_first: &[u32],
) -> GpuLights {
    let lights = Lights::new(scene);
    let mut out = GpuLights {
        table: Vec::with_capacity(lights.len()),
        light_of_prim: vec![NO_LIGHT; scene.primitives.len()],
        first_of_instance: vec![NO_LIGHT; scene.instances.len() + 1],
        punctual: lights
            .punctual()
            .iter()
            .map(|l| GpuPunctual::new(l, lights.radius()))
            .collect(),
    };
    let Some(choice) = lights.choice() else {
        return out;
    };
    let entry = |light: usize, record: u32, punctual: u32| GpuLight {
        record,
        pmf: choice.pmf(light),
        cdf_end: (choice.cdf()[light + 1] / choice.total()) as f32,
        punctual,
    };
    for (light, &(inst, prim)) in lights.emitters().iter().enumerate() {
        let record = match scene.instance_of(inst) {
            None => {
                out.light_of_prim[prim as usize] = light as u32;
                prim
            }
            Some(instance) => {
                if out.first_of_instance[inst as usize] == NO_LIGHT {
                    out.first_of_instance[inst as usize] = light as u32;
                }
                let mut world = GpuPrimitive::new(&Primitive {
                    shape: Shape::Triangle(scene.instance_triangle(instance, prim)),
                    material: instance.material,
                });
                world.surface =
                    primitives[(mesh_first[instance.mesh as usize] + prim) as usize].surface;
                primitives.push(world);
                primitives.len() as u32 - 1
            }
        };
        out.table.push(entry(light, record, 0));
    }
    let first = lights.emitters().len();
    for k in 0..lights.punctual().len() {
        out.table.push(entry(first + k, k as u32, 1));
    }
    out
}
