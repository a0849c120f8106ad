//! Light sampling changes the noise, never the picture: the path integrator (next-event
//! estimation with MIS) and the report's BSDF-only integrator agree, tile by tile, within
//! a few standard errors on scenes that exercise every kind of light and lobe: area
//! lights (cuboid, sphere, triangles), glossy and mirror metal, glass, the sky, and an
//! environment map. Furnaces check that no energy is gained or lost.

use canopy_render::scene_file::{parse_scene, Assets};
use canopy_render::{render, Accel, BuiltinScene, Film, Integrator, Scene};
use glam::Vec3;

/// Side of the square tiles whose means are compared.
const TILE: u32 = 8;

/// Per tile and channel: mean over independent renders and its standard error.
struct TileStats {
    mean: Vec<f64>,
    standard_error: Vec<f64>,
}

fn render_film(scene: &Scene) -> Film {
    let accel = Accel::default_for(scene);
    render(scene, &accel, &|| {}).0
}

fn tile_means(film: &Film) -> Vec<f64> {
    let (tx, ty) = (film.width / TILE, film.height / TILE);
    let mut sums = vec![0.0f64; (tx * ty * 3) as usize];
    for y in 0..ty * TILE {
        for x in 0..tx * TILE {
            let tile = ((y / TILE) * tx + x / TILE) as usize;
            let p = film.pixel(x, y);
            for c in 0..3 {
                sums[tile * 3 + c] += p[c] as f64;
            }
        }
    }
    let n = (TILE * TILE) as f64;
    sums.iter().map(|s| s / n).collect()
}

/// `runs` renders with seeds 1..=runs, each at the scene's spp.
fn tile_stats(scene: &Scene, integrator: Integrator, runs: u64) -> TileStats {
    let per_run: Vec<Vec<f64>> = (1..=runs)
        .map(|seed| {
            let mut s = scene.clone();
            s.settings.integrator = integrator;
            s.settings.seed = seed;
            tile_means(&render_film(&s))
        })
        .collect();
    let n = runs as f64;
    let cells = per_run[0].len();
    let mean: Vec<f64> = (0..cells)
        .map(|i| per_run.iter().map(|r| r[i]).sum::<f64>() / n)
        .collect();
    let standard_error = (0..cells)
        .map(|i| {
            let var = per_run
                .iter()
                .map(|r| (r[i] - mean[i]).powi(2))
                .sum::<f64>()
                / (n - 1.0);
            (var / n).sqrt()
        })
        .collect();
    TileStats {
        mean,
        standard_error,
    }
}

/// Asserts that both integrators agree on every tile and channel within `sigmas`
/// combined standard errors.
fn assert_integrators_agree(name: &str, scene: &Scene, runs: u64) {
    let path = tile_stats(scene, Integrator::Path, runs);
    let bsdf = tile_stats(scene, Integrator::Bsdf, runs);
    let sigmas = 4.5;
    let mut worst: f64 = 0.0;
    for i in 0..path.mean.len() {
        let se = (path.standard_error[i].powi(2) + bsdf.standard_error[i].powi(2)).sqrt();
        let difference = (path.mean[i] - bsdf.mean[i]).abs();
        let z = difference / (se + 1e-6);
        worst = worst.max(z);
        assert!(
            z < sigmas,
            "{name}: tile {} channel {}: path {:.4} ± {:.4}, bsdf {:.4} ± {:.4} ({z:.1} standard errors)",
            i / 3,
            i % 3,
            path.mean[i],
            path.standard_error[i],
            bsdf.mean[i],
            bsdf.standard_error[i]
        );
    }
    // The image as a whole: a smaller bias hides in tiles but not in the sum.
    let total = |s: &TileStats| s.mean.iter().sum::<f64>();
    let total_se = |s: &TileStats| s.standard_error.iter().map(|e| e * e).sum::<f64>().sqrt();
    let z = (total(&path) - total(&bsdf)).abs()
        / (total_se(&path).powi(2) + total_se(&bsdf).powi(2)).sqrt();
    assert!(
        z < 4.0,
        "{name}: image means differ by {z:.1} standard errors"
    );
    // Light sampling must also have paid off somewhere: less noise in the sum (where
    // there is something to sample).
    let sampled =
        !canopy_render::lights::Lights::new(scene).is_empty() || scene.background.is_sampled();
    assert!(
        !sampled || total_se(&path) < total_se(&bsdf),
        "{name}: light sampling did not reduce the noise ({} vs {})",
        total_se(&path),
        total_se(&bsdf)
    );
    eprintln!("{name}: worst tile {worst:.2} standard errors, image {z:.2}");
}

/// Serves in-memory files to scenes.
struct MemoryAssets(Vec<(&'static str, Vec<u8>)>);

impl Assets for MemoryAssets {
    fn read(&self, path: &str) -> Result<Vec<u8>, String> {
        self.0
            .iter()
            .find(|(name, _)| *name == path)
            .map(|(_, bytes)| bytes.clone())
            .ok_or_else(|| format!("no file {path}"))
    }
}

fn scene(source: &str, assets: &MemoryAssets) -> Scene {
    parse_scene(source, "test.toml", assets).unwrap_or_else(|e| panic!("{e}"))
}

const SMALL: &str = r#"
[render]
width = 32
height = 32
spp = 32
max_depth = 5
"#;

const FLOOR: &str = r#"
[materials.floor]
type = "lambertian"
albedo = [0.7, 0.7, 0.7]

[[cuboids]]
min = [-4, 0, -4]
max = [4, 0, 4]
material = "floor"
"#;

const CAMERA: &str = r#"
[camera]
look_from = [0, 2, 4]
look_at = [0, 0.5, 0]
vfov = 45
"#;

/// A Radiance .hdr image: a dim blue-grey sky with a bright sun up and to one side.
fn environment_hdr() -> Vec<u8> {
    let (w, h) = (32u32, 16u32);
    let pixels: Vec<image::Rgb<f32>> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            if (x, y) == (20, 4) {
                image::Rgb([300.0, 250.0, 200.0])
            } else {
                let up = 1.0 - y as f32 / h as f32;
                image::Rgb([0.2 * up, 0.3 * up, 0.5 * up + 0.05])
            }
        })
        .collect();
    let mut bytes = Vec::new();
    image::codecs::hdr::HdrEncoder::new(&mut bytes)
        .encode(&pixels, w as usize, h as usize)
        .unwrap();
    bytes
}

/// A unit quad in the xz-plane at height 0, as an OBJ.
const QUAD_OBJ: &[u8] = b"v -0.5 0 -0.5\nv 0.5 0 -0.5\nv 0.5 0 0.5\nv -0.5 0 0.5\nf 1 2 3 4\n";

fn assets() -> MemoryAssets {
    MemoryAssets(vec![
        ("sky.hdr", environment_hdr()),
        ("quad.obj", QUAD_OBJ.to_vec()),
    ])
}

#[test]
fn cornell_box_is_the_same_picture_with_and_without_light_sampling() {
    let mut cornell = BuiltinScene::find("cornell").unwrap().load().unwrap();
    cornell.settings.width = 32;
    cornell.settings.height = 32;
    cornell.settings.spp = 32;
    cornell.settings.max_depth = 5;
    assert_integrators_agree("cornell", &cornell, 16);
}

#[test]
fn small_sphere_light_over_a_diffuse_floor() {
    let source = format!(
        r#"background = [0, 0, 0]
{CAMERA}{SMALL}{FLOOR}
[[spheres]]
center = [0, 1.2, 0]
radius = 0.25
material = {{ type = "emissive", radiance = [12, 10, 8] }}

[[spheres]]
center = [0.8, 0.4, 0.3]
radius = 0.4
material = {{ type = "lambertian", albedo = [0.2, 0.6, 0.3] }}
"#
    );
    assert_integrators_agree("sphere light", &scene(&source, &assets()), 16);
}

#[test]
fn glossy_and_mirror_metal_under_a_small_area_light() {
    let source = format!(
        r#"background = [0, 0, 0]
{CAMERA}{SMALL}{FLOOR}
[[cuboids]] # the light, facing down
min = [-0.4, 2, -0.4]
max = [0.4, 2, 0.4]
material = {{ type = "emissive", radiance = [10, 10, 10] }}

[[spheres]]
center = [-0.6, 0.5, 0]
radius = 0.5
material = {{ type = "metal", albedo = [0.9, 0.8, 0.6], fuzz = 0.3 }}

[[spheres]]
center = [0.6, 0.5, 0]
radius = 0.5
material = {{ type = "metal", albedo = [0.8, 0.8, 0.8], fuzz = 0.05 }}

[[spheres]]
center = [0, 0.3, 1]
radius = 0.3
material = {{ type = "metal", albedo = [0.9, 0.9, 0.9] }}
"#
    );
    assert_integrators_agree("glossy metal", &scene(&source, &assets()), 16);
}

#[test]
fn glass_and_a_triangle_light_under_the_sky() {
    let source = format!(
        r#"background = "sky"
{CAMERA}{SMALL}{FLOOR}
[[meshes]] # two emissive triangles
file = "quad.obj"
translate = [0, 1.8, 0]
material = {{ type = "emissive", radiance = [6, 5, 4] }}

[[spheres]]
center = [0, 0.5, 0]
radius = 0.5
material = {{ type = "dielectric", ior = 1.5 }}

[[cuboids]]
min = [0.7, 0, -0.3]
max = [1.3, 0.6, 0.3]
material = {{ type = "lambertian", albedo = [0.6, 0.3, 0.2] }}
"#
    );
    assert_integrators_agree("glass and triangles", &scene(&source, &assets()), 16);
}

#[test]
fn environment_map_lights_diffuse_and_glossy_surfaces() {
    let source = format!(
        r#"background = {{ environment = "sky.hdr", rotate = 30 }}
{CAMERA}{SMALL}{FLOOR}
[[spheres]]
center = [-0.6, 0.5, 0]
radius = 0.5
material = {{ type = "lambertian", albedo = [0.8, 0.8, 0.8] }}

[[spheres]]
center = [0.6, 0.5, 0]
radius = 0.5
material = {{ type = "metal", albedo = [0.9, 0.9, 0.9], fuzz = 0.2 }}
"#
    );
    assert_integrators_agree("environment map", &scene(&source, &assets()), 16);
}

#[test]
fn metallic_roughness_surfaces_under_an_area_light_and_an_environment_map() {
    let source = format!(
        r#"background = {{ environment = "sky.hdr", rotate = 30 }}
{CAMERA}{SMALL}
[[cuboids]]
min = [-3, -0.1, -3]
max = [3, 0, 3]
material = {{ type = "pbr", base_color = [0.6, 0.6, 0.6], roughness = 0.7 }}

[[cuboids]] # the light, facing down
min = [-0.4, 2, -0.4]
max = [0.4, 2, 0.4]
material = {{ type = "emissive", radiance = [10, 10, 10] }}

[[spheres]]
center = [-0.6, 0.5, 0]
radius = 0.5
material = {{ type = "pbr", base_color = [1.0, 0.77, 0.34], metallic = 1, roughness = 0.35 }}

[[spheres]]
center = [0.6, 0.5, 0]
radius = 0.5
material = {{ type = "pbr", base_color = [0.2, 0.4, 0.8], roughness = 0.15 }}

[[spheres]]
center = [0, 0.3, 1]
radius = 0.3
material = {{ type = "pbr", base_color = [0.8, 0.3, 0.3], metallic = 0.5, roughness = 0.05 }}
"#
    );
    assert_integrators_agree("metallic-roughness", &scene(&source, &assets()), 16);
}

/// Mean of every 8x8 tile of `runs` path-traced renders is 1 within noise.
fn assert_furnace_is_one(name: &str, scene: &Scene, runs: u64) {
    let stats = tile_stats(scene, Integrator::Path, runs);
    for i in 0..stats.mean.len() {
        let z = (stats.mean[i] - 1.0).abs() / (stats.standard_error[i] + 1e-6);
        assert!(
            z < 4.5,
            "{name}: tile {} channel {}: {:.4} ± {:.4}",
            i / 3,
            i % 3,
            stats.mean[i],
            stats.standard_error[i]
        );
    }
    let mean = stats.mean.iter().sum::<f64>() / stats.mean.len() as f64;
    assert!((mean - 1.0).abs() < 0.01, "{name}: image mean {mean}");
}

const FURNACE_OBJECTS: &str = r#"
[camera]
look_from = [0.3, 0.4, 4]
look_at = [0, 0, 0]
vfov = 35

[render]
width = 16
height = 16
spp = 16
max_depth = 12

[materials.white]
type = "lambertian"
albedo = [1, 1, 1]

[[spheres]]
center = [0, 0, 0]
radius = 1
material = "white"

[[cuboids]]
min = [-0.3, -0.3, -0.3]
max = [0.3, 0.3, 0.3]
translate = [0.9, 0.9, 0.6]
material = "white"
"#;

#[test]
fn white_furnace_with_light_sampling_under_a_constant_sky() {
    let source = format!("background = [1, 1, 1]\n{FURNACE_OBJECTS}");
    let mut furnace = scene(&source, &assets());
    assert_furnace_is_one("constant sky", &furnace, 8);
    furnace.settings.russian_roulette = false;
    assert_furnace_is_one("constant sky, no roulette", &furnace, 8);
}

#[test]
fn white_furnace_under_a_uniform_environment_map() {
    let mut bytes = Vec::new();
    let white = vec![image::Rgb([1.0f32, 1.0, 1.0]); 8 * 4];
    image::codecs::hdr::HdrEncoder::new(&mut bytes)
        .encode(&white, 8, 4)
        .unwrap();
    let source = format!(
        "background = {{ environment = \"white.hdr\", rotate = [10, 20, 30] }}\n{FURNACE_OBJECTS}"
    );
    let furnace = scene(&source, &MemoryAssets(vec![("white.hdr", bytes)]));
    assert_furnace_is_one("environment map", &furnace, 8);
}

/// Root-mean-square difference of two films as displayed: radiance clamped to 1 per
/// channel, as an 8-bit image shows it. Unclamped, the error is 98% the light's edge
/// pixels (15 against 0.7, by pixel coverage), noise that no integrator changes.
fn rmse(a: &Film, b: &Film) -> f64 {
    let sum: f64 = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(p, q)| (p.min(Vec3::ONE) - q.min(Vec3::ONE)).length_squared() as f64)
        .sum();
    (sum / (3 * a.pixels.len()) as f64).sqrt()
}

#[test]
fn light_sampling_cuts_the_cornell_box_error_several_fold_at_equal_samples() {
    let mut cornell = BuiltinScene::find("cornell").unwrap().load().unwrap();
    cornell.settings.width = 48;
    cornell.settings.height = 48;
    cornell.settings.max_depth = 6;
    let mut reference = cornell.clone();
    reference.settings.spp = 1024;
    reference.settings.seed = 99;
    let reference = render_film(&reference);
    let at = |integrator| {
        let mut s = cornell.clone();
        s.settings.spp = 16;
        s.settings.integrator = integrator;
        rmse(&render_film(&s), &reference)
    };
    let (path, bsdf) = (at(Integrator::Path), at(Integrator::Bsdf));
    eprintln!("cornell RMSE at 16 spp: path {path:.4}, bsdf {bsdf:.4}");
    // Measured 0.018 against 0.176: 9.6x.
    assert!(bsdf > 5.0 * path, "path {path}, bsdf {bsdf}");
}

#[test]
fn light_sampled_images_do_not_depend_on_the_thread_count() {
    let mut cornell = BuiltinScene::find("cornell").unwrap().load().unwrap();
    cornell.settings.width = 24;
    cornell.settings.height = 24;
    cornell.settings.spp = 4;
    let image = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| render_film(&cornell))
    };
    assert_eq!(image(1).pixels, image(3).pixels);
    assert!(image(1).pixels.iter().any(|p| *p != Vec3::ZERO));
}

/// A quad mesh from `corners` (counter-clockwise seen from its front) with texture
/// coordinates (0, 0), (1, 0), (1, 1), (0, 1) at them.
fn quad(name: &str, corners: [Vec3; 4]) -> canopy_render::SceneMesh {
    canopy_render::SceneMesh {
        name: name.into(),
        mesh: std::sync::Arc::new(
            canopy_bvh::TriangleMesh::new(corners.to_vec(), vec![[0, 1, 2], [0, 2, 3]]).unwrap(),
        ),
        normals: Vec::new(),
        uvs: vec![
            glam::Vec2::new(0.0, 0.0),
            glam::Vec2::new(1.0, 0.0),
            glam::Vec2::new(1.0, 1.0),
            glam::Vec2::new(0.0, 1.0),
        ],
        tangents: Vec::new(),
    }
}

#[test]
fn an_emissive_texture_lights_as_it_looks() {
    use canopy_render::material::{Material, Pbr};
    use canopy_render::texture::{Image, MaterialMaps, TextureRef, Wrap};
    // A glowing panel over a white floor, its emission scaled by four coloured
    // quadrants: light sampling must find each quadrant's colour where the BSDF-only
    // estimator does (a panel sampled by its factor alone would light the floor white).
    let quadrants = Image {
        width: 2,
        height: 2,
        texels: vec![
            [255, 0, 0, 255],
            [0, 255, 0, 255],
            [0, 0, 255, 255],
            [255, 255, 255, 255],
        ],
    };
    let panel = Pbr {
        base_color: Vec3::splat(0.2),
        metallic: 0.0,
        roughness: 0.6,
        emission: Vec3::splat(6.0),
    };
    let mut scene = Scene {
        materials: vec![
            Material::Lambertian {
                albedo: Vec3::splat(0.8),
            },
            Material::Pbr(panel),
        ],
        meshes: vec![
            quad(
                "floor",
                [
                    Vec3::new(-3.0, 0.0, 3.0),
                    Vec3::new(3.0, 0.0, 3.0),
                    Vec3::new(3.0, 0.0, -3.0),
                    Vec3::new(-3.0, 0.0, -3.0),
                ],
            ),
            quad(
                "panel",
                [
                    Vec3::new(-1.0, 1.0, -1.0),
                    Vec3::new(1.0, 1.0, -1.0),
                    Vec3::new(1.0, 1.0, 1.0),
                    Vec3::new(-1.0, 1.0, 1.0),
                ],
            ),
        ],
        instances: (0..2)
            .map(|k| canopy_render::MeshInstance {
                mesh: k,
                to_world: glam::Affine3A::IDENTITY,
                material: k,
            })
            .collect(),
        images: vec![std::sync::Arc::new(quadrants)],
        background: canopy_render::Background::Constant(Vec3::ZERO),
        ..Scene::default()
    };
    scene
        .set_material_maps(
            1,
            MaterialMaps {
                emissive: Some(TextureRef {
                    image: 0,
                    wrap: [Wrap::ClampToEdge; 2],
                    transform: None,
                }),
                ..MaterialMaps::default()
            },
        )
        .unwrap();
    scene.camera.look_from = Vec3::new(0.0, 1.6, 4.0);
    scene.camera.look_at = Vec3::new(0.0, 0.3, 0.0);
    scene.camera.vfov = 60.0;
    scene.settings = canopy_render::RenderSettings {
        width: 32,
        height: 32,
        spp: 16,
        max_depth: 3,
        ..Default::default()
    };
    assert_integrators_agree("emissive texture", &scene, 48);
}

#[test]
fn gltf_models_are_the_same_picture_with_and_without_light_sampling() {
    // Textures, alpha modes, a normal map and instanced wheels, under a dim environment
    // map with a bright patch (which light sampling finds far more often).
    let (width, height) = (16, 8);
    let mut pixels = vec![Vec3::new(0.3, 0.32, 0.35); width * height];
    for (row, column) in [(1, 4), (1, 5), (1, 6), (2, 4), (2, 5), (2, 6)] {
        pixels[row * width + column] = Vec3::new(4.0, 3.7, 3.4);
    }
    let turn = glam::Mat3::from_rotation_y(0.4);
    let map = canopy_render::EnvironmentMap::new("patch.hdr", width, height, pixels, turn);
    let patch = canopy_render::Background::Environment(std::sync::Arc::new(map));
    for model in [
        "BoxTextured.glb",
        "CesiumMilkTruck.glb",
        "AlphaBlendModeTest.glb",
    ] {
        let path = format!("{}/../../scenes/gltf/{model}", env!("CARGO_MANIFEST_DIR"));
        let mut scene = canopy_render::load_scene(&path).unwrap();
        scene.background = patch.clone();
        scene.settings.width = 32;
        scene.settings.height = 32;
        scene.settings.spp = 16;
        scene.settings.max_depth = 4;
        assert_integrators_agree(model, &scene, 32);
    }
}
