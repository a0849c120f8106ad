//! canopy-render: scenes, shapes, materials, camera, the path tracing integrator and
//! image output. BVHs come from `canopy-bvh`.
//!
//! The data flows one way: scene file -> [`Scene`] -> [`Accel`] -> [`render`] ->
//! [`Film`] -> image file.

pub mod accel;
pub mod background;
pub mod builtin;
pub mod camera;
pub mod checkpoint;
pub mod error;
pub mod files;
pub mod film;
pub mod geometry;
pub mod integrator;
pub mod lights;
pub mod material;
pub mod mesh;
pub mod output;
pub mod region;
pub mod rng;
pub mod sampling;
pub mod scene;
pub mod scene_build;
pub mod scene_file;
pub mod visualize;

pub use accel::{clipper, Accel, AccelKind};
pub use background::{Background, EnvironmentMap};
pub use builtin::{BuiltinScene, BUILTIN_SCENES};
pub use canopy_bvh::{BvhWidth, RayQuery};
pub use error::{OutputError, SceneError};
pub use film::Film;
pub use integrator::{render, render_counted, render_samples, Accumulator, RenderStats};
pub use output::write_image;
pub use region::Region;
pub use scene::{Integrator, MeshInstance, RenderSettings, Scene, SceneMesh};

use scene_file::{parse_scene, DirAssets};
use std::path::Path;

/// Largest scene file read (a scene with a million inline spheres fits).
pub const MAX_SCENE_FILE_BYTES: u64 = 256 << 20;

/// Loads a scene file; its meshes are found relative to its directory.
pub fn load_scene_file(path: &Path) -> Result<Scene, SceneError> {
    let display = path.display().to_string();
    let read_error = |cause: files::ReadError| SceneError::Read {
        file: display.clone(),
        cause: cause.into(),
    };
    let bytes = files::read_regular_file(path, MAX_SCENE_FILE_BYTES).map_err(read_error)?;
    let source = String::from_utf8(bytes).map_err(|_| SceneError::Read {
        file: display.clone(),
        cause: std::io::Error::other("not a text (UTF-8) file"),
    })?;
    let dir = path.parent().unwrap_or(Path::new(".")).to_owned();
    let mut scene = parse_scene(&source, &display, &DirAssets(dir))?;
    scene.inputs.insert(0, path.to_owned());
    Ok(scene)
}

/// A built-in scene by name, else a scene file by path, else a bare OBJ or PLY mesh
/// (see [`scene_from_mesh`]).
pub fn load_scene(name_or_path: &str) -> Result<Scene, SceneError> {
    if let Some(builtin) = BuiltinScene::find(name_or_path) {
        return builtin.load();
    }
    let path = Path::new(name_or_path);
    if !path.exists() {
        return Err(SceneError::Unknown(name_or_path.to_owned()));
    }
    if mesh::MeshFormat::from_path(name_or_path).is_ok() {
        scene_from_mesh(path)
    } else {
        load_scene_file(path)
    }
}

/// A scene of one mesh file: grey, smooth-shaded where the file has normals, under the
/// sky, seen from the front. The mesh is stored once and placed by one instance.
pub fn scene_from_mesh(path: &Path) -> Result<Scene, SceneError> {
    let file = path
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default();
    let dir = path.parent().unwrap_or(Path::new(".")).to_owned();
    let source = format!(
        "name = {name:?}\n[camera]\nlook_from = [0, 0, 1]\nlook_at = [0, 0, 0]\n\
         [geometry.mesh]\nfile = {file:?}\n\
         [[instances]]\ngeometry = \"mesh\"\nmaterial = {{ type = \"lambertian\", albedo = [0.7, 0.7, 0.7] }}\n",
        name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
    );
    let mut scene = parse_scene(&source, &path.display().to_string(), &DirAssets(dir))?;
    debug_assert_eq!(scene.inputs.len(), 1, "the mesh is recorded as an input");
    // Frame the mesh: look at its centre from the front, a little above.
    let bounds = scene.bounds();
    let radius = 0.5 * bounds.extent().length();
    let centre = bounds.center();
    scene.camera.look_at = centre;
    scene.camera.vfov = 40.0;
    let distance = radius / (0.5 * scene.camera.vfov.to_radians()).tan() * 1.1;
    scene.camera.look_from = centre + distance * glam::Vec3::new(0.0, 0.3, 1.0).normalize();
    Ok(scene)
}

/// How a checkpoint names a scene so that it can be found again from any directory: a
/// built-in scene by its name, a file by its absolute path.
pub fn scene_source(name_or_path: &str) -> Result<String, SceneError> {
    if BuiltinScene::find(name_or_path).is_some() {
        return Ok(name_or_path.to_owned());
    }
    let read_error = |cause| SceneError::Read {
        file: name_or_path.to_owned(),
        cause,
    };
    let absolute = std::fs::canonicalize(name_or_path).map_err(read_error)?;
    absolute.to_str().map(str::to_owned).ok_or_else(|| {
        read_error(std::io::Error::other(
            "the path is not valid UTF-8, which a checkpoint cannot store",
        ))
    })
}
