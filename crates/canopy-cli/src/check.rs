//! `canopy check`: load and validate a scene, then describe it without rendering.

use crate::scene_facts::SceneFacts;
use crate::units::human_bytes;
use canopy_bvh::Bvh2Node;
use canopy_render::scene::Primitive;
use canopy_render::Scene;
use clap::Args;
use serde::Serialize;

/// A triangle of a mesh stored once: its indices and about half a vertex (with its
/// normal), its share of a triangle pack, of the tree's nodes and of its index.
const BYTES_PER_MESH_TRIANGLE: u64 = 12 + 12 + 48 + 2 * 32 / 8 + 4;

/// An instance: its place in the scene and in the top-level structure (with its share of
/// the top tree).
const BYTES_PER_INSTANCE: u64 = 56 + 128 + 2 * std::mem::size_of::<Bvh2Node>() as u64;

/// A primitive, and its share of a BVH: about two nodes and one index each.
const BYTES_PER_PRIMITIVE: u64 =
    (std::mem::size_of::<Primitive>() + 2 * std::mem::size_of::<Bvh2Node>() + 4) as u64;

#[derive(Args)]
pub struct CheckArgs {
    /// Built-in scene name, scene file, or a bare OBJ/PLY mesh.
    scene: String,
    /// A folder the scene may also read files from (meshes, models, maps). A scene reads
    /// only files in its own folder unless this allows more; repeat it for several.
    #[arg(long, value_name = "DIR")]
    allow_path: Vec<std::path::PathBuf>,
    /// Print the description as one JSON object (warnings also go to stderr).
    #[arg(long)]
    json: bool,
}

/// What `canopy check` reports.
#[derive(Serialize)]
struct Description {
    #[serde(flatten)]
    facts: SceneFacts,
    name: String,
    description: String,
    materials: usize,
    emissive_materials: usize,
    textured_materials: usize,
    /// Point, spot and directional lights.
    punctual_lights: usize,
    bounds_min: [f32; 3],
    bounds_max: [f32; 3],
    film_bytes: u64,
    geometry_bytes: u64,
    /// The environment map's pixels and sampling tables (0 without one).
    environment_bytes: u64,
    /// Decoded texture images.
    texture_bytes: u64,
    warnings: Vec<String>,
}

pub fn run(args: &CheckArgs) -> anyhow::Result<()> {
    let scene = canopy_render::load_scene_allowing(&args.scene, &args.allow_path)?;
    let description = describe(&args.scene, &scene);
    for warning in &description.warnings {
        eprintln!("warning: {warning}");
    }
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&description)?);
    } else {
        for line in lines(&scene, &description) {
            outln!("{line}");
        }
        outln!("ok          {} is valid", args.scene);
    }
    Ok(())
}

fn describe(arg: &str, scene: &Scene) -> Description {
    let bounds = scene.bounds();
    Description {
        facts: SceneFacts::of(arg, scene),
        name: scene.name.clone(),
        description: scene.description.clone(),
        materials: scene.materials.len(),
        emissive_materials: scene
            .materials
            .iter()
            .filter(|m| m.emitted() != glam::Vec3::ZERO)
            .count(),
        textured_materials: scene.textured_materials(),
        punctual_lights: scene.lights.len(),
        bounds_min: bounds.min.to_array(),
        bounds_max: bounds.max.to_array(),
        film_bytes: scene.settings.film_bytes(),
        environment_bytes: match &scene.background {
            canopy_render::Background::Environment(map) => {
                let (w, h) = map.size();
                canopy_render::background::environment_memory(w as u64, h as u64)
            }
            _ => 0,
        },
        geometry_bytes: scene.primitives.len() as u64 * BYTES_PER_PRIMITIVE
            + scene
                .meshes
                .iter()
                .map(|m| m.mesh.indices().len() as u64 * BYTES_PER_MESH_TRIANGLE)
                .sum::<u64>()
            + scene.instances.len() as u64 * BYTES_PER_INSTANCE,
        texture_bytes: scene.image_bytes(),
        warnings: scene.warnings(),
    }
}

/// The report `canopy check` prints, one line each.
fn lines(scene: &Scene, d: &Description) -> Vec<String> {
    let c = &scene.camera;
    vec![
        format!("scene       {} {}", d.name, d.description),
        format!(
            "camera      from {} to {}, up {}, vfov {}°, aperture {}",
            c.look_from, c.look_at, c.up, c.vfov, c.aperture
        ),
        format!("render      {}", d.facts.settings_text()),
        format!("primitives  {}", d.facts.primitives_text()),
        format!(
            "materials   {} ({} emissive, {} textured); {} point, spot or directional lights",
            d.materials, d.emissive_materials, d.textured_materials, d.punctual_lights
        ),
        format!("bounds      {:?} to {:?}", d.bounds_min, d.bounds_max),
        format!(
            "memory      ~{} of film, ~{} of primitives and BVH, ~{} of environment map, ~{} of textures",
            human_bytes(d.film_bytes),
            human_bytes(d.geometry_bytes),
            human_bytes(d.environment_bytes),
            human_bytes(d.texture_bytes)
        ),
    ]
}
