//! canopy-render: scenes, shapes, materials, camera, the path tracing integrator and
//! image output. BVHs come from `canopy-bvh`.
//!
//! The data flows one way: scene file -> [`Scene`] -> [`Accel`] -> [`render`] ->
//! [`Film`] -> image file.

pub mod accel;
pub mod builtin;
pub mod camera;
pub mod error;
pub mod film;
pub mod geometry;
pub mod integrator;
pub mod material;
pub mod mesh;
pub mod output;
pub mod rng;
pub mod scene;
pub mod scene_file;

pub use accel::{Accel, AccelKind};
pub use builtin::{BuiltinScene, BUILTIN_SCENES};
pub use error::{OutputError, SceneError};
pub use film::Film;
pub use integrator::{render, RenderStats};
pub use output::write_image;
pub use scene::{Background, RenderSettings, Scene};

use scene_file::{parse_scene, DirAssets};
use std::path::Path;

/// Loads a scene file; its meshes are found relative to its directory.
pub fn load_scene_file(path: &Path) -> Result<Scene, SceneError> {
    let display = path.display().to_string();
    let source = std::fs::read_to_string(path).map_err(|cause| SceneError::Read {
        file: display.clone(),
        cause,
    })?;
    let dir = path.parent().unwrap_or(Path::new(".")).to_owned();
    parse_scene(&source, &display, &DirAssets(dir))
}

/// A built-in scene by name, else a scene file by path.
pub fn load_scene(name_or_path: &str) -> Result<Scene, SceneError> {
    if let Some(builtin) = BuiltinScene::find(name_or_path) {
        return builtin.load();
    }
    let path = Path::new(name_or_path);
    if path.exists() {
        load_scene_file(path)
    } else {
        Err(SceneError::Unknown(name_or_path.to_owned()))
    }
}
