//! Built-in scenes, reachable by name. Each is the scene file under `scenes/` of the
//! repository, embedded in the binary with the meshes it uses.

use crate::error::SceneError;
use crate::scene::Scene;
use crate::scene_file::{parse_scene, Assets};

/// A scene shipped with canopy.
pub struct BuiltinScene {
    pub name: &'static str,
    source: &'static str,
}

macro_rules! scene {
    ($name:literal) => {
        BuiltinScene {
            name: $name,
            source: include_str!(concat!("../../../scenes/", $name, ".toml")),
        }
    };
}

/// Every built-in scene, in the order `canopy scenes` lists them.
pub const BUILTIN_SCENES: &[BuiltinScene] = &[
    scene!("paper-1"),
    scene!("paper-2"),
    scene!("paper-3"),
    scene!("paper-4"),
    scene!("paper-5"),
    scene!("paper-6"),
    scene!("rtiow-final"),
    scene!("cornell"),
    scene!("teapots"),
];

/// Mesh files the built-in scenes reference, by the path the scene files use.
const EMBEDDED_MESHES: &[(&str, &[u8])] = &[(
    "meshes/teapot.obj",
    include_bytes!("../../../scenes/meshes/teapot.obj"),
)];

struct EmbeddedAssets;

impl Assets for EmbeddedAssets {
    fn read(&self, path: &str) -> Result<Vec<u8>, String> {
        EMBEDDED_MESHES
            .iter()
            .find(|(name, _)| *name == path)
            .map(|(_, bytes)| bytes.to_vec())
            .ok_or_else(|| format!("`{path}` is not embedded with the built-in scenes"))
    }
}

impl BuiltinScene {
    pub fn find(name: &str) -> Option<&'static BuiltinScene> {
        BUILTIN_SCENES.iter().find(|s| s.name == name)
    }

    /// The scene file's text, as under `scenes/`.
    pub fn source(&self) -> &'static str {
        self.source
    }

    pub fn load(&self) -> Result<Scene, SceneError> {
        parse_scene(
            self.source,
            &format!("<built-in {}>", self.name),
            &EmbeddedAssets,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_scene_loads_and_is_named_after_itself() {
        for builtin in BUILTIN_SCENES {
            let scene = builtin
                .load()
                .unwrap_or_else(|e| panic!("{}: {e}", builtin.name));
            assert_eq!(scene.name, builtin.name);
            assert!(
                !scene.description.is_empty(),
                "{} has no description",
                builtin.name
            );
            assert!(!scene.primitives.is_empty());
        }
    }

    #[test]
    fn paper_scenes_match_the_report() {
        // Section 4.1: 480x480, 4 bounces, 128 samples; spheres-only, mesh-only, both.
        for name in [
            "paper-1", "paper-2", "paper-3", "paper-4", "paper-5", "paper-6",
        ] {
            let scene = BuiltinScene::find(name).unwrap().load().unwrap();
            let s = scene.settings;
            assert_eq!(
                (s.width, s.height, s.spp, s.max_depth),
                (480, 480, 128, 4),
                "{name}"
            );
            let counts = scene.shape_counts();
            let (spheres, triangles) = (counts.spheres, counts.triangles);
            match name {
                "paper-1" | "paper-2" => assert!((480..=500).contains(&spheres) && triangles == 0),
                "paper-3" | "paper-4" => assert!(spheres == 3 && (900..1100).contains(&triangles)),
                _ => assert!((480..=500).contains(&spheres) && (900..1100).contains(&triangles)),
            }
        }
    }
}
