//! A saved render, loaded to be continued.

use crate::{JobError, RenderJob};
use canopy_bvh::TriangleTest;
use canopy_render::checkpoint::Checkpoint;
use canopy_render::{Accumulator, Scene};
use std::path::{Path, PathBuf};

/// A checkpoint with the scene it was made from, loaded again and checked to be the same
/// scene (its fingerprint), with the checkpoint's settings.
pub struct Resumed {
    pub scene: Scene,
    /// How the checkpoint names the scene.
    pub source: String,
    pub accumulator: Accumulator,
    /// The checkpoint file.
    pub path: PathBuf,
    /// The render that wrote it (see [`RenderJob::resume_owner`]).
    pub owner: u64,
    /// How the render tested triangles: it goes on in the same mode.
    pub triangle_test: TriangleTest,
}

impl Resumed {
    /// Loads the checkpoint at `path` and the scene it names (whose own files may also
    /// lie in the folders `allowed`, as for [`canopy_render::load_scene_allowing`]).
    ///
    /// A checkpoint is a file anyone can craft: the scene it names must be a built-in
    /// scene or a file of a scene format (`.toml`, `.obj`, `.ply`, `.gltf`, `.glb`), and an
    /// error in loading it shows nothing of the file's text.
    pub fn load(path: &Path, allowed: &[PathBuf]) -> Result<Self, JobError> {
        let checkpoint = Checkpoint::load(path)?;
        let named = &checkpoint.scene;
        if !names_a_scene(named) {
            return Err(JobError::Invalid(format!(
                "{}: the checkpoint names `{named}` as its scene, which is neither a built-in scene nor a scene file (.toml, .obj, .ply, .gltf, .glb)",
                path.display()
            )));
        }
        let scene = canopy_render::load_scene_allowing(named, allowed)
            .map_err(|e| JobError::Scene(e.withholding_text()))?;
        Self::with_checkpoint(checkpoint, scene, path)
    }

    /// Loads the checkpoint at `path` to continue it on `scene` (one built in code, which
    /// a checkpoint cannot name), which must be the scene it was made from.
    pub fn load_for(path: &Path, scene: Scene) -> Result<Self, JobError> {
        Self::with_checkpoint(Checkpoint::load(path)?, scene, path)
    }

    fn with_checkpoint(
        checkpoint: Checkpoint,
        mut scene: Scene,
        path: &Path,
    ) -> Result<Self, JobError> {
        scene.settings = checkpoint.settings;
        checkpoint.matches(&scene, path)?;
        Ok(Self {
            scene,
            source: checkpoint.scene,
            accumulator: checkpoint.accumulator,
            path: path.to_owned(),
            owner: checkpoint.owner,
            triangle_test: checkpoint.triangle_test,
        })
    }

    /// The job that continues this render, saving to the same checkpoint (set
    /// `checkpoint.every` for periodic saves).
    pub fn job(&self) -> RenderJob<'_> {
        let mut job = RenderJob::new(&self.scene, self.source.clone());
        job.region = self.accumulator.region;
        job.aovs = self.accumulator.aovs.set;
        job.resume = Some(self.accumulator.clone());
        job.resume_owner = Some(self.owner);
        job.structure.triangle_test = self.triangle_test;
        job.checkpoint.periodic = Some(self.path.clone());
        job.checkpoint.on_interrupt = Some(self.path.clone());
        job
    }
}

/// Whether a checkpoint's scene is one canopy could have rendered: a built-in scene's
/// name, or a path with a scene file's extension.
fn names_a_scene(named: &str) -> bool {
    if canopy_render::BuiltinScene::find(named).is_some() {
        return true;
    }
    let extension = Path::new(named)
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    matches!(
        extension.as_deref(),
        Some("toml" | "obj" | "ply" | "gltf" | "glb")
    )
}
