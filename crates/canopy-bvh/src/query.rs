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

/// Ray queries of a structure that owns its geometry.
///
/// Closest-hit ties go to the lower instance, then the lower primitive
/// ([`Hit::is_before`]), so every structure and layout gives brute force's answer. A ray
/// `mask` skips the instances whose mask shares no bit with it (a structure without
/// instances ignores it).
pub trait RayQuery: Sync {
    /// Box of everything the structure holds.
    fn bounds(&self) -> Aabb;

    /// Closest hit of `ray` within `[t_min, t_max]` among the instances `mask` accepts.
    #[inline]
    fn intersect_masked(&self, ray: &Ray, mask: u32) -> Option<Hit> {
        self.intersect_counted(ray, mask, &mut ())
    }

    /// Whether anything `mask` accepts blocks `ray` within its range (any hit).
    fn occluded_masked(&self, ray: &Ray, mask: u32) -> bool;

    /// [`RayQuery::intersect_masked`], reporting its work (node visits, primitive tests,
    /// at every level) to `counter`.
    fn intersect_counted<C: TraversalCounter>(
        &self,
        ray: &Ray,
        mask: u32,
        counter: &mut C,
    ) -> Option<Hit>;

    /// The work a closest-hit query does for `ray`: node visits and primitive tests.
    fn traversal_cost(&self, ray: &Ray) -> TraversalStats {
        let mut stats = TraversalStats::default();
        self.intersect_counted(ray, ALL_MASKS, &mut stats);
        stats
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

    /// Closest hits of rays `0..count` on this thread: `ray(i)` makes ray `i`, `answer(i,
    /// hit)` takes its hit, in order. Structures override it to choose their layout and
    /// kernels once for all the rays.
    fn intersect_each<R, A>(&self, count: usize, mask: u32, mut ray: R, mut answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
    {
        for i in 0..count {
            answer(i, self.intersect_masked(&ray(i), mask));
        }
    }

    /// [`RayQuery::intersect_each`] for coherent rays: rays `i` and `i + 1` mostly start
    /// near each other and run in similar directions (camera rays of neighbouring
    /// pixels or of one pixel's samples). Structures may trace them as packets; the
    /// answers are the same.
    fn intersect_coherent<R, A>(&self, count: usize, mask: u32, ray: R, answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
    {
        self.intersect_each(count, mask, ray, answer)
    }

    /// Occlusion of rays `0..count` on this thread, as [`RayQuery::intersect_each`].
    fn occluded_each<R, A>(&self, count: usize, mask: u32, mut ray: R, mut answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool),
    {
        for i in 0..count {
            answer(i, self.occluded_masked(&ray(i), mask));
        }
    }

    /// [`RayQuery::occluded_each`] for coherent rays (shadow rays from neighbouring
    /// points towards one light): structures may trace them as packets; the answers are
    /// the same.
    fn occluded_coherent<R, A>(&self, count: usize, mask: u32, ray: R, answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool),
    {
        self.occluded_each(count, mask, ray, answer)
    }

    /// Whether large batches are best traced in the order of their rays' origins
    /// ([`RayOrder`]): structures larger than a core's cache.
    fn orders_batches(&self) -> bool {
        false
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

/// A structure shared (by several top-level trees, or with its owner) answers as itself.
impl<B: RayQuery + Send> RayQuery for std::sync::Arc<B> {
    fn bounds(&self) -> Aabb {
        (**self).bounds()
    }
    #[inline]
    fn intersect_masked(&self, ray: &Ray, mask: u32) -> Option<Hit> {
        (**self).intersect_masked(ray, mask)
    }
    #[inline]
    fn occluded_masked(&self, ray: &Ray, mask: u32) -> bool {
        (**self).occluded_masked(ray, mask)
    }
    #[inline]
    fn intersect_counted<C: TraversalCounter>(
        &self,
        ray: &Ray,
        mask: u32,
        counter: &mut C,
    ) -> Option<Hit> {
        (**self).intersect_counted(ray, mask, counter)
    }
    fn intersect_each<R, A>(&self, count: usize, mask: u32, ray: R, answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
    {
        (**self).intersect_each(count, mask, ray, answer)
    }
    fn intersect_coherent<R, A>(&self, count: usize, mask: u32, ray: R, answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
    {
        (**self).intersect_coherent(count, mask, ray, answer)
    }
    fn occluded_each<R, A>(&self, count: usize, mask: u32, ray: R, answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool),
    {
        (**self).occluded_each(count, mask, ray, answer)
    }
    fn occluded_coherent<R, A>(&self, count: usize, mask: u32, ray: R, answer: A)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool),
    {
        (**self).occluded_coherent(count, mask, ray, answer)
    }
    fn orders_batches(&self) -> bool {
        (**self).orders_batches()
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
