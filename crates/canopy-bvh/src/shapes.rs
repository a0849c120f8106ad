//! Shapes a wide tree tests itself: the ray/sphere and ray/box tests, the shapes a
//! geometry offers for keeping ([`KnownShape`]), and the leaf-ordered records a tree keeps
//! of them ([`crate::BvhN::store_shapes`]), so that testing one is a few loads and no call
//! through the caller's closure.

use crate::{Aabb, Ray};
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
    first_in_range(near, far, ray.t_min, ray.t_max)
}

/// Ray/box slab test, the box given by its corners `min` and `max` and the ray by an
/// origin in the box's frame, its inverse direction and its range: the entry distance if
/// it lies in `[t_min, t_max]`, else the exit distance (a ray that starts inside, through a
/// glass box, finds the far wall), else `None`. Tangent rays (`0 * inf`) follow
/// `f32::min`'s and `f32::max`'s rule for NaN: the other operand.
#[inline(always)]
pub fn intersect_box(
    min: Vec3,
    max: Vec3,
    origin: Vec3,
    inv_dir: Vec3,
    t_min: f32,
    t_max: f32,
) -> Option<f32> {
    let t0 = (min - origin) * inv_dir;
    let t1 = (max - origin) * inv_dir;
    let enter = t0.min(t1).max_element();
    let exit = t0.max(t1).min_element();
    if enter > exit {
        return None;
    }
    first_in_range(enter, exit, t_min, t_max)
}

/// `near` if it lies in `[t_min, t_max]`, else `far` if it does, else `None`: a solid's
/// entry, or its exit for a ray that starts inside.
#[inline(always)]
fn first_in_range(near: f32, far: f32, t_min: f32, t_max: f32) -> Option<f32> {
    let in_range = |t: f32| t >= t_min && t <= t_max;
    if in_range(near) {
        Some(near)
    } else if in_range(far) {
        Some(far)
    } else {
        None
    }
}

/// A primitive whose test canopy knows, so that a wide tree can keep it beside its leaves
/// and test it itself ([`crate::Geometry::known_shape`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum KnownShape {
    /// Hit as [`intersect_sphere`] hits it.
    Sphere { center: Vec3, radius: f32 },
    /// An axis-aligned box, hit as [`intersect_box`] hits it with the ray's own origin and
    /// inverse direction.
    Box(Aabb),
}

impl KnownShape {
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray) -> Option<f32> {
        match *self {
            KnownShape::Sphere { center, radius } => intersect_sphere(center, radius, ray),
            KnownShape::Box(b) => {
                intersect_box(b.min, b.max, ray.origin, ray.inv_dir, ray.t_min, ray.t_max)
            }
        }
    }
}

/// A leaf entry's known shape, or a marker that the entry is something else (tested by
/// the caller's closure). Aligned so that a record never straddles two cache lines.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(align(32))]
pub(crate) struct ShapeRecord(pub Option<KnownShape>);

impl ShapeRecord {
    #[inline(always)]
    pub fn is_kept(&self) -> bool {
        self.0.is_some()
    }

    /// The hit of a kept shape; `None` for a miss and for an entry that is not kept.
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray) -> Option<f32> {
        self.0.as_ref().and_then(|shape| shape.intersect(ray))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_fit_one_cache_line_half() {
        assert_eq!(std::mem::size_of::<ShapeRecord>(), 32);
    }

    #[test]
    fn a_box_is_entered_or_left_within_the_range() {
        let b = KnownShape::Box(Aabb::new(Vec3::ZERO, Vec3::ONE));
        let ray = |x: f32, t_min: f32, t_max: f32| {
            Ray::new(Vec3::new(x, 0.5, 0.5), Vec3::X, t_min, t_max)
        };
        assert_eq!(b.intersect(&ray(-2.0, 0.0, f32::INFINITY)), Some(2.0));
        // Starting inside, the far wall.
        assert_eq!(b.intersect(&ray(0.25, 0.0, f32::INFINITY)), Some(0.75));
        assert_eq!(b.intersect(&ray(-2.0, 0.0, 1.5)), None);
        assert_eq!(b.intersect(&ray(2.0, 0.0, f32::INFINITY)), None);
        // A flat box (a wall) is hit where the ray crosses its plane.
        let wall = KnownShape::Box(Aabb::new(
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 1.0),
        ));
        assert_eq!(wall.intersect(&ray(-1.0, 0.0, f32::INFINITY)), Some(2.0));
        assert_eq!(ShapeRecord(None).intersect(&ray(-2.0, 0.0, 9.0)), None);
    }
}
