//! A saved render, loaded to be continued.

use crate::{JobError, RenderJob};
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
}

impl Resumed {
    /// Loads the checkpoint at `path` and the scene it names.
    pub fn load(path: &Path) -> Result<Self, JobError> {
        let checkpoint = Checkpoint::load(path)?;
        let scene = canopy_render::load_scene(&checkpoint.scene)?;
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
        })
    }

    /// The job that continues this render, saving to the same checkpoint (set
    /// `checkpoint.every` for periodic saves).
    pub fn job(&self) -> RenderJob<'_> {
        let mut job = RenderJob::new(&self.scene, self.source.clone());
        job.region = self.accumulator.region;
        job.resume = Some(self.accumulator.clone());
        job.resume_owner = Some(self.owner);
        job.checkpoint.periodic = Some(self.path.clone());
        job.checkpoint.on_interrupt = Some(self.path.clone());
        job
    }
}
