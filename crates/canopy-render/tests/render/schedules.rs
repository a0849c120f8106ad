//! The wavefront schedule renders the depth-first schedule's image bit for bit: on every
//! built-in scene with both estimators, with see-through (alpha) surfaces, textures and
//! punctual lights (whose shadow rays the wavefront traces in packets), for any thread
//! count, region and split of the samples.

use canopy_render::accel::Accel;
use canopy_render::lights::PunctualLight;
use canopy_render::{
    load_scene, render_samples_with, Accumulator, BuiltinScene, Integrator, Region, Scene,
    Schedule, BUILTIN_SCENES,
};
use glam::Vec3;
use std::path::Path;

fn accel_of(scene: &Scene) -> Accel {
    Accel::default_for(scene)
}

fn shrunk(mut scene: Scene) -> Scene {
    (
        scene.settings.width,
        scene.settings.height,
        scene.settings.spp,
    ) = (32, 24, 3);
    scene.settings.max_depth = scene.settings.max_depth.min(12);
    scene
}

/// The sums of `count` samples from sample `first` over `region`, in `schedule`.
fn sums(
    scene: &Scene,
    accel: &Accel,
    region: Region,
    first: u32,
    count: u32,
    schedule: Schedule,
) -> Accumulator {
    let mut accumulator = Accumulator::for_region(region);
    accumulator.samples = first;
    render_samples_with(scene, accel, &mut accumulator, count, schedule, &|| {});
    accumulator
}

fn same_in_both_schedules(scene: &Scene, what: &str) {
    let accel = accel_of(scene);
    let full = Region::full(scene.settings.width, scene.settings.height);
    let depth = sums(scene, &accel, full, 0, scene.settings.spp, Schedule::Depth);
    let wavefront = sums(
        scene,
        &accel,
        full,
        0,
        scene.settings.spp,
        Schedule::Wavefront,
    );
    assert!(
        depth.sums.iter().any(|s| *s != Vec3::ZERO),
        "{what}: the image is black"
    );
    for (i, (d, w)) in depth.sums.iter().zip(&wavefront.sums).enumerate() {
        assert_eq!(
            d.to_array().map(f32::to_bits),
            w.to_array().map(f32::to_bits),
            "{what}: pixel {i}"
        );
    }
    assert_eq!(depth.rays, wavefront.rays, "{what}: rays");
    assert_eq!(depth.invalid_samples, wavefront.invalid_samples, "{what}");
}

#[test]
fn every_built_in_scene_is_the_same_in_both_schedules_with_both_estimators() {
    for builtin in BUILTIN_SCENES {
        for integrator in Integrator::ALL {
            let mut scene = shrunk(builtin.load().unwrap());
            scene.settings.integrator = integrator;
            same_in_both_schedules(&scene, &format!("{} {integrator}", builtin.name));
        }
    }
}

#[test]
fn see_through_textured_and_punctually_lit_scenes_are_the_same_in_both_schedules() {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/gltf");
    for model in ["AlphaBlendModeTest.glb", "CesiumMilkTruck.glb"] {
        let scene = shrunk(load_scene(models.join(model).to_str().unwrap()).unwrap());
        same_in_both_schedules(&scene, model);
    }
    let mut lit = shrunk(BuiltinScene::find("cornell").unwrap().load().unwrap());
    lit.lights.push(PunctualLight::Point {
        position: Vec3::new(0.0, 1.5, 0.0),
        intensity: Vec3::splat(3.0),
    });
    same_in_both_schedules(&lit, "cornell with a point light");
    // Shadow rays in packets: over kept spheres, and over triangle packs beside them.
    for name in ["paper-1", "paper-5"] {
        let mut lit = shrunk(BuiltinScene::find(name).unwrap().load().unwrap());
        lit.lights.push(PunctualLight::Point {
            position: Vec3::new(2.0, 6.0, 1.0),
            intensity: Vec3::splat(40.0),
        });
        same_in_both_schedules(&lit, &format!("{name} with a point light"));
    }
}

#[test]
fn wavefront_images_do_not_depend_on_threads_regions_or_sample_splits() {
    let scene = shrunk(BuiltinScene::find("paper-5").unwrap().load().unwrap());
    let accel = accel_of(&scene);
    let full = Region::full(32, 24);
    let on_threads = |threads| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| sums(&scene, &accel, full, 0, 3, Schedule::Wavefront))
    };
    let whole = on_threads(1);
    assert_eq!(whole, on_threads(2));
    assert_eq!(whole, on_threads(3));

    let region = Region {
        x: 5,
        y: 7,
        width: 11,
        height: 6,
    };
    let part = sums(&scene, &accel, region, 0, 3, Schedule::Wavefront);
    for y in 0..6 {
        for x in 0..11 {
            let whole_pixel = whole.sums[(7 + y) * 32 + 5 + x];
            assert_eq!(
                part.sums[y * 11 + x],
                whole_pixel,
                "pixel {x},{y} of the region"
            );
        }
    }

    // Two samples, then the third, add up to the three at once.
    let mut split = sums(&scene, &accel, full, 0, 2, Schedule::Wavefront);
    render_samples_with(&scene, &accel, &mut split, 1, Schedule::Wavefront, &|| {});
    assert_eq!(split.sums, whole.sums);
    assert_eq!(split.samples, 3);
}
