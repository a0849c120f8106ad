//! canopy-job: one render, owned in one place. The command line, the Python bindings and
//! distributed rendering all describe a render as a [`RenderJob`] — the scene, the
//! acceleration structure, the device (CPU or GPU), the region of the image, the
//! checkpoint policy — and run it with an [`Observer`] that sees its progress and may
//! cancel it between passes.
//!
//! A render adds one sample per pixel per pass, in sample order, so an interrupted,
//! checkpointed and resumed render gives the uninterrupted render's image bit for bit,
//! and a region gives exactly those pixels of the whole image.
//!
//! ```no_run
//! # fn main() -> Result<(), canopy_job::JobError> {
//! let scene = canopy_render::load_scene("paper-3").unwrap();
//! let job = canopy_job::RenderJob::new(&scene, "paper-3");
//! let outcome = job.prepare()?.run(&mut ())?;
//! let film = outcome.accumulator.film();
//! # Ok(()) }
//! ```

mod denoise;
mod engine;
mod observer;
mod options;
mod prepared;
mod resume;

pub use canopy_denoise::{DenoiseError, Oidn, Options as DenoiseOptions};
pub use denoise::denoise_film;
pub use observer::Observer;
pub use options::{RenderOptions, MAX_LEAF_SIZE};
pub use prepared::{Outcome, Prepared, AOV_BYTES_PER_PIXEL, BYTES_PER_PIXEL, MAX_THREADS};
pub use resume::Resumed;

use canopy_bvh::{BuildParams, OptimizeBudget, TriangleTest};
use canopy_render::checkpoint::CheckpointError;
pub use canopy_render::Schedule;
use canopy_render::{AccelKind, Accumulator, AovSet, BvhWidth, Region, Scene};
use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;
use std::time::Duration;
use thiserror::Error;

/// Where a render runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Device {
    /// All cores (or the job's thread count).
    #[default]
    Cpu,
    /// The first adapter wgpu finds, walking the binary tree of the chosen builder: the
    /// CPU's image up to rounding.
    Gpu,
}

impl Device {
    pub const ALL: [Device; 2] = [Device::Cpu, Device::Gpu];

    pub fn name(self) -> &'static str {
        match self {
            Device::Cpu => "cpu",
            Device::Gpu => "gpu",
        }
    }
}

impl fmt::Display for Device {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Device {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Device::ALL
            .into_iter()
            .find(|d| d.name() == s)
            .ok_or_else(|| format!("device must be \"cpu\" or \"gpu\", not {s:?}"))
    }
}

/// The acceleration structure a render traces.
#[derive(Clone, Debug)]
pub struct Structure {
    /// `none` (a loop over all primitives) or a BVH builder.
    pub kind: AccelKind,
    /// Children per node on the CPU (the GPU always walks the binary tree).
    pub width: BvhWidth,
    pub params: BuildParams,
    /// Improve the tree by reinsertion before rendering.
    pub optimize: Option<OptimizeBudget>,
    /// How triangles are tested on the CPU (the GPU's kernels are watertight).
    pub triangle_test: TriangleTest,
}

impl Default for Structure {
    fn default() -> Self {
        Self {
            kind: AccelKind::Bvh(canopy_bvh::Builder::default()),
            width: BvhWidth::default(),
            params: BuildParams::default(),
            optimize: None,
            triangle_test: TriangleTest::Watertight,
        }
    }
}

/// When and where a render saves its state.
#[derive(Clone, Debug, Default)]
pub struct CheckpointPolicy {
    /// Saved every [`every`](Self::every) while rendering, and removed once the render
    /// is complete.
    pub periodic: Option<PathBuf>,
    pub every: Duration,
    /// Where a render cancelled before its last pass saves its state; nowhere if `None`
    /// (the samples so far are still in the [`Outcome`]).
    pub on_interrupt: Option<PathBuf>,
}

/// One render: what to render, through which structure, where, which pixels, and how its
/// work is kept.
#[derive(Clone, Debug)]
pub struct RenderJob<'s> {
    /// The scene, with the settings (size, spp, seed, integrator) to render it with.
    pub scene: &'s Scene,
    /// How a checkpoint names the scene to find it again: a built-in name or an
    /// absolute path (see [`canopy_render::scene_source`]).
    pub source: String,
    pub structure: Structure,
    pub device: Device,
    /// The order CPU workers trace paths in (the image is the same in each).
    pub schedule: Schedule,
    /// Worker threads on the CPU; `None` is the current rayon pool (all cores).
    pub threads: Option<usize>,
    /// The pixels to render; the whole image by default.
    pub region: Region,
    /// The AOV layers to accumulate with the samples (none by default); a resumed
    /// render's must be the same.
    pub aovs: AovSet,
    pub checkpoint: CheckpointPolicy,
    /// Samples already rendered (a checkpoint's), to continue from; its region replaces
    /// [`region`](Self::region).
    pub resume: Option<Accumulator>,
    /// The owner of the checkpoint [`resume`](Self::resume) came from
    /// ([`Checkpoint::owner`](canopy_render::checkpoint::Checkpoint::owner)): this render
    /// continues it, so it may replace and remove that checkpoint. Any other render's
    /// checkpoint is never replaced or removed.
    pub resume_owner: Option<u64>,
}

impl<'s> RenderJob<'s> {
    /// The whole image of `scene` on the CPU through the default structure, no
    /// checkpoints.
    pub fn new(scene: &'s Scene, source: impl Into<String>) -> Self {
        let s = scene.settings;
        Self {
            scene,
            source: source.into(),
            structure: Structure::default(),
            device: Device::Cpu,
            schedule: Schedule::default(),
            threads: None,
            region: Region::full(s.width, s.height),
            aovs: AovSet::NONE,
            checkpoint: CheckpointPolicy::default(),
            resume: None,
            resume_owner: None,
        }
    }

    /// The region this job renders: the resumed samples' region, else its own.
    pub fn region(&self) -> Region {
        self.resume.as_ref().map_or(self.region, |a| a.region)
    }
}

/// Why a render could not start or go on.
#[derive(Debug, Error)]
pub enum JobError {
    /// The job's own settings contradict each other or the scene.
    #[error("{0}")]
    Invalid(String),
    #[error("cannot start {threads} worker threads: {cause}")]
    Threads { threads: usize, cause: String },
    #[error(transparent)]
    Gpu(#[from] canopy_gpu::GpuError),
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error(transparent)]
    Scene(#[from] canopy_render::SceneError),
}
