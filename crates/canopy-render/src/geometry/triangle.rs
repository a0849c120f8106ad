use super::{max_abs, Surface, POINT_ERROR_ULPS};
use canopy_bvh::{Aabb, Ray};
use glam::Vec3;

/// A triangle, stored as one vertex and two edges for the intersection test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangle {
    pub p0: Vec3,
    pub e1: Vec3,
    pub e2: Vec3,
    /// Index into the scene's vertex-normal triples, or [`Triangle::FLAT`].
    pub normals: u32,
}

impl Triangle {
    /// `normals` value of a flat-shaded triangle.
    pub const FLAT: u32 = u32::MAX;

    pub fn new(p0: Vec3, p1: Vec3, p2: Vec3) -> Self {
        Self {
            p0,
            e1: p1 - p0,
            e2: p2 - p0,
            normals: Self::FLAT,
        }
    }

    pub fn vertices(&self) -> [Vec3; 3] {
        [self.p0, self.p0 + self.e1, self.p0 + self.e2]
    }

    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(self.vertices())
    }

    pub fn area(&self) -> f32 {
        0.5 * self.e1.cross(self.e2).length()
    }

    /// Distance and barycentrics (u, v of vertices 1 and 2) of the hit (Möller and
    /// Trumbore, "Fast, minimum storage ray-triangle intersection", 1997).
    #[inline]
    fn hit(&self, ray: &Ray) -> Option<(f32, f32, f32)> {
        let pvec = ray.dir.cross(self.e2);
        let det = self.e1.dot(pvec);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv_det = 1.0 / det;
        let tvec = ray.origin - self.p0;
        let u = tvec.dot(pvec) * inv_det;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let qvec = tvec.cross(self.e1);
        let v = ray.dir.dot(qvec) * inv_det;
        if v < 0.0 || u + v > 1.0 {
            return None;
        }
        let t = self.e2.dot(qvec) * inv_det;
        (t >= ray.t_min && t <= ray.t_max).then_some((t, u, v))
    }

    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<f32> {
        self.hit(ray).map(|(t, _, _)| t)
    }

    pub fn surface(&self, ray: &Ray, vertex_normals: &[[Vec3; 3]]) -> Surface {
        // Recompute the barycentrics for this one hit rather than carry them through
        // traversal; the point from barycentrics is far more precise than o + t d.
        let (_, u, v) = self.hit(ray).unwrap_or((0.0, 1.0 / 3.0, 1.0 / 3.0));
        let p = self.p0 + u * self.e1 + v * self.e2;
        let geometric_normal = self.e1.cross(self.e2).normalize_or(Vec3::Y);
        let shading_normal = match vertex_normals.get(self.normals as usize) {
            Some([n0, n1, n2]) => {
                let n = ((1.0 - u - v) * *n0 + u * *n1 + v * *n2).normalize_or(geometric_normal);
                if n.dot(geometric_normal) < 0.0 {
                    -n
                } else {
                    n
                }
            }
            None => geometric_normal,
        };
        let [a, b, c] = self.vertices();
        Surface {
            p,
            geometric_normal,
            shading_normal,
            error: POINT_ERROR_ULPS * max_abs(a).max(max_abs(b)).max(max_abs(c)),
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
    fn smooth_normal_is_interpolated() {
        let mut t = tri();
        t.normals = 0;
        let normals = [[Vec3::Z, Vec3::new(1.0, 0.0, 1.0).normalize(), Vec3::Z]];
        let s = t.surface(&ray(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z), &normals);
        assert_eq!(s.geometric_normal, Vec3::Z);
        assert!(s.shading_normal.x > 0.1 && s.shading_normal.z > 0.5);
    }
}
