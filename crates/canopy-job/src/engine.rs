//! What renders a pass: the CPU integrator or the GPU renderer, behind one call.

use crate::observer::Observer;
use crate::JobError;
use canopy_render::{
    render_aov_samples, render_samples_abandonable, Accel, Accumulator, RenderStats, Scene,
    Schedule,
};

/// A device ready to add samples to an accumulator.
pub(crate) enum Engine<'a> {
    Cpu {
        scene: &'a Scene,
        accel: &'a Accel,
        schedule: Schedule,
    },
    Gpu {
        renderer: &'a canopy_gpu::Renderer<'a>,
        /// The camera and settings rendered (the renderer may have been uploaded with
        /// others: a viewer's earlier view).
        scene: &'a Scene,
        /// Where the accumulator has AOV layers: the CPU's structure that traces them.
        aovs: Option<&'a Accel>,
    },
}

impl Engine<'_> {
    /// Adds one sample to every pixel of the accumulator's region; `None` when the
    /// observer abandoned the pass (when `abandonable`; on the CPU, between rows), the
    /// accumulator then torn (see [`render_samples_abandonable`]). The GPU's passes run
    /// whole.
    pub(crate) fn pass(
        &self,
        accumulator: &mut Accumulator,
        observer: &dyn Observer,
        abandonable: bool,
    ) -> Result<Option<RenderStats>, JobError> {
        match self {
            Engine::Cpu {
                scene,
                accel,
                schedule,
            } => Ok(render_samples_abandonable(
                scene,
                accel,
                accumulator,
                1,
                *schedule,
                &|| observer.rows_done(1),
                &|| !(abandonable && observer.abandon_pass()),
            )),
            Engine::Gpu {
                renderer,
                scene,
                aovs,
            } => {
                // The AOVs of the GPU's samples: the same camera rays, traced on the CPU.
                let aov_rays = match aovs {
                    Some(accel) => render_aov_samples(scene, accel, accumulator, 1),
                    None => 0,
                };
                let done =
                    renderer.render_view_samples(&scene.camera, &scene.settings, accumulator, 1)?;
                observer.rows_done(accumulator.region.height as u64);
                Ok(Some(RenderStats {
                    rays: done.rays + aov_rays,
                    shadow_rays: done.shadow_rays,
                    invalid_samples: done.invalid_samples,
                    elapsed: done.elapsed,
                    ..RenderStats::default()
                }))
            }
        }
    }
}
