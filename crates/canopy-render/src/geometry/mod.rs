//! Shapes: sphere, triangle and cuboid, behind one primitive list.
//!
//! Each shape answers two questions: the hit distance along a ray (the hot path, called
//! from BVH traversal) and, for the one closest hit, the surface there.

mod cuboid;
mod sphere;
mod triangle;

pub use canopy_bvh::ShearedRay;
pub use cuboid::{Cuboid, Rectangle};
pub use sphere::Sphere;
pub use triangle::Triangle;

use canopy_bvh::{Aabb, Hit, PrimHit, Ray};
use glam::{Vec2, Vec3};

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

/// A point drawn on a shape's surface for a reference point that wants light from it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSample {
    pub p: Vec3,
    /// Unit outward normal at `p`.
    pub normal: Vec3,
    /// Bound on the rounding error of `p` (as [`Surface::error`]).
    pub error: f32,
    /// Density of the direction from the reference point to `p`, per unit solid angle.
    pub pdf: f32,
}

impl SurfaceSample {
    /// A point `p` (normal `normal`, rounding error `error`) drawn uniformly over a
    /// surface of `area`, with its density at `reference`; `None` where that is unbounded.
    pub(crate) fn by_area(
        area: f32,
        reference: Vec3,
        p: Vec3,
        normal: Vec3,
        error: f32,
    ) -> Option<Self> {
        let pdf = area_to_solid_angle(1.0 / area, reference, p, normal)?;
        Some(Self {
            p,
            normal,
            error,
            pdf,
        })
    }
}

/// Solid-angle density at `reference` of a point `p` (normal `normal`) drawn with density
/// `area_pdf` per unit area; `None` where it is unbounded (seen edge-on or from on it).
#[inline]
pub(crate) fn area_to_solid_angle(
    area_pdf: f32,
    reference: Vec3,
    p: Vec3,
    normal: Vec3,
) -> Option<f32> {
    let to_reference = reference - p;
    let distance_squared = to_reference.length_squared();
    let cos = normal.dot(to_reference).abs() / distance_squared.sqrt();
    let pdf = area_pdf * distance_squared / cos;
    (pdf.is_finite() && pdf > 0.0).then_some(pdf)
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
    #[inline(always)]
    pub fn surface(&self, ray: &Ray, hit: &Hit, vertex_normals: &[[Vec3; 3]]) -> Surface {
        match self {
            Shape::Sphere(s) => s.surface(ray, hit.t),
            Shape::Triangle(tri) => tri.surface(hit.u, hit.v, vertex_normals),
            Shape::Cuboid(c) => c.surface(ray, hit.t),
        }
    }

    /// Surface area (both sides of a flat shape count once).
    pub fn area(&self) -> f32 {
        match self {
            Shape::Sphere(s) => s.area(),
            Shape::Triangle(t) => t.area(),
            Shape::Cuboid(c) => c.area(),
        }
    }

    /// A point of the surface drawn from `u` in `[0, 1)²` for light arriving at
    /// `reference`: spheres by the cone of directions they subtend, triangles and cuboids
    /// uniformly by area. `None` when the point cannot carry light there (seen edge-on).
    #[inline(always)]
    pub fn sample_toward(&self, reference: Vec3, u: Vec2) -> Option<SurfaceSample> {
        match self {
            Shape::Sphere(s) => s.sample_toward(reference, u),
            Shape::Triangle(t) => t.sample_toward(reference, u),
            Shape::Cuboid(c) => c.sample_toward(reference, u),
        }
    }

    /// The density [`Shape::sample_toward`] has for the point `p` (normal `normal`) of this
    /// shape that a ray from `reference` hit first.
    pub fn pdf_toward(&self, reference: Vec3, p: Vec3, normal: Vec3) -> f32 {
        match self {
            Shape::Sphere(s) => s.pdf_toward(reference, p, normal),
            Shape::Triangle(t) => t.pdf_toward(reference, p, normal),
            Shape::Cuboid(c) => c.pdf_toward(reference, p, normal),
        }
    }

    /// Surface area inside `region` (for EPO, [`canopy_bvh::epo`]): exact for triangles
    /// and cuboids (their faces clipped to the box); `None` for spheres, whose clipped
    /// area has no closed form here.
    pub fn area_in_box(&self, region: &Aabb) -> Option<f32> {
        match self {
            Shape::Triangle(t) => Some(canopy_bvh::triangle_area_in_box(&t.v, region)),
            Shape::Cuboid(c) => Some(
                c.face_triangles()
                    .iter()
                    .map(|t| canopy_bvh::triangle_area_in_box(t, region))
                    .sum(),
            ),
            Shape::Sphere(_) => None,
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

#[cfg(test)]
mod sampling_tests {
    use super::*;
    use crate::rng::Rng;

    /// Solid angle of a triangle seen from the origin (Van Oosterom & Strackee 1983).
    fn triangle_solid_angle(a: Vec3, b: Vec3, c: Vec3) -> f32 {
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let numerator = a.dot(b.cross(c)).abs();
        let denominator = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
        2.0 * numerator.atan2(denominator)
    }

    /// Monte Carlo ∫ dω over the drawn points' directions, E[1 / pdf], and checks that
    /// every point lies on the shape and reports the density `pdf_toward` gives it.
    fn drawn_solid_angle(shape: &Shape, reference: Vec3) -> f32 {
        let mut rng = Rng::for_sample(5, 6, 7);
        let n = 200_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            let u = Vec2::new(rng.next_f32(), rng.next_f32());
            let Some(s) = shape.sample_toward(reference, u) else {
                continue;
            };
            let back = shape.pdf_toward(reference, s.p, s.normal);
            assert!((back - s.pdf).abs() <= 1e-3 * s.pdf, "{back} vs {}", s.pdf);
            let to_point = s.p - reference;
            let ray = Ray::new(reference, to_point, 0.0, 1.0 + 1e-4);
            // (At a grazing angle the ray may just miss by rounding.)
            let grazing = s.normal.dot(to_point.normalize()).abs() < 1e-2;
            assert!(
                grazing || shape.intersect(&ray).is_some(),
                "{:?} is not on the shape",
                s.p
            );
            sum += 1.0 / s.pdf as f64;
        }
        (sum / n as f64) as f32
    }

    #[test]
    fn sphere_cone_covers_exactly_the_sphere_seen() {
        for (radius, distance) in [(1.0, 3.0), (0.01, 50.0), (2.0, 2.1)] {
            let sphere = Shape::Sphere(Sphere::new(Vec3::new(0.0, 0.0, -distance), radius));
            let sin2 = (radius as f64 / distance as f64).powi(2);
            let cone = (std::f64::consts::TAU * (1.0 - (1.0 - sin2).sqrt())) as f32;
            let drawn = drawn_solid_angle(&sphere, Vec3::ZERO);
            assert!(
                (drawn / cone - 1.0).abs() < 1e-3,
                "r {radius}: {drawn} vs {cone}"
            );
        }
    }

    #[test]
    fn triangle_samples_cover_its_solid_angle() {
        let (a, b, c) = (
            Vec3::new(-1.0, -0.5, -2.0),
            Vec3::new(1.5, -0.2, -3.0),
            Vec3::new(0.1, 1.2, -1.5),
        );
        let drawn = drawn_solid_angle(&Shape::Triangle(Triangle::new(a, b, c)), Vec3::ZERO);
        let exact = triangle_solid_angle(a, b, c);
        assert!((drawn / exact - 1.0).abs() < 0.02, "{drawn} vs {exact}");
    }

    #[test]
    fn box_samples_cover_its_silhouette_twice_and_a_flat_box_once() {
        // A flat rectangle: two triangles' solid angle, drawn once.
        let corners = [
            Vec3::new(-1.0, 2.0, -1.0),
            Vec3::new(1.0, 2.0, -1.0),
            Vec3::new(1.0, 2.0, 1.0),
            Vec3::new(-1.0, 2.0, 1.0),
        ];
        let flat = Shape::Cuboid(Cuboid::axis_aligned(corners[0], corners[2]));
        let reference = Vec3::new(0.3, 0.0, 0.2);
        let exact = triangle_solid_angle(
            corners[0] - reference,
            corners[1] - reference,
            corners[2] - reference,
        ) + triangle_solid_angle(
            corners[0] - reference,
            corners[2] - reference,
            corners[3] - reference,
        );
        let drawn = drawn_solid_angle(&flat, reference);
        assert!((drawn / exact - 1.0).abs() < 0.02, "{drawn} vs {exact}");
        // A cube seen from afar covers about twice its face's solid angle (1/16).
        let far = Shape::Cuboid(Cuboid::axis_aligned(
            Vec3::new(-0.5, -0.5, -100.5),
            Vec3::new(0.5, 0.5, -99.5),
        ));
        let twice_face = 2.0 * 1.0 / (100.0f32 * 100.0);
        let drawn = drawn_solid_angle(&far, Vec3::ZERO);
        assert!(
            (drawn / twice_face - 1.0).abs() < 0.03,
            "{drawn} vs {twice_face}"
        );
    }
}
