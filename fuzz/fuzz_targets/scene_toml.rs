//! The TOML scene reader: any text is a scene or an error, never a panic or a hang.
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
            // What the reader accepts, the renderer must be able to use.
            assert!(scene.settings.check().is_ok());
            for b in scene.primitive_bounds() {
                assert!(b.min.is_finite() && b.max.is_finite());
            }
        }
    }
});
