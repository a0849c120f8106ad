//! End-to-end checks of the integrator: energy conservation (white furnace), exact
//! determinism across thread counts, and identical images with and without a BVH (every
//! builder, every width).

use canopy_bvh::{BuildParams, Builder};
use canopy_render::camera::CameraSpec;
use canopy_render::geometry::{Cuboid, Shape, Sphere, Triangle};
use canopy_render::material::Material;
use canopy_render::scene::Primitive;
use canopy_render::{
    render, Accel, AccelKind, Background, BuiltinScene, BvhWidth, Film, Integrator, RenderSettings,
    Sampler, Scene,
};
use glam::Vec3;

/// A scene of the given shapes, all of one material, under a uniform white sky.
fn furnace(shapes: Vec<Shape>, material: Material, max_depth: u32) -> Scene {
    Scene {
        camera: CameraSpec {
            look_from: Vec3::new(0.3, 0.4, 4.0),
            look_at: Vec3::ZERO,
            vfov: 35.0,
            ..CameraSpec::default()
        },
        settings: RenderSettings {
            width: 24,
            height: 24,
            spp: 16,
            max_depth,
            seed: 7,
            integrator: Integrator::Bsdf,
            russian_roulette: false,
            ..RenderSettings::default()
        },
        background: Background::Constant(Vec3::ONE),
        materials: vec![material],
        primitives: std::sync::Arc::new(
            shapes
                .into_iter()
                .map(|shape| Primitive { shape, material: 0 })
                .collect(),
        ),
        ..Scene::default()
    }
}

fn render_with(scene: &Scene, kind: AccelKind) -> Film {
    render_wide(scene, kind, BvhWidth::Two)
}

fn render_wide(scene: &Scene, kind: AccelKind, width: BvhWidth) -> Film {
    let accel = Accel::for_scene(scene, kind, width, &BuildParams::default(), None);
    render(scene, &accel, &|| {}).0
}

/// A closed cube of 12 triangles, centred at the origin.
fn triangle_cube() -> Vec<Shape> {
    let c =
        |i: usize| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32) - 0.5;
    let faces = [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
    ];
    faces
        .iter()
        .flat_map(|&[a, b, d, e]| {
            [
                Triangle::new(c(a), c(b), c(d)),
                Triangle::new(c(a), c(d), c(e)),
            ]
        })
        .map(Shape::Triangle)
        .collect()
}

/// With albedo 1, a convex object under a white sky reflects exactly what reaches it: one
/// bounce, then the sky. Any self-intersection (or lost energy) shows as a dark pixel,
/// since two segments are all a path may have.
#[test]
fn white_furnace_convex_shapes_render_exactly_one() {
    let white = Material::Lambertian { albedo: Vec3::ONE };
    let cases = [
        ("sphere", vec![Shape::Sphere(Sphere::new(Vec3::ZERO, 1.0))]),
        (
            "cuboid",
            vec![Shape::Cuboid(Cuboid::axis_aligned(
                Vec3::splat(-0.7),
                Vec3::splat(0.7),
            ))],
        ),
        ("triangle cube", triangle_cube()),
    ];
    for (name, shapes) in cases {
        let film = render_with(&furnace(shapes, white, 2), AccelKind::default());
        for (i, p) in film.pixels.iter().enumerate() {
            assert!(
                (*p - Vec3::ONE).abs().max_element() < 1e-5,
                "{name}: pixel {i} = {p}"
            );
        }
    }
}

#[test]
fn grey_lambertian_sphere_reflects_its_albedo() {
    let grey = Material::Lambertian {
        albedo: Vec3::splat(0.5),
    };
    let film = render_with(
        &furnace(vec![Shape::Sphere(Sphere::new(Vec3::ZERO, 1.0))], grey, 2),
        AccelKind::default(),
    );
    let centre = film.pixel(12, 12);
    assert!(
        (centre - Vec3::splat(0.5)).abs().max_element() < 1e-5,
        "{centre}"
    );
    assert_eq!(film.pixel(0, 0), Vec3::ONE, "corner sees the sky");
}

/// Glass neither gains nor loses energy: every path eventually leaves to the white sky.
/// Only paths longer than the depth limit are lost, which are very rare at depth 64.
#[test]
fn white_furnace_dielectric_conserves_energy() {
    let glass = Material::Dielectric { ior: 1.5 };
    for shapes in [
        vec![Shape::Sphere(Sphere::new(Vec3::ZERO, 1.0))],
        vec![Shape::Cuboid(Cuboid::axis_aligned(
            Vec3::splat(-0.7),
            Vec3::splat(0.7),
        ))],
    ] {
        let film = render_with(&furnace(shapes, glass, 64), AccelKind::default());
        let mean: Vec3 = film.pixels.iter().copied().sum::<Vec3>() / film.pixels.len() as f32;
        assert!((mean - Vec3::ONE).abs().max_element() < 0.01, "mean {mean}");
        for p in &film.pixels {
            // Each sample carries exactly 1 (or 0 if cut off): no gain, anywhere.
            assert!(p.max_element() <= 1.0 + 1e-5, "energy gained: {p}");
        }
    }
}

fn small(name: &str) -> Scene {
    let mut scene = BuiltinScene::find(name).unwrap().load().unwrap();
    scene.settings = RenderSettings {
        width: 40,
        height: 30,
        spp: 3,
        ..scene.settings
    };
    scene
}

#[test]
fn image_is_identical_for_any_number_of_threads() {
    let scene = small("paper-5");
    let render_on = |threads| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| render_with(&scene, AccelKind::default()))
    };
    let one = render_on(1);
    assert_eq!(one, render_on(2));
    assert_eq!(one, render_on(3));
}

/// With light sampling (the default integrator) this also holds the shadow rays' any-hit
/// queries to brute force.
#[test]
fn bvh_and_brute_force_render_the_same_image() {
    for name in ["paper-1", "paper-3", "cornell"] {
        let scene = small(name);
        let linear = render_with(&scene, AccelKind::None);
        for &builder in Builder::ALL {
            for width in BvhWidth::ALL {
                let image = render_wide(&scene, AccelKind::Bvh(builder), width);
                assert_eq!(linear, image, "{name} with {builder} x{width}");
            }
        }
    }
}

/// A scene of mesh instances (400 teapots: turned, mirrored, squashed, emissive) renders
/// the same image through every builder and width, for the bottom and top structures
/// alike (brute force over 400k placed triangles would take minutes here; canopy-bvh's
/// tests hold the instanced queries to brute force ray by ray).
#[test]
fn instanced_scene_renders_the_same_image_through_every_structure() {
    let mut scene = small("teapots");
    scene.settings.width = 24;
    scene.settings.height = 16;
    let reference = render_wide(&scene, AccelKind::default(), BvhWidth::Eight);
    let lit = reference
        .pixels
        .iter()
        .filter(|p| p.max_element() > 0.0)
        .count();
    assert!(lit > reference.pixels.len() / 2);
    for &builder in Builder::ALL {
        for width in BvhWidth::ALL {
            let image = render_wide(&scene, AccelKind::Bvh(builder), width);
            assert_eq!(reference, image, "{builder} x{width}");
        }
    }
}

#[test]
fn different_seeds_give_different_noise() {
    let mut scene = small("paper-1");
    let a = render_with(&scene, AccelKind::default());
    scene.settings.seed += 1;
    assert_ne!(a, render_with(&scene, AccelKind::default()));
}

/// Sobol points give the independent sampler's expected image with less noise: per
/// pixel, the two seeds' renders differ less, and the images' means agree within the
/// noise (spheres under the sky, an area light, glass).
#[test]
fn sobol_sampling_is_unbiased_and_less_noisy() {
    for name in ["paper-1", "cornell", "paper-6"] {
        let mut scene = small(name);
        (
            scene.settings.width,
            scene.settings.height,
            scene.settings.spp,
        ) = (24, 24, 64);
        let accel = Accel::default_for(&scene);
        // Per sampler: the mean of the two seeds' images and the RMS per-pixel noise.
        let mut measure = |sampler| {
            scene.settings.sampler = sampler;
            let films: Vec<Film> = (0..2)
                .map(|seed| {
                    scene.settings.seed = seed;
                    render(&scene, &accel, &|| {}).0
                })
                .collect();
            let pixels = films[0].pixels.iter().zip(&films[1].pixels);
            let (mut sum, mut squares) = (0.0f64, 0.0f64);
            for (a, b) in pixels {
                sum += (*a + *b).element_sum() as f64 / 2.0;
                squares += (*a - *b).length_squared() as f64 / 2.0;
            }
            let n = films[0].pixels.len() as f64 * 3.0;
            (sum / n, (squares / n).sqrt())
        };
        let (sobol_mean, sobol_noise) = measure(Sampler::Sobol);
        let (mean, noise) = measure(Sampler::Independent);
        assert!(
            sobol_noise < 0.85 * noise,
            "{name}: noise {sobol_noise} against {noise}"
        );
        // Standard error of each image mean: two renders, every pixel and channel.
        let n = 24.0 * 24.0 * 3.0 * 2.0;
        let error = (sobol_noise.powi(2) + noise.powi(2)).sqrt() / f64::sqrt(n);
        let z = (sobol_mean - mean).abs() / error;
        assert!(
            z < 4.0,
            "{name}: means {sobol_mean} and {mean} are {z:.1} standard errors apart"
        );
    }
}

#[test]
fn counted_render_is_the_same_image_and_counts_the_work() {
    let scene = small("paper-3");
    let none = Accel::build(
        AccelKind::None,
        BvhWidth::Two,
        &scene.primitives,
        &BuildParams::default(),
    );
    let (plain, _) = render(&scene, &none, &|| {});
    let (counted, stats) = canopy_render::render_counted(&scene, &none, &|| {});
    assert_eq!(plain, counted);
    // Brute force tests every primitive for every closest-hit ray and visits no node
    // (shadow rays are timed, not counted).
    assert_eq!(
        stats.traversal.primitives_tested,
        (stats.rays - stats.shadow_rays) * scene.primitives.len() as u64
    );
    assert_eq!(stats.traversal.nodes_visited, 0);
    let bvh = Accel::build(
        AccelKind::default(),
        BvhWidth::Four,
        &scene.primitives,
        &BuildParams::default(),
    );
    let (_, stats) = canopy_render::render_counted(&scene, &bvh, &|| {});
    assert!(stats.traversal.nodes_visited > 0);
    assert!(stats.traversal.primitives_tested < stats.rays * scene.primitives.len() as u64 / 10);
    // Lit by an emitter, light sampling sends shadow rays, and they are timed (a sky
    // alone, as above, is left to BSDF sampling: no shadow rays).
    assert_eq!(stats.shadow_rays, 0);
    let lit = small("cornell");
    let accel = Accel::default_for(&lit);
    let (_, stats) = canopy_render::render_counted(&lit, &accel, &|| {});
    assert!(stats.shadow_rays > 0 && stats.shadow_time > std::time::Duration::ZERO);
}
