//! Whole glTF models placed in a scene file, each by one transform, with their own
//! meshes, materials and node hierarchy ([`crate::gltf_scene`]); the scene file's camera
//! and background stay.
//!
//! ```toml
//! [[gltf]]
//! file = "CesiumMilkTruck.glb"
//! scale = 2.0
//! rotate = [0, 90, 0]
//! translate = [0, 0, -3]
//! ```

use super::{checked_scale, rotation, Assets, ScaleDoc, SceneBuilder};
use crate::error::SceneError;
use glam::Affine3A;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use toml::Spanned;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct GltfDoc {
    file: String,
    scale: Option<ScaleDoc>,
    #[serde(default)]
    rotate: [f32; 3],
    #[serde(default)]
    translate: [f32; 3],
}

/// Files relative to a model's own directory (its buffers), read through the scene's
/// assets.
struct BesideModel<'a> {
    assets: &'a dyn Assets,
    dir: PathBuf,
}

impl BesideModel<'_> {
    fn path(&self, path: &str) -> String {
        self.dir.join(path).to_string_lossy().into_owned()
    }
}

impl Assets for BesideModel<'_> {
    fn read(&self, path: &str) -> Result<Vec<u8>, String> {
        self.assets.read(&self.path(path))
    }

    fn locate(&self, path: &str) -> Option<PathBuf> {
        self.assets.locate(&self.path(path))
    }
}

impl SceneBuilder<'_> {
    /// A glTF model placed by its entry's transform.
    pub(super) fn gltf(
        &mut self,
        doc: &Spanned<GltfDoc>,
        assets: &dyn Assets,
    ) -> Result<(), SceneError> {
        let g = doc.get_ref();
        let fail = |message: String| {
            self.cx
                .invalid::<()>(doc.span(), format!("gltf `{}`: {message}", g.file))
        };
        let Some(scale) = checked_scale(&g.scale, g.rotate, g.translate) else {
            return fail("transform numbers must be finite and `scale` non-zero".into());
        };
        let to_world = Affine3A::from_scale_rotation_translation(
            scale,
            rotation(g.rotate),
            g.translate.into(),
        );
        let bytes = match assets.read(&g.file) {
            Ok(bytes) => bytes,
            Err(e) => return fail(e),
        };
        self.scene.inputs.extend(assets.locate(&g.file));
        let beside = BesideModel {
            assets,
            dir: Path::new(&g.file)
                .parent()
                .unwrap_or(Path::new(""))
                .to_owned(),
        };
        match crate::gltf_scene::add_gltf(&mut self.scene, &bytes, &beside, to_world) {
            Ok(_camera) => Ok(()), // the scene file's camera stays
            Err(e) => fail(e),
        }
    }
}
