//! The acceleration structure a render uses: none (a loop over all primitives, the
//! report's baseline) or a BVH from any builder, binary or collapsed to 4 or 8 wide.

use crate::geometry::{Shape, ShearedRay};
use crate::scene::Primitive;
use canopy_bvh::{
    build_with_clipper, split_box, split_triangle, Aabb, BuildParams, Builder, BvhWidth, Clipper,
    Hit, OptimizeBudget, Ray, TraversalCounter, TraversalStats, Tree, PACK_LANES,
};
use rayon::prelude::*;
use std::fmt;
use std::str::FromStr;
use std::time::{Duration, Instant};

/// Which acceleration structure to build.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AccelKind {
    /// Test every primitive for every ray.
    None,
    Bvh(Builder),
}

impl Default for AccelKind {
    fn default() -> Self {
        AccelKind::Bvh(Builder::default())
    }
}

impl fmt::Display for AccelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AccelKind::None => f.write_str("none"),
            AccelKind::Bvh(b) => f.write_str(b.name()),
        }
    }
}

impl FromStr for AccelKind {
    type Err = canopy_bvh::UnknownBuilder;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s == "none" {
            return Ok(AccelKind::None);
        }
        s.parse::<Builder>().map(AccelKind::Bvh).map_err(|mut e| {
            e.known = format!("none, {}", e.known);
            e
        })
    }
}

/// A built acceleration structure over a scene's primitives.
#[derive(Clone, Debug)]
pub struct Accel {
    /// The tree in the layout asked for; `None` for brute force.
    tree: Option<Tree>,
    /// Whether any primitive is a triangle: only then does a query prepare the ray for
    /// triangle tests.
    has_triangles: bool,
    /// Wall-clock time of the build, collapse included.
    pub build_time: Duration,
}

/// Cuts primitives for builders with spatial splits (`sbvh`): triangles are clipped to
/// the plane, other shapes are cut as their boxes (conservative for spheres and turned
/// cuboids).
pub fn clipper(primitives: &[Primitive]) -> impl Clipper + '_ {
    move |prim: u32, within: Aabb, axis: usize, position: f32| match primitives[prim as usize]
        .shape
        .triangle_vertices()
    {
        Some(v) => split_triangle(v, within, axis, position),
        None => split_box(within, axis, position),
    }
}

/// A leaf of a packed tree with at most this many packs, unless the caller set the
/// leaf size.
pub const PACKED_LEAF_PACKS: u32 = 2;

/// The parameters a wide tree over triangles only is built with. Its leaves are tested a
/// pack of four triangles at a time, so where the caller left them at their defaults:
/// - leaves are priced in packs ([`BuildParams::leaf_block`] 1 becomes [`PACK_LANES`]):
///   a pack costs about one triangle test;
/// - leaves may hold two packs (`max_leaf_size` 4 becomes 8): one node level fewer to
///   fetch from memory, and the two packs lie side by side.
///
/// On the 202k dragon, incoherent rays in random order, one thread: leaves priced in packs
/// gave 25-45% more rays per second; two-pack leaves another 7-31% (closest hit) and
/// 16-18% (occlusion), measured in turns in one process (`examples/ray_speed.rs
/// --leaf 4,8`). Larger leaves (12, 16) gave no more.
pub fn packed_params(params: &BuildParams) -> BuildParams {
    let defaults = BuildParams::default();
    let lanes = PACK_LANES as u32;
    BuildParams {
        leaf_block: match params.leaf_block {
            1 => lanes,
            block => block,
        },
        max_leaf_size: match params.max_leaf_size {
            size if size == defaults.max_leaf_size => PACKED_LEAF_PACKS * lanes,
            size => size,
        },
        ..*params
    }
}

impl Accel {
    /// Builds the structure for `primitives`. A wide tree over triangles only is built
    /// for its triangle packs ([`packed_params`]); the image does not change: every tree
    /// gives the same closest hits.
    pub fn build(
        kind: AccelKind,
        width: BvhWidth,
        primitives: &[Primitive],
        params: &BuildParams,
    ) -> Self {
        Self::build_optimized(kind, width, primitives, params, None)
    }

    /// [`Accel::build`], the binary tree improved by reinsertion within `optimize`
    /// ([`canopy_bvh::optimize`]) before it is collapsed; the time is in `build_time`.
    pub fn build_optimized(
        kind: AccelKind,
        width: BvhWidth,
        primitives: &[Primitive],
        params: &BuildParams,
        optimize: Option<OptimizeBudget>,
    ) -> Self {
        let start = Instant::now();
        let AccelKind::Bvh(builder) = kind else {
            return Self {
                has_triangles: has_triangles(primitives),
                tree: None,
                build_time: start.elapsed(),
            };
        };
        let boxes: Vec<_> = primitives.par_iter().map(|p| p.shape.bounds()).collect();
        let packed = width != BvhWidth::Two
            && primitives
                .par_iter()
                .all(|p| matches!(p.shape, Shape::Triangle(_)));
        let params = if packed {
            packed_params(params)
        } else {
            *params
        };
        let mut bvh = build_with_clipper(builder, &boxes, &params, &clipper(primitives));
        if let Some(budget) = optimize {
            bvh = canopy_bvh::optimize(&bvh, &params.sah, budget).0;
        }
        let mut tree = Tree::new(bvh, width);
        tree.pack_triangles(|p| primitives[p as usize].shape.triangle_vertices());
        Self {
            has_triangles: has_triangles(primitives),
            tree: Some(tree),
            build_time: start.elapsed(),
        }
    }

    /// The tree, unless this is the brute-force structure.
    pub fn tree(&self) -> Option<&Tree> {
        self.tree.as_ref()
    }

    /// The work a closest-hit query does for `ray`: node visits and primitive tests.
    pub fn traversal_cost(&self, primitives: &[Primitive], ray: &Ray) -> TraversalStats {
        let mut work = TraversalStats::default();
        self.intersect_counted(primitives, ray, &mut work);
        work
    }

    /// Closest hit; ties go to the lower primitive index whatever the structure.
    #[inline]
    pub fn intersect(&self, primitives: &[Primitive], ray: &Ray) -> Option<Hit> {
        self.intersect_counted(primitives, ray, &mut ())
    }

    /// [`Accel::intersect`], reporting its work to `counter` (brute force counts one
    /// primitive test per primitive and no nodes).
    #[inline]
    pub fn intersect_counted<C: TraversalCounter>(
        &self,
        primitives: &[Primitive],
        ray: &Ray,
        counter: &mut C,
    ) -> Option<Hit> {
        // Trees with triangle packs test triangles themselves; the closure sees the rest.
        let test_other =
            |prim: u32, ray: &Ray| primitives[prim as usize].shape.intersect_non_triangle(ray);
        if let Some(tree) = self.tree_without_triangle_closure() {
            return tree.intersect_counted(ray, test_other, counter);
        }
        match &self.tree {
            Some(tree) => {
                // The shear depends on the direction only: it stays valid as t_max shrinks.
                let sheared = ShearedRay::new(ray);
                let test = |prim: u32, ray: &Ray| {
                    primitives[prim as usize]
                        .shape
                        .intersect_sheared(ray, &sheared)
                };
                tree.intersect_counted(ray, test, counter)
            }
            None => {
                for _ in primitives {
                    counter.test_primitive();
                }
                brute_force(primitives, ray, &self.shear(ray))
            }
        }
    }

    /// Whether anything blocks `ray` within its range (any hit, not the closest): the
    /// shadow-ray query.
    #[inline]
    pub fn occluded(&self, primitives: &[Primitive], ray: &Ray) -> bool {
        let test_other = |prim: u32, ray: &Ray| {
            primitives[prim as usize]
                .shape
                .intersect_non_triangle(ray)
                .is_some()
        };
        if let Some(tree) = self.tree_without_triangle_closure() {
            return tree.occluded(ray, test_other);
        }
        match &self.tree {
            Some(tree) => {
                let sheared = ShearedRay::new(ray);
                let test = |prim: u32, ray: &Ray| {
                    primitives[prim as usize]
                        .shape
                        .intersect_sheared(ray, &sheared)
                        .is_some()
                };
                tree.occluded(ray, test)
            }
            None => {
                let sheared = self.shear(ray);
                primitives
                    .iter()
                    .any(|p| p.shape.intersect_sheared(ray, &sheared).is_some())
            }
        }
    }

    /// Whether batches are best traced in the order of their rays' origins
    /// ([`Tree::orders_batches`]; see [`canopy_bvh::RayOrder`]).
    pub fn orders_batches(&self) -> bool {
        self.tree.as_ref().is_some_and(Tree::orders_batches)
    }

    /// Closest hits of rays `0..count` on this thread: `ray(i)` makes ray `i` and
    /// `answer(i, hit)` takes its hit, in order. The hits of [`Accel::intersect`]; a tree
    /// that tests its own triangles (or has none) chooses its layout and instruction set
    /// once for all the rays ([`Tree::intersect_each`]), the others go ray by ray.
    pub fn intersect_each(
        &self,
        primitives: &[Primitive],
        count: usize,
        mut ray: impl FnMut(usize) -> Ray,
        mut answer: impl FnMut(usize, Option<Hit>),
    ) {
        match self.tree_without_triangle_closure() {
            Some(tree) => {
                let test_other = |prim: u32, ray: &Ray| {
                    primitives[prim as usize].shape.intersect_non_triangle(ray)
                };
                tree.intersect_each(count, ray, answer, test_other)
            }
            None => (0..count).for_each(|i| answer(i, self.intersect(primitives, &ray(i)))),
        }
    }

    /// Occlusion of rays `0..count` on this thread, as [`Accel::intersect_each`].
    pub fn occluded_each(
        &self,
        primitives: &[Primitive],
        count: usize,
        mut ray: impl FnMut(usize) -> Ray,
        mut answer: impl FnMut(usize, bool),
    ) {
        match self.tree_without_triangle_closure() {
            Some(tree) => {
                let test_other = |prim: u32, ray: &Ray| {
                    primitives[prim as usize]
                        .shape
                        .intersect_non_triangle(ray)
                        .is_some()
                };
                tree.occluded_each(count, ray, answer, test_other)
            }
            None => (0..count).for_each(|i| answer(i, self.occluded(primitives, &ray(i)))),
        }
    }

    /// The tree, when no triangle reaches its closure: there are none, or the tree tests
    /// them itself from its packs. Its queries then need no sheared ray.
    #[inline]
    fn tree_without_triangle_closure(&self) -> Option<&Tree> {
        self.tree
            .as_ref()
            .filter(|tree| tree.has_triangle_packs() || !self.has_triangles)
    }

    /// The ray prepared for triangle tests, when there are triangles to test.
    #[inline]
    fn shear(&self, ray: &Ray) -> ShearedRay {
        if self.has_triangles {
            ShearedRay::new(ray)
        } else {
            ShearedRay::UNUSED
        }
    }
}

fn has_triangles(primitives: &[Primitive]) -> bool {
    primitives
        .iter()
        .any(|p| matches!(p.shape, Shape::Triangle(_)))
}

fn brute_force(primitives: &[Primitive], ray: &Ray, sheared: &ShearedRay) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    let mut ray = *ray;
    for (prim, p) in primitives.iter().enumerate() {
        if let Some(h) = p.shape.intersect_sheared(&ray, sheared) {
            let hit = Hit::new(prim as u32, h);
            if best.is_none_or(|b| hit.is_before(&b)) {
                ray.t_max = hit.t;
                best = Some(hit);
            }
        }
    }
    best
}
