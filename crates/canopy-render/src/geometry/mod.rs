//! Shapes: sphere, triangle and cuboid, behind one primitive list.
//!
//! Each shape answers two questions: the hit distance along a ray (the hot path, called
//! from BVH traversal) and, for the one closest hit, the surface there.

mod cuboid;
mod sphere;
mod triangle;

pub use canopy_bvh::ShearedRay;
pub use cuboid::Cuboid;
pub use sphere::Sphere;
pub use triangle::Triangle;

use canopy_bvh::{Aabb, Hit, PrimHit, Ray};
use glam::Vec3;

/// The local geometry at a hit point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    pub p: Vec3,
    /// Unit normal of the true surface, pointing outwards (for triangles: by winding).
    pub geometric_normal: Vec3,
    /// Unit normal used for shading (interpolated vertex normals for smooth meshes),
    /// flipped into the geometric normal's hemisphere.
    pub shading_normal: Vec3,
    /// Bound on the rounding error of `p` along any axis; secondary rays start this far
    /// off the surface so they cannot hit it again by accident.
    pub error: f32,
}

/// Relative rounding-error allowance for computed hit points (a few dozen ulps).
pub(crate) const POINT_ERROR_ULPS: f32 = 16.0 * f32::EPSILON;

/// One primitive of a scene's geometry.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    Sphere(Sphere),
    Triangle(Triangle),
    Cuboid(Cuboid),
}

impl Shape {
    pub fn bounds(&self) -> Aabb {
        match self {
            Shape::Sphere(s) => s.bounds(),
            Shape::Triangle(t) => t.bounds(),
            Shape::Cuboid(c) => c.bounds(),
        }
    }

    /// Hit distance in `[ray.t_min, ray.t_max]`, if any.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<f32> {
        self.intersect_sheared(ray, &ShearedRay::new(ray))
            .map(|h| h.t)
    }

    /// [`Shape::intersect`] with the ray already prepared for triangle tests (once per
    /// ray, during traversal).
    #[inline]
    pub fn intersect_sheared(&self, ray: &Ray, sheared: &ShearedRay) -> Option<PrimHit> {
        match self {
            Shape::Sphere(s) => s.intersect(ray).map(PrimHit::from),
            Shape::Triangle(t) => t.hit(ray, sheared),
            Shape::Cuboid(c) => c.intersect(ray).map(PrimHit::from),
        }
    }

    /// [`Shape::intersect_sheared`] for queries whose triangles are tested elsewhere (in a
    /// wide tree's triangle packs): spheres and cuboids inline, a triangle (never expected
    /// here) prepares its own ray.
    #[inline(always)]
    pub fn intersect_non_triangle(&self, ray: &Ray) -> Option<PrimHit> {
        match self {
            Shape::Sphere(s) => s.intersect(ray).map(PrimHit::from),
            Shape::Cuboid(c) => c.intersect(ray).map(PrimHit::from),
            Shape::Triangle(t) => cold_triangle_hit(t, ray),
        }
    }

    /// The surface where `ray` hits this shape (`hit` from a query of `ray`; triangles use
    /// its barycentrics, other shapes its distance). `vertex_normals` holds the per-vertex
    /// normals of smooth triangles.
    pub fn surface(&self, ray: &Ray, hit: &Hit, vertex_normals: &[[Vec3; 3]]) -> Surface {
        match self {
            Shape::Sphere(s) => s.surface(ray, hit.t),
            Shape::Triangle(tri) => tri.surface(hit.u, hit.v, vertex_normals),
            Shape::Cuboid(c) => c.surface(ray, hit.t),
        }
    }

    /// The vertices of a triangle; `None` for other shapes.
    #[inline]
    pub fn triangle_vertices(&self) -> Option<[Vec3; 3]> {
        match self {
            Shape::Triangle(t) => Some(t.v),
            _ => None,
        }
    }
}

#[cold]
#[inline(never)]
fn cold_triangle_hit(t: &Triangle, ray: &Ray) -> Option<PrimHit> {
    t.hit(ray, &ShearedRay::new(ray))
}

/// Largest absolute coordinate.
#[inline]
pub(crate) fn max_abs(v: Vec3) -> f32 {
    v.abs().max_element()
}
