//! Shapes: sphere, triangle and cuboid, behind one primitive list.
//!
//! Each shape answers two questions: the hit distance along a ray (the hot path, called
//! from BVH traversal) and, for the one closest hit, the surface there.

mod cuboid;
mod sphere;
mod triangle;

pub use cuboid::Cuboid;
pub use sphere::Sphere;
pub use triangle::{ShearedRay, Triangle};

use canopy_bvh::{Aabb, Ray};
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
    }

    /// [`Shape::intersect`] with the ray already prepared for triangle tests (once per
    /// ray, during traversal).
    #[inline]
    pub fn intersect_sheared(&self, ray: &Ray, sheared: &ShearedRay) -> Option<f32> {
        match self {
            Shape::Sphere(s) => s.intersect(ray),
            Shape::Triangle(t) => t.hit(ray, sheared).map(|(t, _)| t),
            Shape::Cuboid(c) => c.intersect(ray),
        }
    }

    /// The surface where `ray` hits this shape at distance `t` (from [`Shape::intersect`]).
    /// `vertex_normals` holds the per-vertex normals of smooth triangles.
    pub fn surface(&self, ray: &Ray, t: f32, vertex_normals: &[[Vec3; 3]]) -> Surface {
        match self {
            Shape::Sphere(s) => s.surface(ray, t),
            Shape::Triangle(tri) => tri.surface(ray, vertex_normals),
            Shape::Cuboid(c) => c.surface(ray, t),
        }
    }
}

/// Largest absolute coordinate.
#[inline]
pub(crate) fn max_abs(v: Vec3) -> f32 {
    v.abs().max_element()
}
