//! Mesh instances render the image of the same meshes baked into world space: shapes,
//! normals and rounding-error bounds are taken through each instance's transform
//! (rotations, mirrors, non-uniform scale), and an emissive instance is a light that
//! light sampling finds, with the density MIS needs.

use canopy_bvh::{BuildParams, TriangleMesh};
use canopy_render::camera::CameraSpec;
use canopy_render::geometry::{Cuboid, Shape};
use canopy_render::lights::Lights;
use canopy_render::material::Material;
use canopy_render::scene::Primitive;
use canopy_render::{
    render, Accel, AccelKind, Background, BvhWidth, Film, Integrator, MeshInstance, RenderSettings,
    Scene, SceneMesh,
};
use glam::{Affine3A, Quat, Vec3};
use std::sync::Arc;

/// A closed unit cube of 12 triangles around the origin, vertices shared.
fn cube() -> TriangleMesh {
    let vertices = (0..8)
        .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32) - 0.5)
        .collect();
    let quads = [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
    ];
    let indices = quads
        .iter()
        .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
        .collect();
    TriangleMesh::new(vertices, indices).unwrap()
}

/// A floor, a dim sky, and instances of one cube: diffuse (turned, squashed, mirrored),
/// glass (mirrored: the inside and outside of a dielectric follow the winding), and a
/// small emissive one that lights the rest.
fn scene(integrator: Integrator) -> Scene {
    let materials = vec![
        Material::Lambertian {
            albedo: Vec3::new(0.7, 0.6, 0.5),
        },
        Material::Lambertian {
            albedo: Vec3::new(0.2, 0.5, 0.8),
        },
        Material::Dielectric { ior: 1.5 },
        Material::Emissive {
            radiance: Vec3::splat(12.0),
        },
    ];
    let place = |scale: Vec3, degrees: f32, translate: Vec3| {
        Affine3A::from_scale_rotation_translation(
            scale,
            Quat::from_axis_angle(Vec3::new(0.3, 1.0, 0.2).normalize(), degrees.to_radians()),
            translate,
        )
    };
    let instances = vec![
        (
            place(Vec3::new(1.0, 0.6, 1.4), 30.0, Vec3::new(-1.2, -0.7, 0.0)),
            1,
        ),
        (
            place(Vec3::new(-0.8, 0.8, 0.8), -50.0, Vec3::new(1.1, -0.6, 0.3)),
            1,
        ),
        (
            place(Vec3::new(0.9, -0.9, 0.5), 70.0, Vec3::new(0.0, -0.5, 1.2)),
            2,
        ),
        (
            place(Vec3::new(0.6, 0.1, 0.6), 0.0, Vec3::new(0.0, 1.4, 0.2)),
            3,
        ),
    ]
    .into_iter()
    .map(|(to_world, material)| MeshInstance {
        mesh: 0,
        to_world,
        material,
    })
    .collect();
    Scene {
        camera: CameraSpec {
            look_from: Vec3::new(0.5, 1.5, 5.0),
            look_at: Vec3::new(0.0, -0.3, 0.0),
            vfov: 45.0,
            ..CameraSpec::default()
        },
        settings: RenderSettings {
            width: 48,
            height: 48,
            spp: 48,
            max_depth: 6,
            seed: 3,
            integrator,
            russian_roulette: false,
            ..RenderSettings::default()
        },
        background: Background::Constant(Vec3::splat(0.1)),
        materials,
        primitives: Arc::new(vec![Primitive {
            shape: Shape::Cuboid(Cuboid::axis_aligned(
                Vec3::new(-4.0, -1.3, -4.0),
                Vec3::new(4.0, -1.0, 4.0),
            )),
            material: 0,
        }]),
        meshes: vec![SceneMesh {
            name: "cube".into(),
            mesh: Arc::new(cube()),
            normals: Vec::new(),
            uvs: Vec::new(),
            tangents: Vec::new(),
        }],
        instances,
        ..Scene::default()
    }
}

/// Mean of each `tile`² block of pixels.
fn tile_means(film: &Film, tile: u32) -> Vec<Vec3> {
    let mut means = Vec::new();
    for ty in (0..film.height).step_by(tile as usize) {
        for tx in (0..film.width).step_by(tile as usize) {
            let mut sum = Vec3::ZERO;
            for y in ty..ty + tile {
                for x in tx..tx + tile {
                    sum += film.pixel(x, y);
                }
            }
            means.push(sum / (tile * tile) as f32);
        }
    }
    means
}

#[test]
fn instances_render_the_image_of_the_meshes_baked_into_the_world() {
    for integrator in Integrator::ALL {
        let scene = scene(integrator);
        let baked = scene.with_instances_baked();
        assert_eq!(baked.primitives.len(), 1 + 4 * 12);
        for width in [BvhWidth::Two, BvhWidth::Eight] {
            let params = BuildParams::default();
            let instanced = Accel::for_scene(&scene, AccelKind::default(), width, &params, None);
            let flat = Accel::build(AccelKind::default(), width, &baked.primitives, &params);
            let a = render(&scene, &instanced, &|| {}).0;
            let b = render(&baked, &flat, &|| {}).0;
            // The same random numbers drive both: paths differ only where rounding of
            // the transforms sends a ray the other way at an edge.
            let (ta, tb) = (tile_means(&a, 8), tile_means(&b, 8));
            for (i, (x, y)) in ta.iter().zip(&tb).enumerate() {
                let tolerance = 0.03 * x.max(*y).max_element() + 1e-3;
                assert!(
                    (*x - *y).abs().max_element() <= tolerance,
                    "{integrator} x{width}: tile {i}: {x} vs {y}"
                );
            }
            let same = a
                .pixels
                .iter()
                .zip(&b.pixels)
                .filter(|(p, q)| p == q)
                .count();
            assert!(
                same * 2 > a.pixels.len(),
                "{integrator}: {same} identical pixels"
            );
            // The sky alone gives tiles of at most 0.1.
            let lit = ta.iter().filter(|t| t.max_element() > 0.12).count();
            assert!(
                lit > 8,
                "{integrator}: the emissive instance should light the scene"
            );
        }
    }
}

/// The emissive instance's triangles are lights with their world-space area as power,
/// exactly as the baked triangles are.
#[test]
fn an_emissive_instance_is_sampled_as_its_world_triangles() {
    let scene = scene(Integrator::Path);
    let lights = Lights::new(&scene);
    assert_eq!(lights.len(), 12, "the 12 triangles of the emissive cube");
    assert!(lights.emitters().iter().all(|&(inst, _)| inst == 4));
    let baked = Lights::new(&scene.with_instances_baked());
    let (a, b) = (lights.choice().unwrap(), baked.choice().unwrap());
    assert!(
        (a.total() / b.total() - 1.0).abs() < 1e-6,
        "same total power"
    );
}

/// Checkpoints tell instanced scenes apart: moving one instance changes the fingerprint.
#[test]
fn the_fingerprint_covers_instances() {
    let scene = scene(Integrator::Path);
    let mut moved = scene.clone();
    moved.instances[2].to_world.translation.x += 1e-3;
    let mut recoloured = scene.clone();
    recoloured.instances[0].material = 2;
    let f = canopy_render::checkpoint::fingerprint;
    assert_ne!(f(&scene), f(&moved));
    assert_ne!(f(&scene), f(&recoloured));
    assert_eq!(f(&scene), f(&scene.clone()));
}

/// A bare mesh file is the scene that places it once, grey, under the sky: the same
/// fingerprint (so its checkpoints resume) as the scene file written out by hand.
#[test]
fn a_bare_mesh_is_the_scene_file_that_places_it() {
    let meshes = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/meshes");
    for file in ["teapot.ply", "teapot.obj"] {
        let bare = canopy_render::scene_from_mesh(&meshes.join(file)).unwrap();
        let source = format!(
            "name = \"teapot\"\n[camera]\nlook_from = [0, 0, 1]\nlook_at = [0, 0, 0]\n\
             [geometry.mesh]\nfile = {file:?}\n\
             [[instances]]\ngeometry = \"mesh\"\nmaterial = {{ type = \"lambertian\", albedo = [0.7, 0.7, 0.7] }}\n"
        );
        let mut written = canopy_render::scene_file::parse_scene(
            &source,
            "by-hand.toml",
            &canopy_render::scene_file::DirAssets::new(meshes.clone()),
        )
        .unwrap();
        written.camera = bare.camera;
        assert_eq!(
            canopy_render::checkpoint::fingerprint(&bare),
            canopy_render::checkpoint::fingerprint(&written),
            "{file}"
        );
        assert_eq!(bare.inputs, [meshes.join(file)]);
        assert!(bare.camera.look_from.is_finite());
    }
}
