//! Point, spot and directional lights: the irradiance each brings to a diffuse floor is
//! the closed form (intensity / d², times the spot's falloff; the directional light's
//! irradiance times the cosine), seen through the path integrator; they cast shadows;
//! and glTF files place them by their nodes.

use canopy_render::camera::CameraSpec;
use canopy_render::lights::PunctualLight;
use canopy_render::material::Material;
use canopy_render::{integrator, Accel, Integrator, Scene};
use glam::Vec3;
use std::f32::consts::PI;

const ALBEDO: f32 = 0.6;

/// A large diffuse floor at y = 0 under a black sky, seen from straight above through a
/// narrow lens, lit by `light` alone; paths of one bounce (direct light only).
fn floor_under(light: PunctualLight) -> Scene {
    let mut scene = Scene::default();
    scene.set_background_color(Vec3::ZERO).unwrap();
    let floor = scene
        .add_material(Material::Lambertian {
            albedo: Vec3::splat(ALBEDO),
        })
        .unwrap();
    scene
        .add_cuboid(
            Vec3::new(-50.0, -1.0, -50.0),
            Vec3::new(50.0, 0.0, 50.0),
            [0.0; 3],
            Vec3::ZERO,
            floor,
        )
        .unwrap();
    scene
        .set_camera(CameraSpec {
            look_from: Vec3::new(0.0, 10.0, 0.0),
            look_at: Vec3::ZERO,
            up: Vec3::Z,
            vfov: 0.01,
            ..CameraSpec::default()
        })
        .unwrap();
    scene.add_light(light).unwrap();
    (
        scene.settings.width,
        scene.settings.height,
        scene.settings.spp,
    ) = (3, 3, 4);
    scene.settings.max_depth = 2;
    scene.settings.integrator = Integrator::Path;
    scene
}

/// The radiance the camera sees at the middle of the image.
fn centre(scene: &Scene) -> Vec3 {
    let accel = Accel::default_for(scene);
    integrator::render(scene, &accel, &|| {}).0.pixel(1, 1)
}

/// What a Lambertian floor of `ALBEDO` reflects under irradiance `e`.
fn reflected(e: f32) -> f32 {
    ALBEDO / PI * e
}

#[test]
fn a_point_light_brings_intensity_over_distance_squared() {
    let scene = floor_under(PunctualLight::Point {
        position: Vec3::new(0.0, 2.0, 0.0),
        intensity: Vec3::new(8.0, 4.0, 2.0),
    });
    let seen = centre(&scene);
    let expected = Vec3::new(reflected(2.0), reflected(1.0), reflected(0.5));
    assert!(
        (seen - expected).abs().max_element() < 1e-3 * expected.x,
        "{seen} vs {expected}"
    );
    // Off to the side, the cosine and the distance both dim it: d² = 8, cos = 2 / √8.
    let mut side = scene.clone();
    side.lights[0] = PunctualLight::Point {
        position: Vec3::new(2.0, 2.0, 0.0),
        intensity: Vec3::splat(8.0),
    };
    let e = 8.0 / 8.0 * (2.0 / 8f32.sqrt());
    assert!((centre(&side).x - reflected(e)).abs() < 1e-3 * reflected(e));
}

#[test]
fn a_spot_light_fades_between_its_cones_and_a_directional_light_by_the_cosine() {
    let spot = |tilt_degrees: f32| {
        let t = tilt_degrees.to_radians();
        floor_under(PunctualLight::Spot {
            position: Vec3::new(0.0, 2.0, 0.0),
            direction: Vec3::new(t.sin(), -t.cos(), 0.0),
            intensity: Vec3::splat(8.0),
            cos_inner: 20f32.to_radians().cos(),
            cos_outer: 40f32.to_radians().cos(),
        })
    };
    let full = reflected(2.0);
    assert!(
        (centre(&spot(10.0)).x - full).abs() < 1e-3 * full,
        "inside the inner cone"
    );
    assert_eq!(centre(&spot(45.0)).x, 0.0, "outside the outer cone");
    // Halfway in cosine between the cones: the specification's falloff, squared.
    let (ci, co) = (20f32.to_radians().cos(), 40f32.to_radians().cos());
    let tilt = (0.5 * (ci + co)).acos().to_degrees();
    let expected = full * 0.25;
    assert!(
        (centre(&spot(tilt)).x - expected).abs() < 2e-3 * full,
        "{} vs {expected}",
        centre(&spot(tilt)).x
    );
    let sun = |degrees: f32| {
        let t = degrees.to_radians();
        floor_under(PunctualLight::Directional {
            direction: Vec3::new(t.sin(), -t.cos(), 0.0),
            irradiance: Vec3::splat(3.0),
        })
    };
    assert!((centre(&sun(0.0)).x - reflected(3.0)).abs() < 1e-3 * reflected(3.0));
    assert!((centre(&sun(60.0)).x - reflected(1.5)).abs() < 1e-3 * reflected(1.5));
}

#[test]
fn punctual_lights_cast_shadows_and_the_bsdf_integrator_is_warned() {
    let mut scene = floor_under(PunctualLight::Directional {
        direction: -Vec3::Y,
        irradiance: Vec3::splat(3.0),
    });
    let lit = centre(&scene).x;
    let blocker = scene
        .add_material(Material::Lambertian {
            albedo: Vec3::splat(0.5),
        })
        .unwrap();
    // A box beside the camera's narrow view, the sun tilted so that its shadow falls on
    // the middle of the floor.
    scene
        .add_cuboid(
            Vec3::new(3.0, 2.0, -1.0),
            Vec3::new(5.0, 3.0, 1.0),
            [0.0; 3],
            Vec3::ZERO,
            blocker,
        )
        .unwrap();
    let t = (4.0f32 / 2.5).atan();
    scene.lights[0] = PunctualLight::Directional {
        direction: Vec3::new(-t.sin(), -t.cos(), 0.0),
        irradiance: Vec3::splat(3.0),
    };
    assert!(lit > 0.0);
    assert_eq!(centre(&scene).x, 0.0, "in the box's shadow");
    scene.settings.integrator = Integrator::Bsdf;
    assert!(
        scene.warnings().iter().any(|w| w.contains("never finds")),
        "{:?}",
        scene.warnings()
    );
}

#[test]
fn bad_lights_are_refused() {
    let mut scene = Scene::default();
    let e = scene
        .add_light(PunctualLight::Spot {
            position: Vec3::ZERO,
            direction: -Vec3::Y,
            intensity: Vec3::ONE,
            cos_inner: 0.5,
            cos_outer: 0.9,
        })
        .unwrap_err();
    assert!(e.contains("outer cone must be wider"), "{e}");
    let e = scene
        .add_light(PunctualLight::Point {
            position: Vec3::ZERO,
            intensity: Vec3::new(1.0, f32::NAN, 1.0),
        })
        .unwrap_err();
    assert!(e.contains("finite"), "{e}");
    assert!(scene.lights.is_empty());
}
