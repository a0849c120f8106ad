//! The AOVs against values worked out by hand on small scenes, and their determinism:
//! the same bit for bit in a region, across a split of the samples (a resumed render)
//! and in both schedules.

use canopy_bvh::{BuildParams, BvhWidth};
use canopy_render::accel::{Accel, AccelKind};
use canopy_render::aov::NO_ID;
use canopy_render::scene_file::{parse_scene, Assets};
use canopy_render::{
    render_samples_with, Accumulator, Aov, AovBuffers, AovSet, BuiltinScene, Region, Scene,
    Schedule,
};
use glam::Vec3;

struct NoAssets;

impl Assets for NoAssets {
    fn read(&self, path: &str) -> Result<Vec<u8>, String> {
        Err(format!("{path}: no files in this test"))
    }
}

fn scene(source: &str) -> Scene {
    parse_scene(source, "test.toml", &NoAssets).unwrap_or_else(|e| panic!("{e}"))
}

fn accel_of(scene: &Scene) -> Accel {
    Accel::for_scene(
        scene,
        AccelKind::default(),
        BvhWidth::Four,
        &BuildParams::default(),
        None,
    )
}

/// `count` samples from sample `first` over `region`, with every AOV.
fn render(
    scene: &Scene,
    region: Region,
    first: u32,
    count: u32,
    schedule: Schedule,
) -> Accumulator {
    let accel = accel_of(scene);
    let mut acc = Accumulator::for_region(region).with_aovs(AovSet::of(&Aov::ALL));
    acc.samples = first;
    render_samples_with(scene, &accel, &mut acc, count, schedule, &|| {});
    acc
}

fn images(scene: &Scene) -> AovBuffers {
    let s = scene.settings;
    render(
        scene,
        Region::full(s.width, s.height),
        0,
        s.spp,
        Schedule::default(),
    )
    .aov_images()
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).abs().max_element() < 1e-5
}

/// A red Lambertian wall fills the view of a camera looking down -z at it.
const WALL: &str = r#"
background = [0, 0, 0]
[camera]
look_from = [0, 0, 5]
look_at = [0, 0, 0]
vfov = 30
[render]
width = 8
height = 8
spp = 6
[[cuboids]]
min = [-10, -10, -1]
max = [10, 10, 0]
material = { type = "lambertian", albedo = [0.7, 0.2, 0.1] }
"#;

#[test]
fn a_lambertian_surface_shows_its_colour_and_its_normal() {
    let scene = scene(WALL);
    let aovs = images(&scene);
    for i in 0..64 {
        assert!(
            close(aovs.albedo[i], Vec3::new(0.7, 0.2, 0.1)),
            "{:?}",
            aovs.albedo[i]
        );
        assert!(close(aovs.normal[i], Vec3::Z), "{:?}", aovs.normal[i]);
        assert_eq!(aovs.position[i].z, 0.0);
        // The distance from the eye to the point hit.
        let distance = (aovs.position[i] - Vec3::new(0.0, 0.0, 5.0)).length();
        assert!(
            (aovs.depth[i] - distance).abs() < 1e-4,
            "{} {distance}",
            aovs.depth[i]
        );
        assert_ne!(aovs.primitive[i], NO_ID);
    }
}

#[test]
fn a_mirror_shows_the_albedo_of_what_it_reflects() {
    // A mirror at 45 degrees turns the view from -z to +x, onto a green wall; the sky
    // around is black.
    let source = r#"
background = [0, 0, 0]
[camera]
look_from = [0, 0, 5]
look_at = [0, 0, 0]
vfov = 10
[render]
width = 6
height = 6
spp = 4
[[cuboids]]
min = [-3, -3, -0.01]
max = [3, 3, 0]
rotate = [0, 45, 0]
material = { type = "metal", albedo = [0.9, 0.8, 0.5], fuzz = 0 }
[[cuboids]]
min = [5, -50, -50]
max = [6, 50, 50]
material = { type = "lambertian", albedo = [0.2, 0.6, 0.3] }
"#;
    let aovs = images(&scene(source));
    let expected = Vec3::new(0.9, 0.8, 0.5) * Vec3::new(0.2, 0.6, 0.3);
    for i in 0..36 {
        assert!(
            close(aovs.albedo[i], expected),
            "pixel {i}: {:?}",
            aovs.albedo[i]
        );
        // The wall's normal, facing the reflected ray: -x.
        assert!(
            close(aovs.normal[i], -Vec3::X),
            "pixel {i}: {:?}",
            aovs.normal[i]
        );
        // Depth and position are the mirror's (the first hit), not the wall's (10 away).
        let distance = (aovs.position[i] - Vec3::new(0.0, 0.0, 5.0)).length();
        assert!((aovs.depth[i] - distance).abs() < 1e-4 && distance < 6.0);
    }
}

#[test]
fn normals_are_unit_and_face_the_camera_and_the_sky_is_its_colour() {
    let mut scene = BuiltinScene::find("paper-3").unwrap().load().unwrap();
    (
        scene.settings.width,
        scene.settings.height,
        scene.settings.spp,
    ) = (24, 16, 4);
    let aovs = images(&scene);
    let s = scene.settings;
    let camera = canopy_render::camera::Camera::new(&scene.camera, s.width, s.height);
    let (mut surfaces, mut sky) = (0, 0);
    for y in 0..s.height {
        for x in 0..s.width {
            let i = (y * s.width + x) as usize;
            let n = aovs.normal[i];
            if aovs.primitive[i] == NO_ID {
                sky += 1;
                continue;
            }
            surfaces += 1;
            // Within one object a pixel's samples agree closely: close to unit.
            if (n.length() - 1.0).abs() < 1e-3 {
                let centre = canopy_render::camera::Camera::ray(
                    &camera,
                    (x as f32 + 0.5) / s.width as f32,
                    (y as f32 + 0.5) / s.height as f32,
                    &mut canopy_render::rng::Rng::for_sample(0, 0, 0),
                );
                assert!(
                    n.dot(centre.dir) < 0.0,
                    "pixel ({x}, {y}): {n:?} faces away"
                );
            }
            assert!(n.length() <= 1.0 + 1e-5);
            assert!(aovs.albedo[i].cmple(Vec3::ONE + 1e-5).all());
        }
    }
    assert!(
        surfaces > 50 && sky > 0,
        "{surfaces} surface pixels, {sky} sky pixels"
    );
}

#[test]
fn aovs_are_the_same_in_a_region_across_a_split_and_in_both_schedules() {
    let mut scene = BuiltinScene::find("paper-3").unwrap().load().unwrap();
    (scene.settings.width, scene.settings.height) = (20, 12);
    let full = Region::full(20, 12);
    let whole = render(&scene, full, 0, 5, Schedule::Wavefront);
    assert!(whole.aovs.albedo.iter().any(|a| *a != Vec3::ZERO));
    // Split into 2 + 3 samples, as a resumed render is.
    let mut split = render(&scene, full, 0, 2, Schedule::Depth);
    let accel = accel_of(&scene);
    render_samples_with(&scene, &accel, &mut split, 3, Schedule::Wavefront, &|| {});
    assert_eq!(split.aovs, whole.aovs);
    assert_eq!(split.sums, whole.sums);
    // A region holds the same pixels.
    let region = Region {
        x: 3,
        y: 5,
        width: 9,
        height: 4,
    };
    let part = render(&scene, region, 0, 5, Schedule::Depth);
    for row in 0..region.height as usize {
        for col in 0..region.width as usize {
            let inside = row * region.width as usize + col;
            let outside = (row + region.y as usize) * 20 + col + region.x as usize;
            assert_eq!(part.aovs.albedo[inside], whole.aovs.albedo[outside]);
            assert_eq!(part.aovs.normal[inside], whole.aovs.normal[outside]);
            assert_eq!(part.aovs.depth[inside], whole.aovs.depth[outside]);
            assert_eq!(part.aovs.primitive[inside], whole.aovs.primitive[outside]);
        }
    }
}

/// The AOVs traced alone (what a GPU render gets) are those the paths saw, bit for bit,
/// through glass and mirrors (paper-3's glass and metal spheres) and with both estimators.
#[test]
fn aovs_traced_alone_are_the_paths_own() {
    for integrator in [
        canopy_render::Integrator::Path,
        canopy_render::Integrator::Bsdf,
    ] {
        let mut scene = BuiltinScene::find("paper-3").unwrap().load().unwrap();
        (scene.settings.width, scene.settings.height) = (24, 16);
        scene.settings.integrator = integrator;
        let full = Region::full(24, 16);
        let with_paths = render(&scene, full, 0, 4, Schedule::Wavefront);
        let accel = accel_of(&scene);
        let mut alone = Accumulator::for_region(full).with_aovs(AovSet::of(&Aov::ALL));
        for _ in 0..4 {
            canopy_render::render_aov_samples(&scene, &accel, &mut alone, 1);
            alone.samples += 1;
        }
        assert_eq!(alone.aovs, with_paths.aovs, "{integrator}");
    }
}
