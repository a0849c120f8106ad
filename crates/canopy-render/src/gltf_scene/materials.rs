//! glTF's metallic-roughness materials as canopy's materials, until the GGX model of
//! the glTF specification lands: the base colour factor as a Lambertian albedo, metals
//! (metallic at least one half) as canopy's fuzzy metal with the roughness as fuzz,
//! transmission as glass of the material's index of refraction, and emission (times
//! `KHR_materials_emissive_strength`) as an emitter. Textures are not read yet: each
//! material that has one is named in a note.

use crate::material::Material;
use glam::Vec3;

/// A material of the file as canopy renders it, and what it leaves out.
pub(super) fn convert(material: &gltf::Material<'_>, notes: &mut Vec<String>) -> Material {
    let named = match (material.index(), material.name()) {
        (Some(i), name) => format!("material {}", super::data::describe(i, name)),
        (None, _) => "the default material".to_owned(),
    };
    let pbr = material.pbr_metallic_roughness();
    let textures = [
        pbr.base_color_texture().is_some(),
        pbr.metallic_roughness_texture().is_some(),
        material.normal_texture().is_some(),
        material.emissive_texture().is_some(),
    ];
    if textures.iter().any(|&t| t) {
        notes.push(format!(
            "{named}: textures are not rendered yet (its colour and factors are)"
        ));
    }
    if material.alpha_mode() != gltf::material::AlphaMode::Opaque {
        notes.push(format!(
            "{named}: alpha mode {:?} is not rendered yet (drawn opaque)",
            material.alpha_mode()
        ));
    }
    let emissive =
        Vec3::from(material.emissive_factor()) * material.emissive_strength().unwrap_or(1.0);
    if emissive.max_element() > 0.0 && emissive.is_finite() {
        return Material::Emissive { radiance: emissive };
    }
    let transmission = material
        .transmission()
        .map_or(0.0, |t| t.transmission_factor());
    if transmission >= 0.5 {
        return Material::Dielectric {
            ior: material.ior().unwrap_or(1.5),
        };
    }
    let [r, g, b, _alpha] = pbr.base_color_factor();
    let albedo = Vec3::new(r, g, b).clamp(Vec3::ZERO, Vec3::ONE);
    match pbr.metallic_factor() >= 0.5 {
        true => Material::Metal {
            albedo,
            fuzz: pbr.roughness_factor().clamp(0.0, 1.0),
        },
        false => Material::Lambertian { albedo },
    }
}
