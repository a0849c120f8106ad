//! What renders a pass: the CPU integrator or the GPU renderer, behind one call.

use crate::observer::Observer;
use crate::JobError;
use canopy_render::{
    render_aov_samples, render_samples_with, Accel, Accumulator, RenderStats, Scene, Schedule,
};

/// A device ready to add samples to an accumulator.
pub(crate) enum Engine<'a> {
    Cpu {
        scene: &'a Scene,
        accel: &'a Accel,
        schedule: Schedule,
    },
    Gpu {
        renderer: Box<canopy_gpu::Renderer<'a>>,
        /// Where the accumulator has AOV layers: the scene and the CPU's structure that
        /// trace them.
        aovs: Option<(&'a Scene, &'a Accel)>,
    },
}

impl Engine<'_> {
    /// Adds one sample to every pixel of the accumulator's region.
    pub(crate) fn pass(
        &self,
        accumulator: &mut Accumulator,
        observer: &dyn Observer,
    ) -> Result<RenderStats, JobError> {
        match self {
            Engine::Cpu {
                scene,
                accel,
                schedule,
            } => Ok(render_samples_with(
                scene,
                accel,
                accumulator,
                1,
                *schedule,
                &|| observer.rows_done(1),
            )),
            Engine::Gpu { renderer, aovs } => {
                // The AOVs of the GPU's samples: the same camera rays, traced on the CPU.
                let aov_rays = match aovs {
                    Some((scene, accel)) => render_aov_samples(scene, accel, accumulator, 1),
                    None => 0,
                };
                let done = renderer.render_samples(accumulator, 1)?;
                observer.rows_done(accumulator.region.height as u64);
                Ok(RenderStats {
                    rays: done.rays + aov_rays,
                    shadow_rays: done.shadow_rays,
                    invalid_samples: done.invalid_samples,
                    elapsed: done.elapsed,
                    ..RenderStats::default()
                })
            }
        }
    }
}
