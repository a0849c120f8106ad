//! glTF 2.0 models (`.glb` and JSON `.gltf`): any bytes are a scene or an error, never a
//! panic, a read past a buffer or an allocation the file's own bytes cannot back; an
//! accepted scene places meshes whose triangles name their own vertices.
#![no_main]

use canopy_render::gltf_scene::parse_gltf;
use canopy_render::scene_file::Assets;
use libfuzzer_sys::fuzz_target;

/// External buffers do not exist here: only the GLB's chunk and data URIs are read.
struct NoFiles;

impl Assets for NoFiles {
    fn read(&self, path: &str) -> Result<Vec<u8>, String> {
        Err(format!("{path}: no files while fuzzing"))
    }
}

fuzz_target!(|data: &[u8]| {
    if let Ok(scene) = parse_gltf(data, &NoFiles, "fuzz") {
        assert!(!scene.instances.is_empty());
        for mesh in &scene.meshes {
            let count = mesh.mesh.vertices().len();
            assert!(mesh.mesh.indices().iter().flatten().all(|&i| (i as usize) < count));
        }
    }
});
