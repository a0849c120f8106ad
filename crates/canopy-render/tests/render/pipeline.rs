//! What `canopy check` accepts, `canopy render` renders: scenes made of hostile numbers
//! (zero, tiny, denormal, huge and out-of-range values in every transform, shape, camera
//! and material) go through the whole pipeline — parse, the scene's one validation (the
//! check `canopy check`, `load_scene` and every render job make), BVH build and one
//! sample of an 8x8 image — and none that the validation accepts panics later.
//!
//! `CANOPY_FUZZ_CASES=100000 cargo test --release -p canopy-render --test render pipeline`
//! runs more cases than CI does.

use canopy_bvh::BuildParams;
use canopy_render::scene_file::{parse_scene, Assets};
use canopy_render::{render, Accel, AccelKind, BvhWidth, Scene};
use proptest::prelude::*;
use proptest::strategy::ValueTree;

/// Every mesh a scene names is this tetrahedron.
struct Tetrahedron;

impl Assets for Tetrahedron {
    fn read(&self, _path: &str) -> Result<Vec<u8>, String> {
        Ok(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n".to_vec())
    }
}

/// Numbers that have broken renderers: zeros, a scale whose determinant underflows,
/// denormals, values at and past canopy's coordinate limit, and ordinary ones.
const HOSTILE: [&str; 16] = [
    "0", "-0.0", "1e-13", "-1e-13", "1e-30", "1e-45", "1e-7", "0.5", "1", "-1", "2.5", "90",
    "1e12", "1.1e12", "1e30", "3.4e38",
];

/// `sane` most of the time, a hostile number otherwise: most scenes then get past the
/// parser with one or two hostile values, which is where a check can be missing.
fn number(sane: &'static str) -> impl Strategy<Value = &'static str> {
    prop_oneof![6 => Just(sane), 1 => prop::sample::select(&HOSTILE[..])]
}

fn triple(sane: [&'static str; 3]) -> impl Strategy<Value = String> {
    (number(sane[0]), number(sane[1]), number(sane[2]))
        .prop_map(|(a, b, c)| format!("[{a}, {b}, {c}]"))
}

/// A scene of every kind of object, each number sane or drawn from [`HOSTILE`].
fn scene_text() -> impl Strategy<Value = String> {
    let camera = (
        triple(["0", "1", "6"]),
        triple(["0", "0", "0"]),
        number("40"),
        number("0"),
    );
    let shapes = (
        triple(["1", "0", "0"]),
        number("0.5"),
        triple(["-1", "-1", "-1"]),
        triple(["0", "0.5", "0"]),
        triple(["0", "30", "0"]),
    );
    let placement = (
        number("0.5"),
        triple(["1", "2.5", "-1"]),
        triple(["0", "90", "0"]),
        triple(["0", "1", "0"]),
        triple(["1", "0", "0"]),
    );
    let material = (
        triple(["0.5", "0.5", "0.5"]),
        number("0.5"),
        number("1.5"),
        triple(["1", "1", "1"]),
    );
    (camera, shapes, placement, material).prop_map(
        |(
            (from, at, vfov, aperture),
            (center, radius, min, max, turn),
            (scale, axes, rotate, translate, step),
            (albedo, fuzz, ior, radiance),
        )| {
            format!(
                r#"
[camera]
look_from = {from}
look_at = {at}
vfov = {vfov}
aperture = {aperture}

[materials.a]
type = "metal"
albedo = {albedo}
fuzz = {fuzz}

[materials.glass]
type = "dielectric"
ior = {ior}

[materials.lamp]
type = "emissive"
radiance = {radiance}

[[spheres]]
center = {center}
radius = {radius}
material = "a"

[[cuboids]]
min = {min}
max = {max}
rotate = {turn}
material = "glass"

[[meshes]]
file = "t.obj"
material = "lamp"
scale = {scale}
rotate = {rotate}
translate = {translate}

[geometry.t]
file = "t.obj"

[[instances]]
geometry = "t"
material = "a"
scale = {axes}
translate = {translate}
grid = {{ count = [2, 1, 1], step = {step} }}
"#
            )
        },
    )
}

/// The rest of the pipeline for a scene the validation accepted: build, then render one
/// sample of an 8x8 image.
fn build_and_render(mut scene: Scene) {
    scene.settings.width = 8;
    scene.settings.height = 8;
    scene.settings.spp = 1;
    scene.settings.max_depth = 3;
    let accel = Accel::for_scene(
        &scene,
        AccelKind::default(),
        BvhWidth::Four,
        &BuildParams::default(),
        None,
    );
    let (film, _) = render(&scene, &accel, &|| {});
    assert_eq!(film.pixels.len(), 64);
}

fn cases() -> u32 {
    std::env::var("CANOPY_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(300)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    #[test]
    fn a_scene_the_check_accepts_builds_and_renders(text in scene_text()) {
        if let Ok(scene) = parse_scene(&text, "hostile.toml", &Tetrahedron) {
            if scene.validate().is_ok() {
                build_and_render(scene);
            }
        }
    }
}

/// Enough generated scenes pass the validation to exercise the renderer, and enough
/// fail it to exercise the checks.
#[test]
fn the_hostile_scenes_reach_the_renderer() {
    let mut runner = proptest::test_runner::TestRunner::deterministic();
    let (mut accepted, mut refused) = (0, 0);
    for _ in 0..200 {
        let text = scene_text().new_tree(&mut runner).unwrap().current();
        match parse_scene(&text, "hostile.toml", &Tetrahedron).map(|s| s.validate()) {
            Ok(Ok(())) => accepted += 1,
            _ => refused += 1,
        }
    }
    eprintln!("{accepted} accepted, {refused} refused");
    assert!(
        accepted >= 20 && refused >= 20,
        "{accepted} accepted, {refused} refused"
    );
}

/// The case that reached the renderer: an instance scaled by 1e-13 passed `check` and
/// then panicked building the top-level tree ("Singular"). Now the scene file's own
/// check names its line, and the scene's validation refuses the same placement made by
/// changing the scene directly.
#[test]
fn a_tiny_instance_scale_is_refused_with_its_line() {
    let text = "[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n\n[geometry.t]\nfile = \"t.obj\"\n\n\
[[instances]]\ngeometry = \"t\"\nmaterial = { type = \"lambertian\", albedo = [0.5, 0.5, 0.5] }\nscale = 1e-13\n";
    let e = parse_scene(text, "tiny.toml", &Tetrahedron)
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("tiny.toml:8:"), "{e}");
    assert!(e.contains("not invertible"), "{e}");

    let mut scene = parse_scene(&text.replace("1e-13", "1"), "ok.toml", &Tetrahedron).unwrap();
    scene.validate().unwrap();
    scene.instances[0].to_world = glam::Affine3A::from_scale(glam::Vec3::splat(1e-13));
    let e = scene.validate().unwrap_err();
    assert!(e.starts_with("instance 0 of mesh `t`"), "{e}");
}
