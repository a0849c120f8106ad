//! The acceleration structure a render uses: the scene's own primitives in one
//! bottom-level structure, each mesh in one of its own, and a top-level structure over
//! their instances. Each is none (a loop over all primitives, the report's baseline) or
//! a BVH from any builder, binary or collapsed to 4 or 8 wide.

use crate::geometry::{Shape, ShearedRay};
use crate::scene::{Primitive, Scene};
use canopy_bvh::{
    split_box, split_triangle, Aabb, Blas, BlasParams, BuildParams, Builder, BvhWidth, Clipper,
    Coherence, Forward, Geometry, Hit, Instance, KnownShape, OptimizeBudget, PrimHit, Ray,
    RayQuery, RefitError, Tlas, TraversalCounter, Tree, TriangleMesh, TriangleTest,
};
use glam::{Affine3A, Vec3};
use std::fmt;
use std::str::FromStr;
use std::sync::Arc;
use std::time::{Duration, Instant};

pub use canopy_bvh::{packed_params, PACKED_LEAF_PACKS};

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

/// A scene's primitives as geometry a structure shares with the scene: spheres and
/// cuboids tested here, triangles packed into wide leaves (or tested here in binary
/// trees).
#[derive(Clone, Debug, Default)]
pub struct ShapeList(pub Arc<Vec<Primitive>>);

impl Geometry for ShapeList {
    fn len(&self) -> usize {
        self.0.len()
    }

    fn bounds(&self, prim: u32) -> Aabb {
        self.0[prim as usize].shape.bounds()
    }

    #[inline]
    fn triangle(&self, prim: u32) -> Option<[Vec3; 3]> {
        self.0[prim as usize].shape.triangle_vertices()
    }

    #[inline]
    fn known_shape(&self, prim: u32) -> Option<KnownShape> {
        match &self.0[prim as usize].shape {
            Shape::Sphere(s) => Some(KnownShape::Sphere {
                center: s.center,
                radius: s.radius,
            }),
            Shape::Cuboid(c) => c.as_known_shape(),
            Shape::Triangle(_) => None,
        }
    }

    fn has_triangles(&self) -> bool {
        self.0.iter().any(|p| matches!(p.shape, Shape::Triangle(_)))
    }

    #[inline]
    fn intersect(&self, prim: u32, ray: &Ray, sheared: &ShearedRay) -> Option<PrimHit> {
        self.0[prim as usize].shape.intersect_sheared(ray, sheared)
    }

    #[inline(always)]
    fn intersect_other(&self, prim: u32, ray: &Ray) -> Option<PrimHit> {
        self.0[prim as usize].shape.intersect_non_triangle(ray)
    }
}

/// A bottom-level structure of a scene: its own shapes, or one of its meshes.
#[derive(Clone, Debug)]
pub enum SceneBlas {
    Shapes(Blas<ShapeList>),
    Mesh(Blas<Arc<TriangleMesh>>),
}

macro_rules! each_blas {
    ($self:expr, $blas:ident => $body:expr) => {
        match $self {
            SceneBlas::Shapes($blas) => $body,
            SceneBlas::Mesh($blas) => $body,
        }
    };
}

impl SceneBlas {
    pub fn tree(&self) -> Option<&Tree> {
        each_blas!(self, b => b.tree())
    }

    /// See [`Blas::set_triangle_test`].
    pub fn set_triangle_test(&mut self, test: TriangleTest) {
        each_blas!(self, b => b.set_triangle_test(test))
    }

    /// See [`Blas::triangle_test`].
    pub fn triangle_test(&self) -> TriangleTest {
        each_blas!(self, b => b.triangle_test())
    }
}

impl RayQuery for SceneBlas {
    fn bounds(&self) -> Aabb {
        each_blas!(self, b => b.bounds())
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
        each_blas!(self, b => b.closest_hits_into(rays, hits, mask, coherence, counter))
    }

    #[inline]
    fn any_hits_into(&self, rays: &[Ray], blocked: &mut [bool], mask: u32, coherence: Coherence) {
        each_blas!(self, b => b.any_hits_into(rays, blocked, mask, coherence))
    }

    fn orders_batches(&self) -> bool {
        each_blas!(self, b => b.orders_batches())
    }
}

/// The built structure over a scene: its primitives (instance 0, the identity) and its
/// mesh instances (instance `k + 1` places [`Scene::instances`]`[k]`). A scene without
/// mesh instances is traced by the primitives' structure alone, at no extra cost.
#[derive(Clone, Debug)]
pub struct Accel {
    world: Tlas<SceneBlas>,
    /// Wall-clock time of the build: every structure, collapse included.
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

impl Accel {
    /// Builds the structure for `primitives` alone. A wide tree over mostly triangles is
    /// built for its triangle packs ([`packed_params`]); the image does not change:
    /// every tree gives the same closest hits.
    pub fn build(
        kind: AccelKind,
        width: BvhWidth,
        primitives: &Arc<Vec<Primitive>>,
        params: &BuildParams,
    ) -> Self {
        Self::build_optimized(kind, width, primitives, params, None)
    }

    /// [`Accel::build`], the binary tree improved by reinsertion within `optimize`
    /// ([`canopy_bvh::optimize`]) before it is collapsed; the time is in `build_time`.
    pub fn build_optimized(
        kind: AccelKind,
        width: BvhWidth,
        primitives: &Arc<Vec<Primitive>>,
        params: &BuildParams,
        optimize: Option<OptimizeBudget>,
    ) -> Self {
        Self::build_all(kind, width, primitives, &[], &[], params, optimize)
    }

    /// [`Accel::for_scene`] with every choice at its default: the default builder, 8
    /// wide, default parameters, no optimisation (what a render builds unless told).
    pub fn default_for(scene: &Scene) -> Self {
        Self::for_scene(
            scene,
            AccelKind::default(),
            BvhWidth::default(),
            &BuildParams::default(),
            None,
        )
    }

    /// The structure of a whole scene: its primitives and its mesh instances, every
    /// structure built by `kind` in `width`.
    pub fn for_scene(
        scene: &Scene,
        kind: AccelKind,
        width: BvhWidth,
        params: &BuildParams,
        optimize: Option<OptimizeBudget>,
    ) -> Self {
        let meshes: Vec<Arc<TriangleMesh>> = scene.meshes.iter().map(|m| m.mesh.clone()).collect();
        let placed: Vec<(u32, Affine3A)> = scene
            .instances
            .iter()
            .map(|i| (i.mesh, i.to_world))
            .collect();
        Self::build_all(
            kind,
            width,
            &scene.primitives,
            &meshes,
            &placed,
            params,
            optimize,
        )
    }

    fn build_all(
        kind: AccelKind,
        width: BvhWidth,
        primitives: &Arc<Vec<Primitive>>,
        meshes: &[Arc<TriangleMesh>],
        placed: &[(u32, Affine3A)],
        params: &BuildParams,
        optimize: Option<OptimizeBudget>,
    ) -> Self {
        let start = Instant::now();
        let builder = match kind {
            AccelKind::None => None,
            AccelKind::Bvh(builder) => Some(builder),
        };
        let blas_params = BlasParams {
            builder,
            width,
            build: *params,
            optimize,
            triangle_test: TriangleTest::Watertight,
        };
        let shapes = ShapeList(primitives.clone());
        let mut blases = vec![SceneBlas::Shapes(Blas::build(shapes, &blas_params))];
        blases.extend(
            meshes
                .iter()
                .map(|m| SceneBlas::Mesh(Blas::build(m.clone(), &blas_params))),
        );
        let mut instances = vec![Instance::new(0, Affine3A::IDENTITY)];
        instances.extend(
            placed
                .iter()
                .map(|&(mesh, to_world)| Instance::new(mesh + 1, to_world)),
        );
        let top = BlasParams {
            optimize: None,
            ..blas_params
        };
        let world = Tlas::build(blases, instances, &top)
            .expect("scene instances are checked when the scene is made");
        Self {
            world,
            build_time: start.elapsed(),
        }
    }

    /// Tests every structure's triangles in mode `test` ([`TriangleTest`]; watertight
    /// unless set). Images differ only where rays pass within rounding of an edge.
    pub fn with_triangle_test(mut self, test: TriangleTest) -> Self {
        self.world.edit_blases(|b| b.set_triangle_test(test));
        self
    }

    /// Edits the scene's own primitives in place (moving them, say) and refits their
    /// tree to them: the topology kept, every box recomputed, the triangle packs
    /// rewritten; then the top tree is built again. Refused, before `edit` runs, for a
    /// tree with spatial splits ([`Blas::update`]).
    pub fn update_primitives(
        &mut self,
        edit: impl FnOnce(&mut [Primitive]),
    ) -> Result<(), RefitError> {
        let mut edit = Some(edit);
        let mut updated = Ok(());
        self.world.edit_blases(|blas| match blas {
            // The scene's own primitives: the one `Shapes` structure.
            SceneBlas::Shapes(blas) => {
                if let Some(edit) = edit.take() {
                    updated =
                        blas.update(|shapes| edit(Arc::make_mut(&mut shapes.0).as_mut_slice()));
                }
            }
            SceneBlas::Mesh(_) => {}
        });
        updated
    }

    /// The mode triangles are tested in.
    pub fn triangle_test(&self) -> TriangleTest {
        self.world.blases()[0].triangle_test()
    }

    /// The tree over the scene's own primitives, unless this is brute force.
    pub fn tree(&self) -> Option<&Tree> {
        self.world.blases()[0].tree()
    }

    /// The scene's own primitives, as the structure holds them.
    pub fn primitives(&self) -> &[Primitive] {
        match &self.world.blases()[0] {
            SceneBlas::Shapes(blas) => &blas.geometry().0,
            SceneBlas::Mesh(_) => unreachable!("structure 0 holds the scene's primitives"),
        }
    }

    /// Every structure: the primitives', each mesh's, and the top one over instances.
    pub fn world(&self) -> &Tlas<SceneBlas> {
        &self.world
    }
}

/// The structure answers as its world, the top tree over every structure.
impl Forward for Accel {
    type Target = Tlas<SceneBlas>;

    #[inline]
    fn target(&self) -> &Tlas<SceneBlas> {
        &self.world
    }
}
