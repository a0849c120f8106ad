//! [`Blas`]: a bottom-level structure that owns its primitives ([`Geometry`]) and its tree
//! in any layout, or none (a loop over every primitive, the baseline every tree is
//! checked against).

use crate::proximity::PointTree;
use crate::query::{Coherence, RayBatch, RayQuery};
use crate::{
    build_with_clipper, Aabb, BuildParams, Builder, BvhWidth, Geometry, Hit, KnownShape,
    OptimizeBudget, Ray, RefitError, ShearedRay, TraversalCounter, Tree, TriangleTest, PACK_LANES,
};
use rayon::prelude::*;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// How a [`Blas`] (or a [`crate::Tlas`]'s top tree) is built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlasParams {
    /// The builder; `None` builds no tree: queries loop over every primitive.
    pub builder: Option<Builder>,
    pub width: BvhWidth,
    pub build: BuildParams,
    /// Improve the binary tree by reinsertion ([`crate::optimize`]) before collapsing it.
    pub optimize: Option<OptimizeBudget>,
    /// How triangles are tested, by the tree's packs and by brute force alike.
    pub triangle_test: TriangleTest,
}

impl Default for BlasParams {
    fn default() -> Self {
        Self {
            builder: Some(Builder::default()),
            width: BvhWidth::default(),
            build: BuildParams::default(),
            optimize: None,
            triangle_test: TriangleTest::Watertight,
        }
    }
}

impl BlasParams {
    /// The default parameters with another builder (`None`: brute force) and width.
    pub fn new(builder: Option<Builder>, width: BvhWidth) -> Self {
        Self {
            builder,
            width,
            ..Self::default()
        }
    }
}

/// A leaf of a packed tree holds at most this many packs, unless the caller set the
/// leaf size.
pub const PACKED_LEAF_PACKS: u32 = 2;

/// The parameters a wide tree over mostly triangles ([`PACKED_SHARE`]) is built with.
/// Its leaves are tested a pack of four triangles at a time, so where the caller left
/// them at their defaults:
/// - leaves are priced in packs ([`BuildParams::leaf_block`] 1 becomes [`PACK_LANES`]):
///   a pack costs about one triangle test;
/// - leaves may hold two packs (`max_leaf_size` 4 becomes 8): one node level fewer to
///   fetch from memory, and the two packs lie side by side.
///
/// On the 202k dragon, incoherent rays in random order, one thread: leaves priced in packs
/// gave 25-45% more rays per second; two-pack leaves another 7-31% (closest hit) and
/// 16-18% (occlusion), measured in turns in one process (`examples/ray_speed.rs
/// --leaf 4,8` in canopy-render). Larger leaves (12, 16) gave no more.
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

/// Whether at least [`PACKED_SHARE`] of the primitives are triangles or spheres: a wide
/// tree over them is then built for packs ([`packed_params`]), whose lanes test four
/// triangles or four spheres at once. The other primitives (a floor box, a light) share
/// the packs' leaves and are tested one by one.
fn mostly_packable<G: Geometry>(geometry: &G) -> bool {
    let packable = (0..geometry.len() as u32)
        .into_par_iter()
        .filter(|&p| {
            geometry.triangle(p).is_some()
                || matches!(geometry.known_shape(p), Some(KnownShape::Sphere { .. }))
        })
        .count();
    packable > 0 && packable as f64 >= PACKED_SHARE * geometry.len() as f64
}

/// The share of triangles and spheres from which a wide tree is built for its packs: a
/// mesh with a floor and a light beside it is, the 3 spheres and 992 triangles of
/// `paper-3` too (3.5% faster to render than with leaves priced one primitive at a
/// time), and the report's field of spheres.
pub const PACKED_SHARE: f64 = 0.9;

/// A bottom-level acceleration structure: geometry and the tree over it.
#[derive(Clone, Debug)]
pub struct Blas<G> {
    geometry: G,
    /// `None`: brute force.
    tree: Option<Tree>,
    bounds: Aabb,
    /// Whether a query prepares its ray for triangle tests: there are triangles, and no
    /// triangle packs test them.
    shears: bool,
    /// Whether any primitive is a triangle (brute force then prepares its rays).
    triangles: bool,
    params: BlasParams,
    build_time: Duration,
    /// The tree laid out for point queries (nearest points, winding numbers), made at
    /// the first such query and dropped when the geometry changes.
    pub(crate) point_tree: OnceLock<PointTree>,
    /// Whether the triangles close up (see `is_closed` in the point queries), worked
    /// out at the first inside test and forgotten when the geometry changes.
    pub(crate) closed: OnceLock<bool>,
}

impl<G: Geometry> Blas<G> {
    /// Builds the structure over `geometry`. A wide tree over mostly triangles is built
    /// for its triangle packs ([`packed_params`]); every tree gives the same closest hits.
    pub fn build(geometry: G, params: &BlasParams) -> Self {
        let mut blas = Self {
            geometry,
            tree: None,
            bounds: Aabb::EMPTY,
            shears: false,
            triangles: false,
            params: *params,
            build_time: Duration::ZERO,
            point_tree: OnceLock::new(),
            closed: OnceLock::new(),
        };
        blas.rebuild();
        blas
    }

    /// Builds the tree again over the geometry as it is now.
    fn rebuild(&mut self) {
        let start = Instant::now();
        self.point_tree = OnceLock::new();
        self.closed = OnceLock::new();
        let (geometry, params) = (&self.geometry, &self.params);
        let boxes = boxes_of(geometry);
        self.bounds = union_of(&boxes);
        self.tree = params.builder.map(|builder| {
            let packed = params.width != BvhWidth::Two && mostly_packable(geometry);
            let build = match packed {
                true => packed_params(&params.build),
                false => params.build,
            };
            let clipper = |p: u32, within: Aabb, axis: usize, position: f32| {
                geometry.split(p, within, axis, position)
            };
            let mut bvh = build_with_clipper(builder, &boxes, &build, &clipper);
            if let Some(budget) = params.optimize {
                bvh = crate::optimize(&bvh, &build.sah, budget).0;
            }
            let mut tree = Tree::new(bvh, params.width);
            match packed {
                true => tree.pack_leaves(|p| geometry.triangle(p)),
                false => tree.pack_triangles(|p| geometry.triangle(p)),
            }
            tree.store_shapes(|p| geometry.known_shape(p));
            tree.set_triangle_test(params.triangle_test);
            tree
        });
        self.triangles = geometry.has_triangles();
        self.shears = self.triangles && !self.tree.as_ref().is_some_and(Tree::has_triangle_packs);
        self.build_time = start.elapsed();
    }

    pub fn geometry(&self) -> &G {
        &self.geometry
    }

    pub fn into_geometry(self) -> G {
        self.geometry
    }

    /// The tree, unless this is the brute-force structure.
    pub fn tree(&self) -> Option<&Tree> {
        self.tree.as_ref()
    }

    /// Mutable access to the tree's settings that keep its answers (the kernels,
    /// [`Tree::set_isa`]); `None` for brute force.
    pub fn tree_mut(&mut self) -> Option<&mut Tree> {
        self.tree.as_mut()
    }

    /// The mode triangles are tested in.
    pub fn triangle_test(&self) -> TriangleTest {
        self.params.triangle_test
    }

    /// Tests triangles in mode `test` from now on, in the tree's packs and in the
    /// geometry's own tests alike (see [`BlasParams::triangle_test`]).
    pub fn set_triangle_test(&mut self, test: TriangleTest) {
        self.params.triangle_test = test;
        if let Some(tree) = &mut self.tree {
            tree.set_triangle_test(test);
        }
    }

    /// Wall-clock time of the build (boxes, builder, optimiser, collapse, packs).
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Edits the geometry in place (moving vertices, say) and refits the tree to it: the
    /// same topology, every box recomputed, the triangle packs rewritten (an edit that
    /// changes the number of primitives rebuilds it instead). Refused before `edit` runs
    /// where the tree has spatial splits, whose leaf boxes are parts of primitives.
    pub fn update(&mut self, edit: impl FnOnce(&mut G)) -> Result<(), RefitError> {
        if self
            .tree
            .as_ref()
            .is_some_and(|t| t.view().has_spatial_splits())
        {
            return Err(RefitError::SpatialSplits);
        }
        let count = self.geometry.len();
        edit(&mut self.geometry);
        if self.geometry.len() != count {
            self.rebuild();
            return Ok(());
        }
        self.point_tree = OnceLock::new();
        self.closed = OnceLock::new();
        let boxes = boxes_of(&self.geometry);
        self.bounds = union_of(&boxes);
        if let Some(tree) = &mut self.tree {
            let geometry = &self.geometry;
            tree.refit(&boxes, |p| geometry.triangle(p))?;
            tree.store_shapes(|p| geometry.known_shape(p));
        }
        Ok(())
    }

    /// Closest hit, reporting work to `counter`.
    #[inline(always)]
    fn closest<C: TraversalCounter>(&self, ray: &Ray, counter: &mut C) -> Option<Hit> {
        let g = &self.geometry;
        match (&self.tree, self.shears) {
            (Some(tree), false) => {
                tree.intersect_counted(ray, |p, r| g.intersect_other(p, r), counter)
            }
            (Some(tree), true) => {
                // The shear depends on the direction only: valid as t_max shrinks.
                let sheared = self.shear(ray);
                tree.intersect_counted(ray, |p, r| g.intersect(p, r, &sheared), counter)
            }
            (None, _) => brute_force_closest(g, ray, &self.sheared(ray), counter),
        }
    }

    #[inline(always)]
    fn any(&self, ray: &Ray) -> bool {
        let g = &self.geometry;
        match (&self.tree, self.shears) {
            (Some(tree), false) => tree.occluded(ray, |p, r| g.occludes_other(p, r)),
            (Some(tree), true) => {
                let sheared = self.shear(ray);
                tree.occluded(ray, |p, r| g.occludes(p, r, &sheared))
            }
            (None, _) => {
                let sheared = self.sheared(ray);
                ray.is_traceable() && (0..g.len() as u32).any(|p| g.occludes(p, ray, &sheared))
            }
        }
    }

    /// The ray prepared for the triangle tests of brute force, if it makes any.
    #[inline(always)]
    fn sheared(&self, ray: &Ray) -> ShearedRay {
        match self.triangles {
            true => self.shear(ray),
            false => ShearedRay::UNUSED,
        }
    }

    /// The ray prepared for triangle tests in this structure's mode.
    #[inline(always)]
    fn shear(&self, ray: &Ray) -> ShearedRay {
        ShearedRay::with_test(ray, self.params.triangle_test)
    }

    /// The tree, where one closure serves every ray (no per-ray preparation).
    #[inline(always)]
    fn tree_for_each(&self) -> Option<&Tree> {
        self.tree.as_ref().filter(|_| !self.shears)
    }
}

fn union_of(boxes: &[Aabb]) -> Aabb {
    boxes
        .par_iter()
        .copied()
        .reduce(|| Aabb::EMPTY, Aabb::union)
}

fn boxes_of<G: Geometry>(geometry: &G) -> Vec<Aabb> {
    (0..geometry.len() as u32)
        .into_par_iter()
        .map(|p| geometry.bounds(p))
        .collect()
}

/// The closest hit by a loop over every primitive (ties to the lower index).
fn brute_force_closest<G: Geometry, C: TraversalCounter>(
    geometry: &G,
    ray: &Ray,
    sheared: &ShearedRay,
    counter: &mut C,
) -> Option<Hit> {
    if !ray.is_traceable() {
        return None;
    }
    let mut best: Option<Hit> = None;
    let mut ray = *ray;
    for prim in 0..geometry.len() as u32 {
        counter.test_primitive();
        if let Some(h) = geometry.intersect(prim, &ray, sheared) {
            let hit = Hit::new(prim, h);
            if best.is_none_or(|b| hit.is_before(&b)) {
                ray.t_max = hit.t;
                best = Some(hit);
            }
        }
    }
    best
}

impl<G: Geometry> RayQuery for Blas<G> {
    fn bounds(&self) -> Aabb {
        self.bounds
    }

    // Inlined where it may be: a top-level tree tests its instances through this, one
    // ray at a time, from inside its own walk. Either way it is compiled once for each
    // geometry and counter, not for each caller's closures (see `RayQuery`).
    #[inline]
    fn closest_hits_into<C: TraversalCounter>(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        _mask: u32,
        coherence: Coherence,
        counter: &mut C,
    ) {
        assert_eq!(rays.len(), hits.len(), "one hit slot per ray");
        let g = &self.geometry;
        match self.tree_for_each() {
            Some(tree) => {
                let batch = RayBatch::new(rays.len()).with(coherence);
                let (ray, answer) = (|i: usize| rays[i], |i: usize, h| hits[i] = h);
                tree.closest_hits(batch, ray, answer, |p, r| g.intersect_other(p, r), counter)
            }
            None => {
                for (ray, hit) in rays.iter().zip(hits) {
                    *hit = self.closest(ray, counter);
                }
            }
        }
    }

    #[inline]
    fn any_hits_into(&self, rays: &[Ray], blocked: &mut [bool], _mask: u32, coherence: Coherence) {
        assert_eq!(rays.len(), blocked.len(), "one answer per ray");
        let g = &self.geometry;
        match self.tree_for_each() {
            Some(tree) => {
                let batch = RayBatch::new(rays.len()).with(coherence);
                let (ray, answer) = (|i: usize| rays[i], |i: usize, b| blocked[i] = b);
                tree.any_hits(batch, ray, answer, |p, r| g.occludes_other(p, r))
            }
            None => {
                for (ray, b) in rays.iter().zip(blocked) {
                    *b = self.any(ray);
                }
            }
        }
    }

    fn orders_batches(&self) -> bool {
        self.tree.as_ref().is_some_and(Tree::orders_batches)
    }
}
