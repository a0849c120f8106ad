//! Geometry a bottom-level structure owns and tests: the [`Geometry`] trait (the role
//! the caller's closure plays for a bare tree) and [`TriangleMesh`], an indexed mesh
//! whose triangles a wide [`crate::Blas`] packs into its leaves.

use crate::{
    intersect_triangle, split_box, split_triangle, Aabb, KnownShape, PrimHit, Ray, ShearedRay,
};
use glam::Vec3;
use thiserror::Error;

/// Primitives a [`crate::Blas`] is built over and answers queries with.
///
/// A primitive that is a triangle ([`Geometry::triangle`]) is tested by canopy itself
/// where the tree packs triangles into its leaves (4- and 8-wide layouts); every other
/// primitive, and every primitive of a binary tree, goes through [`Geometry::intersect`].
pub trait Geometry: Sync {
    /// Number of primitives; they are numbered `0..len`.
    fn len(&self) -> usize;

    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bounding box of primitive `prim` (empty for one that can never be hit).
    fn bounds(&self, prim: u32) -> Aabb;

    /// The vertices of primitive `prim` if it is a triangle, in winding order.
    #[inline]
    fn triangle(&self, _prim: u32) -> Option<[Vec3; 3]> {
        None
    }

    /// Primitive `prim` as a shape whose test canopy knows (a sphere, an axis-aligned
    /// box), if its hit is that shape's: a wide tree then keeps it beside its leaves and
    /// tests it itself ([`crate::BvhN::store_shapes`]).
    #[inline]
    fn known_shape(&self, _prim: u32) -> Option<KnownShape> {
        None
    }

    /// Whether any primitive is a triangle: only then does a query prepare its ray for
    /// the triangle test ([`ShearedRay`]).
    fn has_triangles(&self) -> bool;

    /// The hit of `ray` on primitive `prim` within `[ray.t_min, ray.t_max]`. `sheared` is
    /// `ShearedRay::new(ray)` where the geometry has triangles, else
    /// [`ShearedRay::UNUSED`]; it depends on the direction only, so it stays valid as
    /// `t_max` shrinks during a query.
    fn intersect(&self, prim: u32, ray: &Ray, sheared: &ShearedRay) -> Option<PrimHit>;

    /// Whether `ray` hits primitive `prim` within its range (shadow rays).
    #[inline]
    fn occludes(&self, prim: u32, ray: &Ray, sheared: &ShearedRay) -> bool {
        self.intersect(prim, ray, sheared).is_some()
    }

    /// [`Geometry::intersect`] of a primitive that is not a triangle (the only kind a
    /// query's closure sees where triangles are packed or absent). Geometry that mixes
    /// kinds can keep its triangle test out of this path, which the traversal inlines.
    #[inline]
    fn intersect_other(&self, prim: u32, ray: &Ray) -> Option<PrimHit> {
        self.intersect(prim, ray, &ShearedRay::UNUSED)
    }

    /// [`Geometry::occludes`] of a primitive that is not a triangle.
    #[inline]
    fn occludes_other(&self, prim: u32, ray: &Ray) -> bool {
        self.intersect_other(prim, ray).is_some()
    }

    /// The part of `prim` inside `within` cut by the plane `point[axis] == position`, for
    /// builders with spatial splits (see [`crate::Clipper`]): triangles are clipped, any
    /// other primitive is cut as its box (conservative).
    fn split(&self, prim: u32, within: Aabb, axis: usize, position: f32) -> (Aabb, Aabb) {
        match self.triangle(prim) {
            Some(v) => split_triangle(v, within, axis, position),
            None => split_box(within, axis, position),
        }
    }
}

/// A triangle mesh stored once: vertices, and three vertex indices per triangle.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleMesh {
    vertices: Vec<Vec3>,
    indices: Vec<[u32; 3]>,
}

/// Why a mesh cannot be made.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum MeshError {
    #[error("vertex {vertex} is not finite ({position:?})")]
    NonFiniteVertex { vertex: usize, position: [f32; 3] },
    #[error("triangle {triangle} uses vertex {index}, but the mesh has {vertices} vertices")]
    IndexOutOfRange {
        triangle: usize,
        index: u32,
        vertices: usize,
    },
    #[error("the mesh has {found} vertices; its triangles need the {expected} it had")]
    VertexCountChanged { expected: usize, found: usize },
}

impl TriangleMesh {
    /// A mesh of `indices.len()` triangles over `vertices`. Refuses non-finite vertices
    /// and indices out of range, naming the first at fault.
    pub fn new(vertices: Vec<Vec3>, indices: Vec<[u32; 3]>) -> Result<Self, MeshError> {
        check_vertices(&vertices)?;
        if let Some((triangle, &index)) = indices.iter().enumerate().find_map(|(t, tri)| {
            tri.iter()
                .find(|&&i| i as usize >= vertices.len())
                .map(|i| (t, i))
        }) {
            return Err(MeshError::IndexOutOfRange {
                triangle,
                index,
                vertices: vertices.len(),
            });
        }
        Ok(Self { vertices, indices })
    }

    pub fn vertices(&self) -> &[Vec3] {
        &self.vertices
    }

    pub fn indices(&self) -> &[[u32; 3]] {
        &self.indices
    }

    /// The vertices of triangle `t`.
    #[inline(always)]
    pub fn vertices_of(&self, t: u32) -> [Vec3; 3] {
        let [a, b, c] = self.indices[t as usize];
        [
            self.vertices[a as usize],
            self.vertices[b as usize],
            self.vertices[c as usize],
        ]
    }

    /// Replaces the vertex positions (same count; the triangles keep their indices).
    /// Through [`crate::Blas::update`], which refits the tree to them.
    pub fn set_vertices(&mut self, vertices: Vec<Vec3>) -> Result<(), MeshError> {
        if vertices.len() != self.vertices.len() {
            return Err(MeshError::VertexCountChanged {
                expected: self.vertices.len(),
                found: vertices.len(),
            });
        }
        check_vertices(&vertices)?;
        self.vertices = vertices;
        Ok(())
    }

    /// Box of every triangle (vertices no triangle uses do not count).
    pub fn bounding_box(&self) -> Aabb {
        (0..self.indices.len() as u32).fold(Aabb::EMPTY, |b, t| b.union(Geometry::bounds(self, t)))
    }

    /// Bytes the mesh holds (vertices and indices).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.vertices.as_slice())
            + std::mem::size_of_val(self.indices.as_slice())
    }
}

fn check_vertices(vertices: &[Vec3]) -> Result<(), MeshError> {
    match vertices.iter().position(|v| !v.is_finite()) {
        Some(vertex) => Err(MeshError::NonFiniteVertex {
            vertex,
            position: vertices[vertex].to_array(),
        }),
        None => Ok(()),
    }
}

impl Geometry for TriangleMesh {
    fn len(&self) -> usize {
        self.indices.len()
    }

    fn bounds(&self, prim: u32) -> Aabb {
        Aabb::from_points(self.vertices_of(prim))
    }

    #[inline]
    fn triangle(&self, prim: u32) -> Option<[Vec3; 3]> {
        Some(self.vertices_of(prim))
    }

    fn has_triangles(&self) -> bool {
        !self.indices.is_empty()
    }

    #[inline]
    fn intersect(&self, prim: u32, ray: &Ray, sheared: &ShearedRay) -> Option<PrimHit> {
        intersect_triangle(&self.vertices_of(prim), ray, sheared)
    }
}

/// Axis-aligned boxes as primitives (hit where a ray enters them, or at `t_min` from
/// inside).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Boxes(pub Vec<Aabb>);

impl Geometry for Boxes {
    fn len(&self) -> usize {
        self.0.len()
    }

    fn bounds(&self, prim: u32) -> Aabb {
        self.0[prim as usize]
    }

    fn has_triangles(&self) -> bool {
        false
    }

    #[inline]
    fn intersect(&self, prim: u32, ray: &Ray, _: &ShearedRay) -> Option<PrimHit> {
        self.0[prim as usize].ray_entry(ray).map(PrimHit::from)
    }
}

/// Geometry shared with its owner elsewhere (a renderer's scene keeps the mesh for
/// shading while the structure tests it): no copy.
impl<G: Geometry + Send> Geometry for std::sync::Arc<G> {
    fn len(&self) -> usize {
        (**self).len()
    }

    fn bounds(&self, prim: u32) -> Aabb {
        (**self).bounds(prim)
    }

    #[inline]
    fn triangle(&self, prim: u32) -> Option<[Vec3; 3]> {
        (**self).triangle(prim)
    }

    fn has_triangles(&self) -> bool {
        (**self).has_triangles()
    }

    #[inline]
    fn intersect(&self, prim: u32, ray: &Ray, sheared: &ShearedRay) -> Option<PrimHit> {
        (**self).intersect(prim, ray, sheared)
    }

    #[inline]
    fn occludes(&self, prim: u32, ray: &Ray, sheared: &ShearedRay) -> bool {
        (**self).occludes(prim, ray, sheared)
    }

    #[inline]
    fn intersect_other(&self, prim: u32, ray: &Ray) -> Option<PrimHit> {
        (**self).intersect_other(prim, ray)
    }

    #[inline]
    fn occludes_other(&self, prim: u32, ray: &Ray) -> bool {
        (**self).occludes_other(prim, ray)
    }

    fn split(&self, prim: u32, within: Aabb, axis: usize, position: f32) -> (Aabb, Aabb) {
        (**self).split(prim, within, axis, position)
    }
}
