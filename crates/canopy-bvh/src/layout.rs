//! The layouts a tree can be traversed in, and [`Tree`]: a tree in any of them. This is the
//! one place that matches on the layout; everything else (the renderer, `canopy bvh`, the
//! benchmarks, pictures of trees) goes through [`Tree`], so a new layout touches only here.

use crate::query::RayBatch;
use crate::traverse::TraversalCounter;
use crate::view::{self, TreeView};
use crate::{
    Aabb, Bvh2, Bvh4, Bvh8, BvhError, GpuBvh, Hit, IntoHit, Isa, IsaError, KnownShape, Ray,
    RefitError, TriangleTest,
};
use crate::{SahCosts, TreeStats};
use glam::Vec3;
use std::fmt;
use std::str::FromStr;

/// Children per node: the binary tree as built, or collapsed to 4 or 8 wide (SIMD box
/// tests, triangles packed in the leaves). 8-wide is the default: the fastest to trace.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum BvhWidth {
    Two,
    Four,
    #[default]
    Eight,
}

impl BvhWidth {
    pub const ALL: [BvhWidth; 3] = [BvhWidth::Two, BvhWidth::Four, BvhWidth::Eight];

    pub fn children(self) -> u32 {
        match self {
            BvhWidth::Two => 2,
            BvhWidth::Four => 4,
            BvhWidth::Eight => 8,
        }
    }
}

impl fmt::Display for BvhWidth {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.children())
    }
}

impl FromStr for BvhWidth {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        BvhWidth::ALL
            .into_iter()
            .find(|w| w.children().to_string() == s)
            .ok_or_else(|| format!("BVH width must be 2, 4 or 8, not `{s}`"))
    }
}

/// A tree in one of the layouts.
#[derive(Clone, Debug, PartialEq)]
pub enum Tree {
    Binary(Bvh2),
    Four(Bvh4),
    Eight(Bvh8),
    /// The binary tree with both children's boxes in each node: the layout canopy-gpu's
    /// kernels walk (traced here by their CPU twin). Made by [`Tree::for_gpu`].
    Gpu(GpuBvh),
}

impl Tree {
    /// The binary tree as it is, or collapsed to the width asked for.
    pub fn new(bvh: Bvh2, width: BvhWidth) -> Self {
        match width {
            BvhWidth::Two => Tree::Binary(bvh),
            BvhWidth::Four => Tree::Four(Bvh4::from_bvh2(&bvh)),
            BvhWidth::Eight => Tree::Eight(Bvh8::from_bvh2(&bvh)),
        }
    }

    /// The binary tree in the GPU layout.
    pub fn for_gpu(bvh: &Bvh2) -> Self {
        Tree::Gpu(GpuBvh::from_bvh2(bvh))
    }

    /// Children per node (the GPU layout is binary).
    pub fn width(&self) -> BvhWidth {
        match self {
            Tree::Binary(_) | Tree::Gpu(_) => BvhWidth::Two,
            Tree::Four(_) => BvhWidth::Four,
            Tree::Eight(_) => BvhWidth::Eight,
        }
    }

    /// Packs the leaves' triangles for the SIMD triangle kernel (wide layouts; the binary
    /// tree tests every primitive through the closure). See [`BvhN::pack_triangles`].
    pub fn pack_triangles(&mut self, triangle: impl Fn(u32) -> Option<[Vec3; 3]> + Sync) {
        match self {
            Tree::Binary(_) | Tree::Gpu(_) => {}
            Tree::Four(t) => t.pack_triangles(triangle),
            Tree::Eight(t) => t.pack_triangles(triangle),
        }
    }

    /// Packs every leaf, a tree without triangles too (wide layouts). See
    /// [`BvhN::pack_leaves`].
    pub fn pack_leaves(&mut self, triangle: impl Fn(u32) -> Option<[Vec3; 3]> + Sync) {
        match self {
            Tree::Binary(_) | Tree::Gpu(_) => {}
            Tree::Four(t) => t.pack_leaves(triangle),
            Tree::Eight(t) => t.pack_leaves(triangle),
        }
    }

    /// Keeps the leaves' spheres and boxes beside them for the wide kernels to test (wide
    /// layouts; see [`BvhN::store_shapes`]).
    pub fn store_shapes(&mut self, shape: impl Fn(u32) -> Option<KnownShape> + Sync) {
        match self {
            Tree::Binary(_) | Tree::Gpu(_) => {}
            Tree::Four(t) => t.store_shapes(shape),
            Tree::Eight(t) => t.store_shapes(shape),
        }
    }

    /// Whether traversal tests some primitives itself as known shapes
    /// ([`Tree::store_shapes`]).
    pub fn has_kept_shapes(&self) -> bool {
        match self {
            Tree::Binary(_) | Tree::Gpu(_) => false,
            Tree::Four(t) => t.has_kept_shapes(),
            Tree::Eight(t) => t.has_kept_shapes(),
        }
    }

    /// Recomputes every box from `boxes` (one per primitive) and the packed triangles
    /// from `triangle`, keeping the topology (for primitives that moved). Refuses a tree
    /// with spatial splits.
    pub fn refit(
        &mut self,
        boxes: &[Aabb],
        triangle: impl Fn(u32) -> Option<[Vec3; 3]> + Sync,
    ) -> Result<(), RefitError> {
        match self {
            Tree::Binary(t) => t.refit(boxes),
            Tree::Gpu(t) => t.refit(boxes),
            Tree::Four(t) => t.refit(boxes, triangle),
            Tree::Eight(t) => t.refit(boxes, triangle),
        }
    }

    /// Whether the tree tests triangles itself, from packs in its leaves.
    pub fn has_triangle_packs(&self) -> bool {
        match self {
            Tree::Binary(_) | Tree::Gpu(_) => false,
            Tree::Four(t) => t.has_triangle_packs(),
            Tree::Eight(t) => t.has_triangle_packs(),
        }
    }

    /// Uses the kernels of `isa` (wide layouts; the binary traversal is scalar).
    pub fn set_isa(&mut self, isa: Isa) -> Result<(), IsaError> {
        match self {
            Tree::Binary(_) | Tree::Gpu(_) => Ok(()),
            Tree::Four(t) => t.set_isa(isa),
            Tree::Eight(t) => t.set_isa(isa),
        }
    }

    /// Tests the triangle packs in mode `test` (wide layouts; the other layouts leave
    /// every primitive to the caller's closure). See [`BvhN::set_triangle_test`].
    pub fn set_triangle_test(&mut self, test: TriangleTest) {
        match self {
            Tree::Binary(_) | Tree::Gpu(_) => {}
            Tree::Four(t) => t.set_triangle_test(test),
            Tree::Eight(t) => t.set_triangle_test(test),
        }
    }

    /// The tree as a walk over boxes, children and leaves, whatever its layout.
    pub fn view(&self) -> &dyn TreeView {
        match self {
            Tree::Binary(t) => t,
            Tree::Four(t) => t,
            Tree::Eight(t) => t,
            Tree::Gpu(t) => t,
        }
    }

    pub fn stats(&self, costs: &SahCosts) -> TreeStats {
        view::stats(self.view(), costs)
    }

    pub fn validate(&self, boxes: &[Aabb]) -> Result<(), BvhError> {
        view::validate(self.view(), boxes)
    }

    /// Every box whose level is in `first..=last` (the root's is level 0; a wide node's
    /// children are one level below it), shallowest first; for pictures of the tree.
    pub fn boxes_at_levels(&self, first: usize, last: usize) -> Vec<(Aabb, usize)> {
        view::boxes_at_levels(self.view(), first, last)
    }

    /// Closest hit; same contract as [`Bvh2::intersect`].
    #[inline]
    pub fn intersect_counted<F, P, C>(&self, ray: &Ray, hit_prim: F, counter: &mut C) -> Option<Hit>
    where
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
        C: TraversalCounter,
    {
        match self {
            Tree::Binary(t) => t.intersect_counted(ray, hit_prim, counter),
            Tree::Four(t) => t.intersect_counted(ray, hit_prim, counter),
            Tree::Eight(t) => t.intersect_counted(ray, hit_prim, counter),
            Tree::Gpu(t) => t.intersect_counted(ray, hit_prim, counter),
        }
    }

    /// Whether anything blocks `ray`; same contract as [`Bvh2::occluded`].
    #[inline]
    pub fn occluded<F>(&self, ray: &Ray, hit_prim: F) -> bool
    where
        F: FnMut(u32, &Ray) -> bool,
    {
        match self {
            Tree::Binary(t) => t.occluded(ray, hit_prim),
            Tree::Four(t) => t.occluded(ray, hit_prim),
            Tree::Eight(t) => t.occluded(ray, hit_prim),
            Tree::Gpu(t) => t.occluded(ray, hit_prim),
        }
    }

    /// Every hit of `ray` within its range, each given to `found` as it is met (with the
    /// triangle's vertices where the tree holds them); same contract as
    /// [`BvhN::for_each_hit`].
    #[inline]
    pub fn for_each_hit<F, P, H>(&self, ray: &Ray, hit_prim: F, found: H)
    where
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
        H: FnMut(Hit, Option<[Vec3; 3]>),
    {
        match self {
            Tree::Binary(t) => _ = t.occluded(ray, reporting(hit_prim, found)),
            Tree::Gpu(t) => _ = t.occluded(ray, reporting(hit_prim, found)),
            Tree::Four(t) => t.for_each_hit(ray, hit_prim, found),
            Tree::Eight(t) => t.for_each_hit(ray, hit_prim, found),
        }
    }

    /// [`Tree::for_each_hit`] of each of `rays`, one after another, each hit given to
    /// `found(i, hit, vertices)` with its ray's index; same contract as
    /// [`BvhN::for_each_hit_of`].
    pub fn for_each_hit_of<F, P, H>(&self, rays: &[Ray], mut hit_prim: F, mut found: H)
    where
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
        H: FnMut(usize, Hit, Option<[Vec3; 3]>),
    {
        let mut one_by_one = |walk: &dyn Fn(&Ray, &mut PrimTest)| {
            for (i, ray) in rays.iter().enumerate() {
                let found = |hit: Hit, vertices: Option<[Vec3; 3]>| found(i, hit, vertices);
                walk(ray, &mut reporting(&mut hit_prim, found));
            }
        };
        match self {
            Tree::Binary(t) => one_by_one(&|ray, test| _ = t.occluded(ray, test)),
            Tree::Gpu(t) => one_by_one(&|ray, test| _ = t.occluded(ray, test)),
            Tree::Four(t) => t.for_each_hit_of(rays, hit_prim, found),
            Tree::Eight(t) => t.for_each_hit_of(rays, hit_prim, found),
        }
    }

    /// Whether batches over this tree are best traced in the order of their rays'
    /// origins ([`crate::BvhN::orders_batches`]; never for the binary and GPU layouts).
    pub fn orders_batches(&self) -> bool {
        match self {
            Tree::Binary(_) | Tree::Gpu(_) => false,
            Tree::Four(t) => t.orders_batches(),
            Tree::Eight(t) => t.orders_batches(),
        }
    }

    /// Closest hits of the batch's rays on this thread: `ray(i)` makes ray `i`,
    /// `answer(i, hit)` takes its hit, in order (the batch's mask is not a tree's
    /// business). The layout (and, for wide trees, the instruction set) is chosen once
    /// for all the rays; coherent batches go in packets where the layout has them
    /// ([`crate::BvhN::intersect_coherent`]). The answers are the same either way.
    pub fn closest_hits<R, A, F, P, C>(
        &self,
        batch: RayBatch,
        mut ray: R,
        mut answer: A,
        mut hit_prim: F,
        counter: &mut C,
    ) where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
        C: TraversalCounter,
    {
        let mut each = |closest: &mut dyn FnMut(&Ray, &mut C) -> Option<Hit>| {
            for i in 0..batch.count {
                answer(i, closest(&ray(i), counter));
            }
        };
        match self {
            Tree::Binary(t) => each(&mut |r, c| t.intersect_counted(r, &mut hit_prim, c)),
            Tree::Gpu(t) => each(&mut |r, c| t.intersect_counted(r, &mut hit_prim, c)),
            Tree::Four(t) => t.closest_hits(batch, ray, answer, hit_prim, counter),
            Tree::Eight(t) => t.closest_hits(batch, ray, answer, hit_prim, counter),
        }
    }

    /// Occlusion of the batch's rays on this thread, as [`Tree::closest_hits`].
    pub fn any_hits<R, A, F>(&self, batch: RayBatch, mut ray: R, mut answer: A, mut hit_prim: F)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool),
        F: FnMut(u32, &Ray) -> bool,
    {
        let mut each = |occluded: &mut dyn FnMut(&Ray) -> bool| {
            for i in 0..batch.count {
                answer(i, occluded(&ray(i)));
            }
        };
        match self {
            Tree::Binary(t) => each(&mut |r| t.occluded(r, &mut hit_prim)),
            Tree::Gpu(t) => each(&mut |r| t.occluded(r, &mut hit_prim)),
            Tree::Four(t) => t.any_hits(batch, ray, answer, hit_prim),
            Tree::Eight(t) => t.any_hits(batch, ray, answer, hit_prim),
        }
    }
}

/// A primitive test as the binary walks take it: whether primitive `prim` stops `ray`.
type PrimTest<'a> = dyn FnMut(u32, &Ray) -> bool + 'a;

/// An any-hit test that gives each hit to `found` and reports no blocker, so that an
/// any-hit walk visits every primitive along the ray.
fn reporting<F, P, H>(mut hit_prim: F, mut found: H) -> impl FnMut(u32, &Ray) -> bool
where
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
    H: FnMut(Hit, Option<[Vec3; 3]>),
{
    move |prim, ray| {
        if let Some(hit) = hit_prim(prim, ray) {
            found(hit.into_hit(prim), None);
        }
        false
    }
}
