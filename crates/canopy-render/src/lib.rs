//! canopy-render: scenes, shapes, materials, camera, the path tracing integrator and
//! image output. BVHs come from `canopy-bvh`.
//!
//! The data flows one way: scene file -> [`Scene`] -> [`Accel`] -> [`render`] ->
//! [`Film`] -> image file.

pub mod accel;
pub mod aov;
pub mod background;
pub mod builtin;
pub mod camera;
pub mod checkpoint;
pub mod error;
pub mod exr_layers;
pub mod files;
pub mod film;
pub mod geometry;
pub mod gltf_scene;
pub mod integrator;
pub mod lights;
pub mod material;
pub mod mesh;
pub mod output;
pub mod output_policy;
pub mod region;
pub mod rng;
pub mod sampling;
pub mod scene;
pub mod scene_build;
pub mod scene_file;
pub mod texture;
pub mod visualize;

pub use accel::{clipper, Accel, AccelKind};
pub use aov::{Aov, AovBuffers, AovSet};
pub use background::{Background, EnvironmentMap};
pub use builtin::{BuiltinScene, BUILTIN_SCENES};
pub use canopy_bvh::{BvhWidth, RayQuery};
pub use error::{OutputError, SceneError};
pub use film::Film;
pub use integrator::{
    render, render_aov_samples, render_counted, render_samples, render_samples_abandonable,
    render_samples_with, Accumulator, RenderStats, Schedule,
};
pub use output::{write_image, write_image_with_aovs};
pub use region::Region;
pub use rng::Sampler;
pub use scene::{Integrator, MeshInstance, RenderSettings, Scene, SceneMesh};

use scene_file::{parse_scene, DirAssets};
use std::path::{Path, PathBuf};

/// Largest scene file read (a scene with a million inline spheres fits).
pub const MAX_SCENE_FILE_BYTES: u64 = 256 << 20;

/// Peak bytes of memory parsing a scene file takes per byte of it, generously: the TOML
/// document with every value and span (measured: 3M inline spheres, 130 MB of text,
/// peak 7.1 GB, about 56 bytes a byte), then the scene built from it.
pub const PARSE_BYTES_PER_FILE_BYTE: u64 = 64;

/// Why a scene file of `size` bytes is not parsed: more memory than `available` (when
/// known) would be needed. Checked before the file is read.
pub fn check_parse_memory(size: u64, available: Option<u64>) -> Result<(), String> {
    files::check_memory(
        size.saturating_mul(PARSE_BYTES_PER_FILE_BYTE),
        available,
        &format!("parsing a scene file of {} MiB", size >> 20),
    )
}

/// Loads a scene file; its meshes are found relative to its directory, and only there
/// or in the folders of `allowed` (see [`DirAssets`]). Its size is checked against the
/// memory parsing it needs before it is read.
pub fn load_scene_file(path: &Path, allowed: &[PathBuf]) -> Result<Scene, SceneError> {
    let display = path.display().to_string();
    let read_error = |cause: files::ReadError| SceneError::Read {
        file: display.clone(),
        cause: cause.into(),
    };
    let size = files::regular_file_size(path).map_err(read_error)?;
    check_parse_memory(size, files::available_memory()).map_err(|message| SceneError::Read {
        file: display.clone(),
        cause: std::io::Error::other(message),
    })?;
    let bytes = files::read_regular_file(path, MAX_SCENE_FILE_BYTES).map_err(read_error)?;
    let source = String::from_utf8(bytes).map_err(|_| SceneError::Read {
        file: display.clone(),
        cause: std::io::Error::other("not a text (UTF-8) file"),
    })?;
    let (assets, _) = DirAssets::beside(path);
    let assets = assets.allowing(allowed).map_err(SceneError::Usage)?;
    let mut scene = parse_scene(&source, &display, &assets)?;
    scene.inputs.insert(0, path.to_owned());
    Ok(scene)
}

/// A built-in scene by name, else a file by path: a glTF model ([`scene_from_gltf`]), a
/// bare OBJ or PLY mesh ([`scene_from_mesh`]), or a scene file. The files it names are
/// read from its own folder only ([`load_scene_allowing`] allows more).
pub fn load_scene(name_or_path: &str) -> Result<Scene, SceneError> {
    load_scene_allowing(name_or_path, &[])
}

/// [`load_scene`], where the files a scene names may also lie in the folders `allowed`.
pub fn load_scene_allowing(name_or_path: &str, allowed: &[PathBuf]) -> Result<Scene, SceneError> {
    let scene = if let Some(builtin) = BuiltinScene::find(name_or_path) {
        builtin.load()?
    } else {
        let path = Path::new(name_or_path);
        if !path.exists() {
            return Err(SceneError::Unknown(name_or_path.to_owned()));
        }
        if is_gltf(path) {
            scene_from_gltf(path, allowed)?
        } else if mesh::MeshFormat::from_path(name_or_path).is_ok() {
            scene_from_mesh(path)?
        } else {
            load_scene_file(path, allowed)?
        }
    };
    // What the loaders built is checked once more as a whole, by the check the render
    // job makes: a scene `canopy check` accepts is one the renderer can use.
    scene.validate().map_err(|message| SceneError::Model {
        file: name_or_path.to_owned(),
        message,
    })?;
    Ok(scene)
}

/// A scene of one mesh file: grey, smooth-shaded where the file has normals, under the
/// sky, seen from the front. The mesh is stored once and placed by one instance. Errors
/// name the mesh file (and its line or element), and a mesh with no triangle of any
/// area is refused: there would be nothing to render and nothing to frame.
pub fn scene_from_mesh(path: &Path) -> Result<Scene, SceneError> {
    let display = path.display().to_string();
    let fail = |cause: mesh::MeshError| SceneError::MeshFile {
        file: display.clone(),
        cause,
    };
    let invalid = |message: String| fail(mesh::MeshError::Invalid(message));
    let format = mesh::MeshFormat::from_path(&path.to_string_lossy()).map_err(fail)?;
    let bytes = scene_file::read_input_file(path).map_err(invalid)?;
    let data = mesh::parse_mesh(&bytes, format).map_err(fail)?;
    drop(bytes);
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut scene = Scene {
        name: stem,
        inputs: vec![path.to_owned()],
        ..Scene::default()
    };
    let grey = scene
        .add_material(material::Material::Lambertian {
            albedo: glam::Vec3::splat(0.7),
        })
        .map_err(invalid)?;
    let mesh = scene
        .add_mesh("mesh", data.positions, data.triangles, data.normals, false)
        .map_err(invalid)?;
    if scene.meshes[mesh as usize].mesh.indices().is_empty() {
        return Err(invalid(format!(
            "no triangle with any area ({} left out as zero-area): nothing to render",
            scene.skipped_degenerate
        )));
    }
    scene
        .add_instance(mesh, glam::Affine3A::IDENTITY, grey)
        .map_err(invalid)?;
    frame_from_front(&mut scene).map_err(|e| invalid(format!("cannot frame the mesh: {e}")))?;
    Ok(scene)
}

/// Points the camera at the whole scene: at its centre, from the front and a little
/// above, far enough back for a 40° field of view to hold it.
pub(crate) fn frame_from_front(scene: &mut Scene) -> Result<(), String> {
    let bounds = scene.bounds();
    let radius = 0.5 * bounds.extent().length();
    let centre = bounds.center();
    scene.camera.look_at = centre;
    scene.camera.vfov = 40.0;
    let distance = radius / (0.5 * scene.camera.vfov.to_radians()).tan() * 1.1;
    scene.camera.look_from = centre + distance * glam::Vec3::new(0.0, 0.3, 1.0).normalize();
    scene.camera.check()
}

/// A scene from a glTF 2.0 file (`.glb`, or `.gltf` with its buffers beside it or in
/// data URIs): see [`gltf_scene`]. Errors name the file and the object at fault.
pub fn scene_from_gltf(path: &Path, allowed: &[PathBuf]) -> Result<Scene, SceneError> {
    let display = path.display().to_string();
    let fail = |message: String| SceneError::Model {
        file: display.clone(),
        message,
    };
    let (assets, _) = DirAssets::beside(path);
    let assets = assets.allowing(allowed).map_err(SceneError::Usage)?;
    let bytes = scene_file::read_input_file(path).map_err(fail)?;
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut scene = gltf_scene::parse_gltf(&bytes, &assets, &stem).map_err(fail)?;
    scene.inputs.insert(0, path.to_owned());
    Ok(scene)
}

/// Whether `path` names a glTF file, by its extension.
pub fn is_gltf(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("glb") || e.eq_ignore_ascii_case("gltf"))
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

#[cfg(test)]
mod tests {
    /// A scene file is refused before it is read when parsing it would take more memory
    /// than is available: 130 MB of inline spheres took 7.1 GB.
    #[test]
    fn scene_files_too_large_to_parse_are_refused_before_reading() {
        let mib = 1u64 << 20;
        assert!(super::check_parse_memory(130 * mib, None).is_ok());
        assert!(super::check_parse_memory(130 * mib, Some(16 << 30)).is_ok());
        let e = super::check_parse_memory(130 * mib, Some(4 << 30)).unwrap_err();
        assert!(
            e.contains("parsing a scene file of 130 MiB needs about 8320 MiB of memory"),
            "{e}"
        );
    }
}
