//! [`RayQuery`]: the one interface of every structure that owns its geometry
//! ([`crate::Blas`], [`crate::Tlas`]) — closest hit, occlusion, their batch forms, ray
//! masks — whatever the layout of its tree.

use crate::{Aabb, Hit, Ray, RayOrder, SliceSlots, TraversalCounter, TraversalStats};
use glam::Vec3;
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
/// A structure answers rays a slice at a time ([`RayQuery::closest_hits_into`],
/// [`RayQuery::any_hits_into`]): it chooses its layout and kernels once for the slice.
/// Everything else — single rays, rays made by a closure, masks, counters, parallel
/// batches — is provided on top of those two.
///
/// Why slices, not the caller's closures: the kernels are then compiled once per
/// structure (and counter) type, not once for every place that asks a query. Each call
/// site with closures of its own made its own copy of every kernel for every instruction
/// set and width, which was most of the build of every crate above this one.
///
/// Closest-hit ties go to the lower instance, then the lower primitive
/// ([`Hit::is_before`]), so every structure and layout gives brute force's answer. A ray
/// mask skips the instances whose mask shares no bit with it.
pub trait RayQuery: Sync {
    /// Box of everything the structure holds.
    fn bounds(&self) -> Aabb;

    /// Closest hits of `rays` on this thread: `hits[i]` is the closest hit of `rays[i]`
    /// within its `[t_min, t_max]` among the instances `mask` accepts; `coherence` says
    /// how the rays relate (the answers never depend on it). The work (node visits,
    /// primitive tests, at every level) goes to `counter`.
    ///
    /// # Panics
    /// If `rays` and `hits` differ in length.
    fn closest_hits_into<C: TraversalCounter>(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        mask: u32,
        coherence: Coherence,
        counter: &mut C,
    );

    /// Occlusion of `rays` on this thread: `blocked[i]` says whether anything `mask`
    /// accepts blocks `rays[i]` within its range (any hit), as
    /// [`RayQuery::closest_hits_into`].
    ///
    /// # Panics
    /// If `rays` and `blocked` differ in length.
    fn any_hits_into(&self, rays: &[Ray], blocked: &mut [bool], mask: u32, coherence: Coherence);

    /// Closest hits of the batch's rays on this thread: `ray(i)` makes ray `i` (for `i`
    /// in `0..batch.count`), `answer(i, hit)` takes its closest hit, in order, as
    /// [`RayQuery::closest_hits_into`] answers them. The rays are made and answered
    /// [`CLOSURE_CHUNK`] at a time, so `ray` is called for a few rays ahead of the
    /// answers.
    #[inline]
    fn closest_hits<R, A, C>(&self, batch: RayBatch, mut ray: R, mut answer: A, counter: &mut C)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
        C: TraversalCounter,
    {
        let (mask, coherence) = (batch.mask, batch.coherence);
        if batch.count == 1 {
            let mut hit = None;
            let one = std::slice::from_mut(&mut hit);
            self.closest_hits_into(&[ray(0)], one, mask, coherence, counter);
            return answer(0, hit);
        }
        let mut hits = [None; CLOSURE_CHUNK];
        in_chunks(batch.count, &mut ray, |rays, first| {
            let hits = &mut hits[..rays.len()];
            self.closest_hits_into(rays, hits, mask, coherence, counter);
            hits.iter()
                .enumerate()
                .for_each(|(k, &h)| answer(first + k, h));
        });
    }

    /// Occlusion of the batch's rays on this thread: `answer(i, blocked)` for ray `i`, as
    /// [`RayQuery::closest_hits`].
    #[inline]
    fn any_hits<R, A>(&self, batch: RayBatch, mut ray: R, mut answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool),
    {
        let (mask, coherence) = (batch.mask, batch.coherence);
        if batch.count == 1 {
            let mut blocked = false;
            let one = std::slice::from_mut(&mut blocked);
            self.any_hits_into(&[ray(0)], one, mask, coherence);
            return answer(0, blocked);
        }
        let mut blocked = [false; CLOSURE_CHUNK];
        in_chunks(batch.count, &mut ray, |rays, first| {
            let blocked = &mut blocked[..rays.len()];
            self.any_hits_into(rays, blocked, mask, coherence);
            blocked
                .iter()
                .enumerate()
                .for_each(|(k, &b)| answer(first + k, b));
        });
    }

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
        let one = std::slice::from_mut(&mut blocked);
        self.any_hits_into(std::slice::from_ref(ray), one, mask, Coherence::Incoherent);
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
        let (rays, one) = (std::slice::from_ref(ray), std::slice::from_mut(&mut hit));
        self.closest_hits_into(rays, one, mask, Coherence::Incoherent, counter);
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
            self.closest_hits_into(rays, hits, mask, Coherence::Incoherent, &mut ())
        });
    }

    /// Occlusion of many rays in parallel: `occluded[i]` answers `rays[i]`.
    ///
    /// # Panics
    /// If `rays` and `occluded` differ in length.
    fn occluded_batch(&self, rays: &[Ray], occluded: &mut [bool], mask: u32) {
        assert_eq!(rays.len(), occluded.len(), "one answer per ray");
        trace_batch(self.orders_batches(), rays, occluded, |rays, out| {
            self.any_hits_into(rays, out, mask, Coherence::Incoherent)
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
    fn closest_hits_into<C: TraversalCounter>(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        mask: u32,
        coherence: Coherence,
        counter: &mut C,
    ) {
        self.target()
            .closest_hits_into(rays, hits, mask, coherence, counter)
    }

    #[inline]
    fn any_hits_into(&self, rays: &[Ray], blocked: &mut [bool], mask: u32, coherence: Coherence) {
        self.target().any_hits_into(rays, blocked, mask, coherence)
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

/// Rays that [`RayQuery::closest_hits`] and [`RayQuery::any_hits`] make at a time, then
/// answer as a slice: whole packets ([`crate::PACKET`]), so that coherent rays are grouped
/// into packets as the caller numbers them, and enough of them that what a slice costs
/// before its first ray (the calls, the kernels' choice and set-up) is spread thin (17 KB
/// of stack).
pub const CLOSURE_CHUNK: usize = 16 * crate::PACKET;

/// Makes rays `0..count` with `ray`, [`CLOSURE_CHUNK`] at a time, and hands each chunk to
/// `each` with the number of its first ray.
#[inline(always)]
fn in_chunks(
    count: usize,
    ray: &mut impl FnMut(usize) -> Ray,
    mut each: impl FnMut(&[Ray], usize),
) {
    let mut rays = [Ray::new(Vec3::ZERO, Vec3::X, 0.0, 0.0); CLOSURE_CHUNK];
    for first in (0..count).step_by(CLOSURE_CHUNK) {
        let chunk = &mut rays[..CLOSURE_CHUNK.min(count - first)];
        chunk
            .iter_mut()
            .enumerate()
            .for_each(|(k, r)| *r = ray(first + k));
        each(chunk, first);
    }
}

/// Answers of many rays in parallel over chunks of [`BATCH_CHUNK`]: `each(rays, out)`
/// answers a chunk on one thread. Traced in [`RayOrder`] where `ordered` (and the batch
/// is worth ordering), each answer written to the caller's slot.
pub fn trace_batch<T: Copy + Default + Send>(
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
        Some(order) => order.trace_into(BATCH_CHUNK, |i| rays[i], each, &SliceSlots::new(out)),
    }
}
