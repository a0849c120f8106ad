use super::{max_abs, Surface, POINT_ERROR_ULPS};
use canopy_bvh::{Aabb, Ray};
use glam::Vec3;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub center: Vec3,
    pub radius: f32,
}

impl Sphere {
    pub fn new(center: Vec3, radius: f32) -> Self {
        Self { center, radius }
    }

    pub fn bounds(&self) -> Aabb {
        Aabb::new(self.center - self.radius, self.center + self.radius)
    }

    /// Ray/sphere roots computed the numerically careful way (Haines et al., "Precision
    /// Improvements for Ray/Sphere Intersection", Ray Tracing Gems, 2019): the
    /// discriminant from the distance of the centre to the ray's line, and the second
    /// root from the first (no catastrophic cancellation), so a small sphere far away or
    /// a huge sphere nearby (the ground ball of radius 1000) both stay precise.
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray) -> Option<f32> {
        let f = ray.origin - self.center;
        let d = ray.dir;
        let a = d.length_squared();
        let b = -f.dot(d);
        let to_line = f + (b / a) * d;
        let r2 = self.radius * self.radius;
        let discriminant = r2 - to_line.length_squared();
        if discriminant < 0.0 {
            return None;
        }
        let c = f.length_squared() - r2;
        let q = b + b.signum() * (a * discriminant).sqrt();
        let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (c / q, q / a) };
        let (near, far) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
        let in_range = |t: f32| t >= ray.t_min && t <= ray.t_max;
        if in_range(near) {
            Some(near)
        } else if in_range(far) {
            Some(far)
        } else {
            None
        }
    }

    pub fn surface(&self, ray: &Ray, t: f32) -> Surface {
        // Re-project onto the sphere: removes most of the error of o + t d.
        let offset = ray.at(t) - self.center;
        let normal = offset.normalize();
        let p = self.center + normal * self.radius;
        Surface {
            p,
            geometric_normal: normal,
            shading_normal: normal,
            error: POINT_ERROR_ULPS * (max_abs(self.center) + self.radius),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: Vec3, d: Vec3) -> Ray {
        Ray::new(o, d, 0.0, f32::INFINITY)
    }

    fn unit() -> Sphere {
        Sphere::new(Vec3::ZERO, 1.0)
    }

    #[test]
    fn head_on_hit_is_at_distance_minus_radius() {
        let t = unit().intersect(&ray(Vec3::new(0.0, 0.0, -5.0), Vec3::Z));
        assert_eq!(t, Some(4.0));
    }

    #[test]
    fn miss_to_the_side() {
        assert_eq!(
            unit().intersect(&ray(Vec3::new(2.0, 0.0, -5.0), Vec3::Z)),
            None
        );
    }

    #[test]
    fn grazing_ray_touches_once() {
        let t = unit()
            .intersect(&ray(Vec3::new(1.0, 0.0, -5.0), Vec3::Z))
            .unwrap();
        assert!((t - 5.0).abs() < 1e-5);
    }

    #[test]
    fn origin_inside_hits_the_far_side() {
        assert_eq!(unit().intersect(&ray(Vec3::ZERO, Vec3::X)), Some(1.0));
    }

    #[test]
    fn sphere_behind_the_origin_is_missed() {
        assert_eq!(
            unit().intersect(&ray(Vec3::new(0.0, 0.0, 5.0), Vec3::Z)),
            None
        );
    }

    #[test]
    fn t_range_limits_are_honoured() {
        let r = Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, 0.0, 3.9);
        assert_eq!(unit().intersect(&r), None);
        let r = Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, 4.5, f32::INFINITY);
        assert_eq!(unit().intersect(&r), Some(6.0));
    }

    #[test]
    fn unnormalised_direction_scales_t() {
        let t = unit().intersect(&ray(Vec3::new(0.0, 0.0, -5.0), 2.0 * Vec3::Z));
        assert_eq!(t, Some(2.0));
    }

    #[test]
    fn huge_sphere_is_hit_precisely_near_its_top() {
        // The report's ground ball: a ray straight down from just above the top.
        let ground = Sphere::new(Vec3::new(0.0, -1000.0, 0.0), 1000.0);
        let t = ground
            .intersect(&ray(Vec3::new(0.3, 0.5, 0.2), -Vec3::Y))
            .unwrap();
        assert!((t - 0.5).abs() < 1e-4, "t = {t}");
    }

    #[test]
    fn surface_normal_points_outwards_and_point_lies_on_sphere() {
        let r = ray(Vec3::new(0.0, 0.0, -5.0), Vec3::Z);
        let s = unit().surface(&r, 4.0);
        assert_eq!(s.geometric_normal, -Vec3::Z);
        assert!((s.p.length() - 1.0).abs() < 1e-6);
    }
}
