//! What a caller sees of a render while it runs, and how it stops one.

/// Progress and control of a running render. Every method has a default that does
/// nothing (and never cancels), so `()` observes nothing.
///
/// [`rows_done`](Self::rows_done) is called from worker threads while a pass runs; the
/// other methods between passes, on the thread that runs the job.
pub trait Observer: Sync {
    /// `rows` more rows of the region have their sample of this pass.
    fn rows_done(&self, _rows: u64) {}

    /// Whether this observer may abandon passes ([`abandon_pass`](Self::abandon_pass));
    /// asked once a run. A run for one that may keeps a copy of the samples before each
    /// pass, to put back when one is abandoned.
    fn abandons_passes(&self) -> bool {
        false
    }

    /// Whether to drop the pass in flight at once (an interactive view whose camera
    /// moved): asked from worker threads between rows, where
    /// [`abandons_passes`](Self::abandons_passes) said so. The run then ends as if
    /// [`keep_going`](Self::keep_going) had said stop, with the passes before it.
    fn abandon_pass(&self) -> bool {
        false
    }

    /// Whether to render another pass; asked before each. A render told to stop ends
    /// with the passes it has, and saves them where the checkpoint policy says.
    fn keep_going(&mut self) -> bool {
        true
    }

    /// A pass is done: every pixel of the region has `samples` of `spp` samples.
    fn pass_done(&mut self, _samples: u32, _spp: u32) {}

    /// The samples so far, after each pass (for a caller that shows the image as it
    /// refines, as the viewer does); called after [`pass_done`](Self::pass_done).
    fn pass_samples(&mut self, _accumulator: &canopy_render::Accumulator) {}

    /// Something went wrong that the render survives (a periodic checkpoint that could
    /// not be written); the library never prints, so it tells the caller.
    fn warning(&mut self, _message: String) {}
}

impl Observer for () {}
