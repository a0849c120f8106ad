//! A job made ready to run (structure built, device opened), and the run itself: passes,
//! periodic checkpoints, cancellation, the checkpoint of an interrupted render.

use crate::engine::Engine;
use crate::observer::Observer;
use crate::{Device, JobError, RenderJob};
use canopy_bvh::TriangleTest;
use canopy_render::checkpoint::{Checkpoint, CheckpointError};
use canopy_render::{Accel, AccelKind, Accumulator, BvhWidth, RenderStats};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Most worker threads a job may ask for.
pub const MAX_THREADS: usize = 1024;

/// Peak bytes per pixel of a render: the sums, the film, a checkpoint's copy and the
/// encoded image.
pub const BYTES_PER_PIXEL: u64 = 64;

/// Peak bytes per pixel that AOV layers add, at most: the layers, their images and the
/// encoded file's copy.
pub const AOV_BYTES_PER_PIXEL: u64 = 3 * 48;

/// A job with its acceleration structure built and its device open.
pub struct Prepared<'j> {
    job: &'j RenderJob<'j>,
    /// Whose checkpoints this render may replace and remove: its own identity (random),
    /// then the resumed checkpoint's owner.
    owners: Vec<u64>,
    pool: Option<rayon::ThreadPool>,
    accel: Arc<Accel>,
    gpu: Option<GpuUse<'j>>,
}

/// The GPU a job renders on.
enum GpuUse<'j> {
    /// Opened for this job: the scene is uploaded when it runs.
    Opened(Box<canopy_gpu::Gpu>),
    /// The caller's, the scene uploaded and kept across jobs.
    Kept(&'j canopy_gpu::Renderer<'j>),
}

/// What a run produced.
#[derive(Debug)]
pub struct Outcome {
    /// Every sample of the region so far: the resumed ones and this run's.
    pub accumulator: Accumulator,
    /// Rays and time of this run (not of the resumed runs before it).
    pub stats: RenderStats,
    /// Whether every sample asked for is in; false when the observer stopped the render.
    pub complete: bool,
    /// Where an incomplete render's state was saved (the policy's `on_interrupt`);
    /// `None` when it was not asked for, could not be saved (the observer was warned), or
    /// there was nothing to save (stopped before the first sample).
    pub saved: Option<PathBuf>,
}

impl<'s> RenderJob<'s> {
    /// Checks the job, starts its threads, opens its device and builds its acceleration
    /// structure.
    pub fn prepare(&self) -> Result<Prepared<'_>, JobError> {
        self.prepare_inner(None, None)
    }

    /// [`prepare`](Self::prepare), tracing through `accel` instead of building one: the
    /// structure an earlier job over the same scene built (a viewer renders many jobs
    /// over one scene as its camera moves, through the one structure). It must hold
    /// this scene's own primitives (the same shared array) and one instance per mesh
    /// instance, else the job is refused. On the GPU, it must be binary.
    pub fn prepare_with(&self, accel: Arc<Accel>) -> Result<Prepared<'_>, JobError> {
        self.check_given(&accel)?;
        self.prepare_inner(Some(accel), None)
    }

    /// [`prepare_with`](Self::prepare_with) on the GPU, rendering through `renderer`:
    /// this scene's geometry, materials and lights uploaded with `accel`'s structures
    /// (by [`canopy_gpu::Renderer::for_accel`]), kept by the caller across jobs whose
    /// camera and settings differ (a viewer's, as its camera moves). Each pass renders
    /// the job's scene's camera and settings on it. Refused for a job not on the GPU
    /// and for another integrator than the upload's.
    pub fn prepare_on<'j>(
        &'j self,
        accel: Arc<Accel>,
        renderer: &'j canopy_gpu::Renderer<'j>,
    ) -> Result<Prepared<'j>, JobError> {
        if self.device != Device::Gpu {
            return Err(JobError::Invalid(
                "a GPU renderer was given to a job on the CPU".into(),
            ));
        }
        let integrator = self.scene.settings.integrator;
        if renderer.integrator() != integrator {
            return Err(JobError::Invalid(format!(
                "the GPU renderer given renders the `{}` integrator, not the `{}` asked for",
                renderer.integrator().name(),
                integrator.name()
            )));
        }
        self.check_given(&accel)?;
        self.prepare_inner(Some(accel), Some(renderer))
    }

    /// Whether `accel` may be traced for this job: built over its scene (and binary, on
    /// the GPU).
    fn check_given(&self, accel: &Accel) -> Result<(), JobError> {
        let scene = self.scene;
        let same_primitives = std::ptr::eq(accel.primitives(), scene.primitives.as_slice());
        if !same_primitives || accel.world().instances().len() != scene.instances.len() + 1 {
            return Err(JobError::Invalid(
                "the acceleration structure given was not built over this scene".into(),
            ));
        }
        let binary = accel
            .world()
            .blases()
            .iter()
            .all(|b| b.tree().is_none_or(|tree| tree.width() == BvhWidth::Two));
        if self.device == Device::Gpu && !binary {
            return Err(JobError::Invalid(
                "the GPU walks binary trees; the structure given is wider".into(),
            ));
        }
        Ok(())
    }

    fn prepare_inner<'j>(
        &'j self,
        accel: Option<Arc<Accel>>,
        kept: Option<&'j canopy_gpu::Renderer<'j>>,
    ) -> Result<Prepared<'j>, JobError> {
        let settings = self.scene.settings;
        self.scene.validate().map_err(JobError::Invalid)?;
        self.region()
            .check_within(settings.width, settings.height)
            .map_err(JobError::Invalid)?;
        let region = self.region();
        let aov_bytes = match self.aovs.is_empty() {
            true => 0,
            false => AOV_BYTES_PER_PIXEL,
        };
        canopy_render::files::check_memory(
            region.pixels() as u64 * (BYTES_PER_PIXEL + aov_bytes),
            canopy_render::files::available_memory(),
            &format!("a {}x{} image", region.width, region.height),
        )
        .map_err(JobError::Invalid)?;
        let owners: Vec<u64> = std::iter::once(canopy_render::files::random_u64())
            .chain(self.resume_owner)
            .collect();
        for path in [&self.checkpoint.periodic, &self.checkpoint.on_interrupt]
            .into_iter()
            .flatten()
        {
            check_checkpoint_path(path, self.scene, &owners)?;
        }
        if let Some(resumed) = &self.resume {
            if resumed.aovs.set != self.aovs {
                return Err(JobError::Invalid(format!(
                    "the render to resume has the AOVs [{}], not the [{}] asked for",
                    resumed.aovs.set, self.aovs
                )));
            }
            if resumed.samples > settings.spp {
                return Err(JobError::Invalid(format!(
                    "the render to resume has {} samples per pixel, more than the {} asked for",
                    resumed.samples, settings.spp
                )));
            }
        }
        let pool = match self.threads {
            None => None,
            Some(n) if !(1..=MAX_THREADS).contains(&n) => {
                return Err(JobError::Invalid(format!(
                    "threads must be in 1..={MAX_THREADS}, not {n}"
                )))
            }
            Some(n) => Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(|e| JobError::Threads {
                        threads: n,
                        cause: e.to_string(),
                    })?,
            ),
        };
        let structure = &self.structure;
        if self.device == Device::Gpu && structure.triangle_test == TriangleTest::Fast {
            return Err(JobError::Invalid(
                "the GPU tests triangles watertight only, and this render's test is the fast one (a resumed render keeps its checkpoint's): render it on the CPU".into(),
            ));
        }
        let gpu = match self.device {
            Device::Cpu => None,
            Device::Gpu if structure.kind == AccelKind::None => {
                return Err(JobError::Invalid(
                    "the GPU traces through a BVH; choose a builder, not `none`".into(),
                ))
            }
            Device::Gpu => Some(match kept {
                Some(renderer) => GpuUse::Kept(renderer),
                None => GpuUse::Opened(Box::new(canopy_gpu::Gpu::new()?)),
            }),
        };
        // The GPU walks the binary tree (in its own layout, derived from it).
        let width = match gpu {
            Some(_) => BvhWidth::Two,
            None => structure.width,
        };
        let install = |work: &(dyn Fn() -> Accel + Sync)| match &pool {
            Some(pool) => pool.install(work),
            None => work(),
        };
        let scene = self.scene;
        let accel = match accel {
            Some(accel) => accel,
            None => Arc::new(install(&|| {
                Accel::for_scene(
                    scene,
                    structure.kind,
                    width,
                    &structure.params,
                    structure.optimize,
                )
                .with_triangle_test(structure.triangle_test)
            })),
        };
        Ok(Prepared {
            job: self,
            owners,
            pool,
            accel,
            gpu,
        })
    }
}

/// A checkpoint may be written to `path` only if it is no input of the scene and holds
/// nothing, or a checkpoint of `owners`: anything else there is the user's, or another
/// render's work.
fn check_checkpoint_path(
    path: &std::path::Path,
    scene: &canopy_render::Scene,
    owners: &[u64],
) -> Result<(), JobError> {
    canopy_render::output_policy::check_not_an_input(path, "checkpoint", &scene.inputs)
        .map_err(JobError::Invalid)?;
    Checkpoint::check_owned_slot(path, owners).map_err(|e| match e {
        // A user's file there: the job itself is wrong, as with an input.
        CheckpointError::NotACheckpoint { .. } => JobError::Invalid(e.to_string()),
        e => e.into(),
    })
}

impl Prepared<'_> {
    /// Saves `accumulator` as this render's checkpoint at `path`, unless something other
    /// than this render's own checkpoint (or the one it continues) is there.
    pub fn save_checkpoint(
        &self,
        accumulator: &Accumulator,
        path: &std::path::Path,
    ) -> Result<(), CheckpointError> {
        let job = self.job;
        Checkpoint::new(&job.source, job.scene, accumulator.clone())
            .with_triangle_test(self.triangle_test())
            .owned_by(self.owners[0])
            .save_owned(path, &self.owners)
    }

    /// How this render tests triangles: the structure's mode on the CPU; the GPU's test
    /// is always watertight.
    pub fn triangle_test(&self) -> TriangleTest {
        match self.gpu {
            Some(_) => TriangleTest::Watertight,
            None => self.accel.triangle_test(),
        }
    }

    /// The structure over the job's scene (the one the CPU traces).
    pub fn accel(&self) -> &Accel {
        &self.accel
    }

    pub fn build_time(&self) -> Duration {
        self.accel.build_time
    }

    /// Children per node of the tree rendered through: 2 on the GPU.
    pub fn width(&self) -> BvhWidth {
        match self.gpu {
            Some(_) => BvhWidth::Two,
            None => self.job.structure.width,
        }
    }

    /// `cpu`, or the GPU adapter in words.
    pub fn device_name(&self) -> String {
        match &self.gpu {
            Some(GpuUse::Opened(gpu)) => gpu.describe(),
            Some(GpuUse::Kept(renderer)) => renderer.gpu().describe(),
            None => "cpu".into(),
        }
    }

    /// Worker threads on the CPU.
    pub fn threads(&self) -> usize {
        self.install(rayon::current_num_threads)
    }

    /// Runs `work` on the job's worker threads.
    pub fn install<R: Send>(&self, work: impl FnOnce() -> R + Send) -> R {
        match &self.pool {
            Some(pool) => pool.install(work),
            None => work(),
        }
    }

    /// Renders the job's region, one sample per pixel per pass, until every sample is in
    /// or `observer` says stop. Periodic checkpoints are saved as the policy says (a
    /// failed save is a warning, tried again later); a stopped render saves its state to
    /// the policy's `on_interrupt`; a complete one removes its periodic checkpoint.
    pub fn run(&self, observer: &mut dyn Observer) -> Result<Outcome, JobError> {
        let job = self.job;
        let scene = job.scene;
        let uploaded;
        let renderer = match &self.gpu {
            None => None,
            // Mesh instances in two levels, as on the CPU (the structures are binary
            // trees: built with width 2 above).
            Some(GpuUse::Opened(gpu)) => {
                uploaded = canopy_gpu::Renderer::for_accel(gpu, scene, &self.accel)?;
                Some(&uploaded)
            }
            Some(GpuUse::Kept(renderer)) => Some(*renderer),
        };
        let engine = match renderer {
            None => Engine::Cpu {
                scene,
                accel: &self.accel,
                schedule: job.schedule,
            },
            Some(renderer) => Engine::Gpu {
                renderer,
                scene,
                aovs: (!job.aovs.is_empty()).then_some(&*self.accel),
            },
        };
        let mut accumulator = job
            .resume
            .clone()
            .unwrap_or_else(|| Accumulator::for_region(job.region).with_aovs(job.aovs));
        let spp = scene.settings.spp;
        let policy = &job.checkpoint;
        let mut stats = RenderStats::default();
        let mut last_save = Instant::now();
        let mut save_failing = false;
        let abandonable = observer.abandons_passes();
        while accumulator.samples < spp && observer.keep_going() {
            let before = abandonable.then(|| accumulator.clone());
            let pass = self.install(|| engine.pass(&mut accumulator, &*observer, abandonable))?;
            let Some(pass) = pass else {
                // Torn by the abandoned pass: the samples before it.
                accumulator = before.expect("only abandonable passes are abandoned");
                break;
            };
            stats.rays += pass.rays;
            stats.shadow_rays += pass.shadow_rays;
            stats.invalid_samples += pass.invalid_samples;
            stats.elapsed += pass.elapsed;
            observer.pass_done(accumulator.samples, spp);
            observer.pass_samples(&accumulator);
            let Some(path) = &policy.periodic else {
                continue;
            };
            if last_save.elapsed() >= policy.every && accumulator.samples < spp {
                // A failed save (a full disk) must not end hours of rendering: warn once
                // per run of failures, and try again at the next save.
                match self.save_checkpoint(&accumulator, path) {
                    Ok(()) => save_failing = false,
                    Err(e) if !save_failing => {
                        save_failing = true;
                        observer.warning(format!("{e}; rendering goes on, saving again later"));
                    }
                    Err(_) => {}
                }
                last_save = Instant::now();
            }
        }
        let complete = accumulator.samples >= spp;
        let mut saved = None;
        // A render stopped before its first sample has nothing to keep.
        if !complete && accumulator.samples > 0 {
            if let Some(path) = &policy.on_interrupt {
                // A failed save must not take the samples with it: they are still in the
                // outcome (the caller writes the image from them), and `saved` says none.
                match self.save_checkpoint(&accumulator, path) {
                    Ok(()) => saved = Some(path.clone()),
                    Err(e) => observer.warning(format!("{e}; the render cannot be resumed")),
                }
            }
        } else if let Some(path) = &policy.periodic {
            // The render is complete: its checkpoint has nothing left to give. Only its
            // own (or the one it continued) is removed, never another render's.
            let _ = Checkpoint::remove_owned(path, &self.owners);
        }
        Ok(Outcome {
            accumulator,
            stats,
            complete,
            saved,
        })
    }
}
