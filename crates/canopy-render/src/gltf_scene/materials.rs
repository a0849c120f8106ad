//! glTF's materials as canopy's: metallic-roughness as [`Pbr`] (the specification's
//! BRDF) with its emission (times `KHR_materials_emissive_strength`) beside what it
//! reflects, and transmission as glass of the material's index of refraction. The
//! textures are read by the loader ([`super::textures`]).

use crate::material::{Material, Pbr};
use crate::scene_file::MAX_RADIANCE;
use crate::texture::Coverage;
use glam::Vec3;

/// A material of the file as canopy renders it, and what it leaves out.
pub(super) fn convert(material: &gltf::Material<'_>, notes: &mut Vec<String>) -> Material {
    let named = match (material.index(), material.name()) {
        (Some(i), name) => format!("material {}", super::data::describe(i, name)),
        (None, _) => "the default material".to_owned(),
    };
    let pbr = material.pbr_metallic_roughness();
    let emission =
        Vec3::from(material.emissive_factor()) * material.emissive_strength().unwrap_or(1.0);
    let emission = match emission.is_finite() && emission.min_element() >= 0.0 {
        true => emission.min(Vec3::splat(MAX_RADIANCE)),
        false => {
            notes.push(format!(
                "{named}: its emission {emission} is not a radiance (left out)"
            ));
            Vec3::ZERO
        }
    };
    let transmission = material
        .transmission()
        .map_or(0.0, |t| t.transmission_factor());
    if transmission >= 0.5 {
        if emission != Vec3::ZERO {
            notes.push(format!(
                "{named}: glass does not emit (its emission is left out)"
            ));
        }
        return Material::Dielectric {
            ior: material.ior().unwrap_or(1.5),
        };
    }
    let [r, g, b, _alpha] = pbr.base_color_factor();
    let albedo = Vec3::new(r, g, b).map(finite_unit);
    Material::Pbr(Pbr {
        base_color: albedo,
        metallic: finite_unit(pbr.metallic_factor()),
        roughness: finite_unit(pbr.roughness_factor()),
        emission,
    })
}

/// How much of the surface is there, where it is not all opaque.
pub(super) fn coverage(material: &gltf::Material<'_>) -> Option<Coverage> {
    let alpha = finite_unit(material.pbr_metallic_roughness().base_color_factor()[3]);
    match material.alpha_mode() {
        gltf::material::AlphaMode::Opaque => None,
        gltf::material::AlphaMode::Mask => Some(Coverage::Mask {
            alpha,
            cutoff: material.alpha_cutoff().unwrap_or(0.5),
        }),
        gltf::material::AlphaMode::Blend => Some(Coverage::Blend { alpha }),
    }
}

/// A factor the specification bounds to [0, 1], clamped there (NaN as 0).
fn finite_unit(v: f32) -> f32 {
    if v.is_nan() {
        0.0
    } else {
        v.clamp(0.0, 1.0)
    }
}
