//! [`RayQuery`]: the one interface of every structure that owns its geometry
//! ([`crate::Blas`], [`crate::Tlas`]) — closest hit, occlusion, their batch forms, ray
//! masks — whatever the layout of its tree.

use crate::{Aabb, Hit, Ray, RayOrder, TraversalCounter, TraversalStats};
use rayon::prelude::*;

/// A ray mask that every instance accepts.
pub const ALL_MASKS: u32 = u32::MAX;

/// Rays per parallel task of the batch calls: large enough to amortise scheduling, small
/// enough to balance two to a few dozen threads.
pub const BATCH_CHUNK: usize = 512;

/// How the rays of a batch relate: a hint for how to trace them. The answers never
/// depend on it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Coherence {
    /// Rays go their own ways (bounces off rough surfaces, random queries): traced one by
    /// one.
    #[default]
    Incoherent,
    /// Rays `i` and `i + 1` mostly start near each other and run in similar directions
    /// (camera rays of neighbouring pixels, shadow rays from neighbouring points towards
    /// one light): structures may trace them as packets.
    Coherent,
}

impl Coherence {
    /// [`Coherence::Coherent`] where `coherent`.
    #[inline]
    pub fn hint(coherent: bool) -> Self {
        match coherent {
            true => Coherence::Coherent,
            false => Coherence::Incoherent,
        }
    }
}

/// What a batch of rays asks besides the rays themselves: how many, which instances (a
/// ray `mask`; a structure without instances ignores it) and how the rays relate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RayBatch {
    pub count: usize,
    pub mask: u32,
    pub coherence: Coherence,
}

impl RayBatch {
    /// `count` incoherent rays that every instance accepts.
    #[inline]
    pub fn new(count: usize) -> Self {
        Self {
            count,
            mask: ALL_MASKS,
            coherence: Coherence::Incoherent,
        }
    }

    /// One ray for the instances `mask` accepts.
    #[inline]
    pub fn one(mask: u32) -> Self {
        Self::new(1).masked(mask)
    }

    /// The batch for the instances `mask` accepts.
    #[inline]
    pub fn masked(self, mask: u32) -> Self {
        Self { mask, ..self }
    }

    /// The batch with the coherence hint `coherence`.
    #[inline]
    pub fn with(self, coherence: Coherence) -> Self {
        Self { coherence, ..self }
    }
}

/// Ray queries of a structure that owns its geometry.
///
/// A structure answers batches of rays ([`RayQuery::closest_hits`],
/// [`RayQuery::any_hits`]): it chooses its layout and kernels once for the batch, and the
/// callers' closures are compiled into its loop. Everything else — single rays, masks,
/// counters, parallel batches — is provided on top of those two.
///
/// Closest-hit ties go to the lower instance, then the lower primitive
/// ([`Hit::is_before`]), so every structure and layout gives brute force's answer. A ray
/// mask skips the instances whose mask shares no bit with it.
pub trait RayQuery: Sync {
    /// Box of everything the structure holds.
    fn bounds(&self) -> Aabb;

    /// Closest hits of the batch's rays on this thread: `ray(i)` makes ray `i` (for `i`
    /// in `0..batch.count`), `answer(i, hit)` takes its closest hit within `[t_min,
    /// t_max]`, in order. The work (node visits, primitive tests, at every level) goes to
    /// `counter`.
    fn closest_hits<R, A, C>(&self, batch: RayBatch, ray: R, answer: A, counter: &mut C)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
        C: TraversalCounter;

    /// Occlusion of the batch's rays on this thread: `answer(i, blocked)` says whether
    /// anything blocks ray `i` within its range (any hit), as [`RayQuery::closest_hits`].
    fn any_hits<R, A>(&self, batch: RayBatch, ray: R, answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool);

    /// Whether large batches are best traced in the order of their rays' origins
    /// ([`RayOrder`]): structures larger than a core's cache.
    fn orders_batches(&self) -> bool {
        false
    }

    /// Closest hit of `ray` within `[t_min, t_max]`.
    #[inline]
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.intersect_masked(ray, ALL_MASKS)
    }

    /// Whether anything blocks `ray` within its range.
    #[inline]
    fn occluded(&self, ray: &Ray) -> bool {
        self.occluded_masked(ray, ALL_MASKS)
    }

    /// Closest hit of `ray` among the instances `mask` accepts.
    #[inline]
    fn intersect_masked(&self, ray: &Ray, mask: u32) -> Option<Hit> {
        self.intersect_counted(ray, mask, &mut ())
    }

    /// Whether anything `mask` accepts blocks `ray` within its range.
    #[inline]
    fn occluded_masked(&self, ray: &Ray, mask: u32) -> bool {
        let mut blocked = false;
        self.any_hits(RayBatch::one(mask), |_| *ray, |_, b| blocked = b);
        blocked
    }

    /// [`RayQuery::intersect_masked`], reporting its work to `counter`.
    #[inline]
    fn intersect_counted<C: TraversalCounter>(
        &self,
        ray: &Ray,
        mask: u32,
        counter: &mut C,
    ) -> Option<Hit> {
        let mut hit = None;
        self.closest_hits(RayBatch::one(mask), |_| *ray, |_, h| hit = h, counter);
        hit
    }

    /// The work a closest-hit query does for `ray`: node visits and primitive tests.
    fn traversal_cost(&self, ray: &Ray) -> TraversalStats {
        let mut stats = TraversalStats::default();
        self.intersect_counted(ray, ALL_MASKS, &mut stats);
        stats
    }

    /// Closest hits of `count` incoherent rays ([`RayQuery::closest_hits`]).
    #[inline]
    fn intersect_each<R, A>(&self, count: usize, mask: u32, ray: R, answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
    {
        self.closest_hits(RayBatch::new(count).masked(mask), ray, answer, &mut ())
    }

    /// Closest hits of `count` coherent rays ([`Coherence::Coherent`]).
    #[inline]
    fn intersect_coherent<R, A>(&self, count: usize, mask: u32, ray: R, answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
    {
        let batch = RayBatch::new(count).masked(mask).with(Coherence::Coherent);
        self.closest_hits(batch, ray, answer, &mut ())
    }

    /// Occlusion of `count` incoherent rays ([`RayQuery::any_hits`]).
    #[inline]
    fn occluded_each<R, A>(&self, count: usize, mask: u32, ray: R, answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool),
    {
        self.any_hits(RayBatch::new(count).masked(mask), ray, answer)
    }

    /// Occlusion of `count` coherent rays ([`Coherence::Coherent`]).
    #[inline]
    fn occluded_coherent<R, A>(&self, count: usize, mask: u32, ray: R, answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool),
    {
        self.any_hits(
            RayBatch::new(count).masked(mask).with(Coherence::Coherent),
            ray,
            answer,
        )
    }

    /// Closest hits of many rays in parallel (rayon's current pool): `hits[i]` answers
    /// `rays[i]`. Large batches over large structures are traced in the order of their
    /// origins; the answers are the same.
    ///
    /// # Panics
    /// If `rays` and `hits` differ in length.
    fn intersect_batch(&self, rays: &[Ray], hits: &mut [Option<Hit>], mask: u32) {
        assert_eq!(rays.len(), hits.len(), "one hit slot per ray");
        trace_batch(self.orders_batches(), rays, hits, |rays, hits| {
            self.intersect_each(rays.len(), mask, |i| rays[i], |i, h| hits[i] = h)
        });
    }

    /// Occlusion of many rays in parallel: `occluded[i]` answers `rays[i]`.
    ///
    /// # Panics
    /// If `rays` and `occluded` differ in length.
    fn occluded_batch(&self, rays: &[Ray], occluded: &mut [bool], mask: u32) {
        assert_eq!(rays.len(), occluded.len(), "one answer per ray");
        trace_batch(self.orders_batches(), rays, occluded, |rays, out| {
            self.occluded_each(rays.len(), mask, |i| rays[i], |i, o| out[i] = o)
        });
    }
}

/// A structure that answers as another one it holds: its queries forward, whole batches
/// at a time, to [`Forward::target`]. Implement this instead of [`RayQuery`] for a
/// wrapper.
pub trait Forward: Sync {
    type Target: RayQuery;
    fn target(&self) -> &Self::Target;
}

impl<T: Forward> RayQuery for T {
    #[inline]
    fn bounds(&self) -> Aabb {
        self.target().bounds()
    }

    #[inline]
    fn closest_hits<R, A, C>(&self, batch: RayBatch, ray: R, answer: A, counter: &mut C)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
        C: TraversalCounter,
    {
        self.target().closest_hits(batch, ray, answer, counter)
    }

    #[inline]
    fn any_hits<R, A>(&self, batch: RayBatch, ray: R, answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool),
    {
        self.target().any_hits(batch, ray, answer)
    }

    #[inline]
    fn orders_batches(&self) -> bool {
        self.target().orders_batches()
    }
}

/// A structure shared (by several top-level trees, or with its owner) answers as itself.
impl<B: RayQuery + Send> Forward for std::sync::Arc<B> {
    type Target = B;
    #[inline]
    fn target(&self) -> &B {
        self
    }
}

/// Answers of many rays in parallel over chunks of [`BATCH_CHUNK`]: `each(rays, out)`
/// answers a chunk on one thread. Traced in [`RayOrder`] where `ordered` (and the batch
/// is worth ordering), the answers then put back in the caller's order.
pub fn trace_batch<T: Copy + Default + Send + Sync>(
    ordered: bool,
    rays: &[Ray],
    out: &mut [T],
    each: impl Fn(&[Ray], &mut [T]) + Sync,
) {
    let order = match ordered {
        true => RayOrder::by_origin(rays.len(), |i| rays[i].origin),
        false => None,
    };
    match order {
        None => out
            .par_chunks_mut(BATCH_CHUNK)
            .zip(rays.par_chunks(BATCH_CHUNK))
            .for_each(|(out, rays)| each(rays, out)),
        Some(order) => {
            let traced = order.trace(BATCH_CHUNK, |i| rays[i], each);
            order.unsort_into(&traced, out);
        }
    }
}
