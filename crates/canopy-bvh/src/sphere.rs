//! Spheres a wide tree tests itself: the ray/sphere test, and the leaf-ordered records a
//! tree keeps of its spheres ([`crate::BvhN::store_spheres`]), so that a sphere test is
//! a few loads and no call through the caller's closure.

use crate::Ray;
use glam::Vec3;

/// Ray/sphere roots computed the numerically careful way (Haines et al., "Precision
/// Improvements for Ray/Sphere Intersection", Ray Tracing Gems, 2019): the discriminant
/// from the distance of the centre to the ray's line, and the second root from the first
/// (no catastrophic cancellation), so a small sphere far away and a huge sphere nearby
/// both stay precise. Returns the nearer root within `[t_min, t_max]`, else the farther.
#[inline(always)]
pub fn intersect_sphere(center: Vec3, radius: f32, ray: &Ray) -> Option<f32> {
    let f = ray.origin - center;
    let d = ray.dir;
    let a = d.length_squared();
    let b = -f.dot(d);
    let to_line = f + (b / a) * d;
    let r2 = radius * radius;
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

/// A leaf entry's sphere (centre and radius), or a marker that the entry is something
/// else (tested by the caller's closure).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(16))]
pub(crate) struct SphereRecord {
    pub center: [f32; 3],
    /// Negative for an entry that is not a sphere.
    pub radius: f32,
}

impl SphereRecord {
    pub const OTHER: Self = Self {
        center: [0.0; 3],
        radius: -1.0,
    };

    pub fn new(center: Vec3, radius: f32) -> Self {
        Self {
            center: center.to_array(),
            radius,
        }
    }

    #[inline(always)]
    pub fn is_sphere(&self) -> bool {
        self.radius >= 0.0
    }

    #[inline(always)]
    pub fn intersect(&self, ray: &Ray) -> Option<f32> {
        intersect_sphere(Vec3::from_array(self.center), self.radius, ray)
    }
}
