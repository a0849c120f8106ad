use super::{area_to_solid_angle, max_abs, Surface, SurfaceSample, POINT_ERROR_ULPS};
use crate::sampling::{spherical_direction, uniform_sphere, Frame};
use canopy_bvh::{Aabb, Ray};
use glam::{Vec2, Vec3};
use std::f32::consts::{PI, TAU};

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

    /// The nearer hit within the ray's range, else the farther
    /// ([`canopy_bvh::intersect_sphere`], precise for small far spheres and huge near
    /// ones; wide trees test spheres with it too).
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray) -> Option<f32> {
        canopy_bvh::intersect_sphere(self.center, self.radius, ray)
    }

    pub fn area(&self) -> f32 {
        4.0 * PI * self.radius * self.radius
    }

    fn error(&self) -> f32 {
        POINT_ERROR_ULPS * (max_abs(self.center) + self.radius)
    }

    /// From outside, a direction uniform in the cone the sphere subtends and the point
    /// where it meets the sphere first (pbrt-v4's construction, precise for small and far
    /// spheres); from inside, a point uniform over the area.
    #[inline]
    pub fn sample_toward(&self, reference: Vec3, u: Vec2) -> Option<SurfaceSample> {
        let Some(cone) = Cone::of(self, reference) else {
            let normal = uniform_sphere(u);
            let p = self.center + self.radius * normal;
            return SurfaceSample::by_area(self.area(), reference, p, normal, self.error());
        };
        // The angle θ from the axis to the drawn direction, then the angle α at the
        // centre between the axis and the point where that direction meets the sphere.
        let (sin2_theta, cos_theta) = if cone.sin2_max < SMALL_CONE_SIN2 {
            // 1 - cos θ underflows: use sin² θ directly (its Taylor expansion).
            let sin2 = cone.sin2_max * u.x;
            (sin2, (1.0 - sin2).sqrt())
        } else {
            let cos = (cone.cos_max - 1.0) * u.x + 1.0;
            (1.0 - cos * cos, cos)
        };
        let cos_alpha = sin2_theta / cone.sin_max
            + cos_theta * (1.0 - sin2_theta / cone.sin2_max).max(0.0).sqrt();
        let sin_alpha = (1.0 - cos_alpha * cos_alpha).max(0.0).sqrt();
        // The frame's z points from the reference to the centre; the normal faces back.
        let frame = Frame::from_z((self.center - reference) / cone.distance);
        let normal = -frame.to_world(spherical_direction(sin_alpha, cos_alpha, TAU * u.y));
        Some(SurfaceSample {
            p: self.center + self.radius * normal,
            normal,
            error: self.error(),
            pdf: cone.pdf(),
        })
    }

    pub fn pdf_toward(&self, reference: Vec3, p: Vec3, normal: Vec3) -> f32 {
        match Cone::of(self, reference) {
            Some(cone) => cone.pdf(),
            None => area_to_solid_angle(1.0 / self.area(), reference, p, normal).unwrap_or(0.0),
        }
    }

    #[inline]
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

/// Below this sin² of the cone's half-angle, 1 - cos is computed from sin² (pbrt-v4's
/// threshold, about 1.5 degrees).
const SMALL_CONE_SIN2: f32 = 0.000_685_23;

/// The cone of directions in which a sphere is seen from a point outside it.
struct Cone {
    distance: f32,
    sin2_max: f32,
    sin_max: f32,
    cos_max: f32,
    /// 1 - cos of the half-angle: the cone's solid angle over 2π.
    one_minus_cos_max: f32,
}

impl Cone {
    /// `None` from inside the sphere (or on it).
    fn of(sphere: &Sphere, reference: Vec3) -> Option<Self> {
        let distance = (sphere.center - reference).length();
        let sin2_max = (sphere.radius / distance).powi(2);
        if sin2_max.is_nan() || sin2_max >= 1.0 {
            return None;
        }
        let cos_max = (1.0 - sin2_max).sqrt();
        let one_minus_cos_max = if sin2_max < SMALL_CONE_SIN2 {
            sin2_max / 2.0
        } else {
            1.0 - cos_max
        };
        (one_minus_cos_max > 0.0).then_some(Self {
            distance,
            sin2_max,
            sin_max: sin2_max.sqrt(),
            cos_max,
            one_minus_cos_max,
        })
    }

    fn pdf(&self) -> f32 {
        1.0 / (TAU * self.one_minus_cos_max)
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
