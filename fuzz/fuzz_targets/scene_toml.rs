//! The whole pipeline from TOML: any text is a scene or an error, never a panic or a hang,
//! and a scene the validation accepts builds and renders.
#![no_main]

use canopy_render::scene_file::{parse_scene, Assets};
use libfuzzer_sys::fuzz_target;

/// Every mesh a scene names is this small triangle, so mesh transforms are exercised.
struct OneTriangle;

impl Assets for OneTriangle {
    fn read(&self, _path: &str) -> Result<Vec<u8>, String> {
        Ok(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".to_vec())
    }
}

fuzz_target!(|data: &[u8]| {
    if let Ok(source) = std::str::from_utf8(data) {
        if let Ok(scene) = parse_scene(source, "fuzz.toml", &OneTriangle) {
            // What the reader and the scene's validation (`canopy check`) accept, the
            // renderer must build and render: one sample of an 8x8 image.
            if scene.validate().is_ok() {
                render_one_sample(scene);
            }
        }
    }
});

fn render_one_sample(mut scene: canopy_render::Scene) {
    scene.settings.width = 8;
    scene.settings.height = 8;
    scene.settings.spp = 1;
    scene.settings.max_depth = 3;
    let accel = canopy_render::Accel::for_scene(
        &scene,
        canopy_render::AccelKind::default(),
        canopy_render::BvhWidth::Four,
        &Default::default(),
        None,
    );
    let (film, _) = canopy_render::render(&scene, &accel, &|| {});
    assert_eq!(film.pixels.len(), 64);
}
