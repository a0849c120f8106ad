//! `canopy check`: load and validate a scene, then describe it without rendering.

use crate::units::human_bytes;
use canopy_bvh::Aabb;
use canopy_bvh::Bvh2Node;
use canopy_render::material::Material;
use canopy_render::scene::Primitive;
use canopy_render::{Background, Scene};
use clap::Args;

/// A primitive, and its share of a BVH: about two nodes and one index each.
const BYTES_PER_PRIMITIVE: u64 =
    (std::mem::size_of::<Primitive>() + 2 * std::mem::size_of::<Bvh2Node>() + 4) as u64;

#[derive(Args)]
pub struct CheckArgs {
    /// Built-in scene name, scene file, or a bare OBJ/PLY mesh.
    scene: String,
}

pub fn run(args: &CheckArgs) -> anyhow::Result<()> {
    let scene = canopy_render::load_scene(&args.scene)?;
    scene.settings.check().map_err(anyhow::Error::msg)?;
    for line in describe(&scene) {
        println!("{line}");
    }
    println!("ok          {} is valid", args.scene);
    Ok(())
}

/// The report `canopy check` prints, one line each.
fn describe(scene: &Scene) -> Vec<String> {
    let s = scene.settings;
    let c = &scene.camera;
    let counts = scene.shape_counts();
    let bounds = scene
        .primitive_bounds()
        .into_iter()
        .fold(Aabb::EMPTY, Aabb::union);
    let emitters = scene
        .materials
        .iter()
        .filter(|m| matches!(m, Material::Emissive { .. }))
        .count();
    let mut lines = vec![
        format!("scene       {} {}", scene.name, scene.description),
        format!(
            "camera      from {} to {}, up {}, vfov {}°, aperture {}",
            c.look_from, c.look_at, c.up, c.vfov, c.aperture
        ),
        format!(
            "render      {}x{}, {} spp, depth {}, seed {}",
            s.width, s.height, s.spp, s.max_depth, s.seed
        ),
        format!(
            "primitives  {} ({} spheres, {} triangles, {} cuboids)",
            scene.primitives.len(),
            counts.spheres,
            counts.triangles,
            counts.cuboids
        ),
        format!(
            "materials   {} ({emitters} emissive)",
            scene.materials.len()
        ),
        format!("bounds      {} to {}", bounds.min, bounds.max),
        format!(
            "memory      ~{} of film, ~{} of primitives and BVH",
            human_bytes(s.film_bytes()),
            human_bytes(scene.primitives.len() as u64 * BYTES_PER_PRIMITIVE)
        ),
    ];
    if scene.skipped_degenerate > 0 {
        lines.push(format!(
            "warning     {} zero-area mesh triangles are left out",
            scene.skipped_degenerate
        ));
    }
    if scene.primitives.is_empty() {
        lines.push("warning     the scene has no primitives".into());
    }
    if emitters == 0 && scene.background == Background::Constant(glam::Vec3::ZERO) {
        lines.push(
            "warning     no light: no emissive material and a black background give a black image"
                .into(),
        );
    }
    lines
}
