//! What renders a pass: the CPU integrator or the GPU renderer, behind one call.

use crate::observer::Observer;
use crate::JobError;
use canopy_render::{render_samples, Accel, Accumulator, RenderStats, Scene};

/// A device ready to add samples to an accumulator.
pub(crate) enum Engine<'a> {
    Cpu { scene: &'a Scene, accel: &'a Accel },
    Gpu(Box<canopy_gpu::Renderer<'a>>),
}

impl Engine<'_> {
    /// Adds one sample to every pixel of the accumulator's region.
    pub(crate) fn pass(
        &self,
        accumulator: &mut Accumulator,
        observer: &dyn Observer,
    ) -> Result<RenderStats, JobError> {
        match self {
            Engine::Cpu { scene, accel } => {
                Ok(render_samples(scene, accel, accumulator, 1, &|| {
                    observer.rows_done(1)
                }))
            }
            Engine::Gpu(renderer) => {
                let done = renderer.render_samples(accumulator, 1)?;
                observer.rows_done(accumulator.region.height as u64);
                Ok(RenderStats {
                    rays: done.rays,
                    shadow_rays: done.shadow_rays,
                    invalid_samples: done.invalid_samples,
                    elapsed: done.elapsed,
                    ..RenderStats::default()
                })
            }
        }
    }
}
