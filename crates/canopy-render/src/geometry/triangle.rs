use super::{area_to_solid_angle, max_abs, Surface, SurfaceSample, POINT_ERROR_ULPS};
use crate::sampling::uniform_triangle;
use canopy_bvh::{intersect_triangle, Aabb, PrimHit, Ray, ShearedRay};
use glam::{DVec3, Vec2, Vec3};

/// A triangle, stored as its three vertices exactly as the mesh gives them: triangles
/// that share an edge then share its end points bit for bit, which the watertight test
/// needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangle {
    pub v: [Vec3; 3],
    /// Index into the scene's vertex-normal triples, or [`Triangle::FLAT`].
    pub normals: u32,
}

impl Triangle {
    /// `normals` value of a flat-shaded triangle.
    pub const FLAT: u32 = u32::MAX;

    pub fn new(v0: Vec3, v1: Vec3, v2: Vec3) -> Self {
        Self {
            v: [v0, v1, v2],
            normals: Self::FLAT,
        }
    }

    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(self.v)
    }

    pub fn area(&self) -> f32 {
        0.5 * (self.v[1] - self.v[0])
            .cross(self.v[2] - self.v[0])
            .length()
    }

    fn normal(&self) -> Vec3 {
        (self.v[1] - self.v[0])
            .cross(self.v[2] - self.v[0])
            .normalize_or(Vec3::Y)
    }

    fn error(&self) -> f32 {
        POINT_ERROR_ULPS
            * max_abs(self.v[0])
                .max(max_abs(self.v[1]))
                .max(max_abs(self.v[2]))
    }

    /// A point uniform over the area (see [`crate::geometry::Shape::sample_toward`]).
    #[inline]
    pub fn sample_toward(&self, reference: Vec3, u: Vec2) -> Option<SurfaceSample> {
        let b = uniform_triangle(u);
        let p = b[0] * self.v[0] + b[1] * self.v[1] + b[2] * self.v[2];
        let normal = self.normal();
        SurfaceSample::by_area(self.area(), reference, p, normal, self.error())
    }

    pub fn pdf_toward(&self, reference: Vec3, p: Vec3, normal: Vec3) -> f32 {
        area_to_solid_angle(1.0 / self.area(), reference, p, normal).unwrap_or(0.0)
    }

    /// The hit of `ray` within its range: distance and the barycentric weights of
    /// vertices 1 and 2. Watertight (canopy-bvh's test, the one its triangle packs run).
    #[inline]
    pub fn hit(&self, ray: &Ray, sheared: &ShearedRay) -> Option<PrimHit> {
        intersect_triangle(&self.v, ray, sheared)
    }

    /// Hit distance, preparing the ray on the spot (for one-off tests; traversal prepares
    /// it once per ray).
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<f32> {
        self.hit(ray, &ShearedRay::new(ray)).map(|h| h.t)
    }

    /// The surface at the hit with barycentrics `(u, v)` (weights of vertices 1 and 2).
    #[inline]
    pub fn surface(&self, u: f32, v: f32, vertex_normals: &[[Vec3; 3]]) -> Surface {
        self.surface_with_normals(u, v, vertex_normals.get(self.normals as usize))
    }

    /// [`Triangle::surface`] with the vertex normals given (`None`: flat).
    #[inline]
    pub fn surface_with_normals(&self, u: f32, v: f32, normals: Option<&[Vec3; 3]>) -> Surface {
        // The point from the weights is far more precise than o + t d.
        let weights = [1.0 - u - v, u, v];
        let p = (0..3)
            .fold(DVec3::ZERO, |p, i| {
                p + weights[i] as f64 * self.v[i].as_dvec3()
            })
            .as_vec3();
        let geometric_normal = self.normal();
        let shading_normal = match normals {
            Some(n) => {
                let interpolated = (0..3)
                    .fold(Vec3::ZERO, |s, i| s + weights[i] * n[i])
                    .normalize_or(geometric_normal);
                if interpolated.dot(geometric_normal) < 0.0 {
                    -interpolated
                } else {
                    interpolated
                }
            }
            None => geometric_normal,
        };
        Surface {
            p,
            geometric_normal,
            shading_normal,
            error: self.error(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> Triangle {
        Triangle::new(Vec3::ZERO, Vec3::X, Vec3::Y)
    }

    fn ray(o: Vec3, d: Vec3) -> Ray {
        Ray::new(o, d, 0.0, f32::INFINITY)
    }

    #[test]
    fn hit_through_the_interior() {
        assert_eq!(
            tri().intersect(&ray(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z)),
            Some(1.0)
        );
    }

    #[test]
    fn back_side_is_hit_too() {
        assert_eq!(
            tri().intersect(&ray(Vec3::new(0.25, 0.25, -1.0), Vec3::Z)),
            Some(1.0)
        );
    }

    #[test]
    fn miss_outside_the_edges() {
        assert_eq!(
            tri().intersect(&ray(Vec3::new(0.75, 0.75, 1.0), -Vec3::Z)),
            None
        );
        assert_eq!(
            tri().intersect(&ray(Vec3::new(-0.1, 0.5, 1.0), -Vec3::Z)),
            None
        );
    }

    #[test]
    fn grazing_edge_and_vertex_hits_count() {
        // Exactly on the edge from (0,0) to (1,0), and exactly on a vertex.
        assert_eq!(
            tri().intersect(&ray(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z)),
            Some(1.0)
        );
        assert_eq!(
            tri().intersect(&ray(Vec3::new(1.0, 0.0, 1.0), -Vec3::Z)),
            Some(1.0)
        );
    }

    #[test]
    fn parallel_ray_misses() {
        assert_eq!(
            tri().intersect(&ray(Vec3::new(-1.0, 0.25, 0.0), Vec3::X)),
            None
        );
    }

    #[test]
    fn triangle_behind_the_origin_is_missed() {
        assert_eq!(
            tri().intersect(&ray(Vec3::new(0.25, 0.25, 1.0), Vec3::Z)),
            None
        );
    }

    #[test]
    fn t_range_limits_are_honoured() {
        let r = Ray::new(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z, 0.0, 0.5);
        assert_eq!(tri().intersect(&r), None);
    }

    #[test]
    fn degenerate_triangle_is_never_hit() {
        let flat = Triangle::new(Vec3::ZERO, Vec3::X, 2.0 * Vec3::X);
        assert_eq!(
            flat.intersect(&ray(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z)),
            None
        );
    }

    #[test]
    fn weights_locate_the_hit_point() {
        let r = ray(Vec3::new(0.2, 0.3, 2.0), -Vec3::Z);
        let h = tri().hit(&r, &ShearedRay::new(&r)).unwrap();
        assert_eq!(h.t, 2.0);
        let w = [1.0 - h.u - h.v, h.u, h.v];
        let p = w[0] * tri().v[0] + w[1] * tri().v[1] + w[2] * tri().v[2];
        assert!((p - Vec3::new(0.2, 0.3, 0.0)).length() < 1e-6);
    }

    #[test]
    fn smooth_normal_is_interpolated() {
        let mut t = tri();
        t.normals = 0;
        let normals = [[Vec3::Z, Vec3::new(1.0, 0.0, 1.0).normalize(), Vec3::Z]];
        let s = t.surface(0.5, 0.0, &normals);
        assert_eq!(s.geometric_normal, Vec3::Z);
        assert!(s.shading_normal.x > 0.1 && s.shading_normal.z > 0.5);
    }
}
