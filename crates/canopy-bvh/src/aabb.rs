//! Axis-aligned bounding boxes and the ray/box slab test.

use crate::Ray;
use bytemuck::{Pod, Zeroable};
use glam::{BVec3, Vec3};

/// An axis-aligned box. The empty box has `min = +inf`, `max = -inf`, so that growing it
/// by anything yields that thing.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

/// Slack on the far slab distance so that rounding in the slab test never culls a box
/// that a primitive inside it is hit in (Ize, "Robust BVH Ray Traversal", JCGT 2013:
/// 1 + 2 gamma(3)).
pub(crate) const FAR_SLACK: f32 =
    1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };

    #[inline]
    pub fn new(min: Vec3, max: Vec3) -> Self {
        Self { min, max }
    }

    /// The smallest box holding every point.
    pub fn from_points(points: impl IntoIterator<Item = Vec3>) -> Self {
        points.into_iter().fold(Self::EMPTY, |b, p| b.grow(p))
    }

    #[inline]
    pub fn grow(self, p: Vec3) -> Self {
        self.union(Aabb::new(p, p))
    }

    /// The smallest box holding both. Boxes are NaN-free (builders' inputs are checked
    /// upstream), so plain compare-and-select suffices and keeps this hot call short.
    #[inline]
    pub fn union(self, other: Aabb) -> Self {
        Self::new(
            Vec3::new(
                fast_min(self.min.x, other.min.x),
                fast_min(self.min.y, other.min.y),
                fast_min(self.min.z, other.min.z),
            ),
            Vec3::new(
                fast_max(self.max.x, other.max.x),
                fast_max(self.max.y, other.max.y),
                fast_max(self.max.z, other.max.z),
            ),
        )
    }

    /// The box both hold, or [`Aabb::EMPTY`] when they do not meet.
    #[inline]
    pub fn intersection(self, other: Aabb) -> Self {
        let b = Self::new(self.min.max(other.min), self.max.min(other.max));
        if b.is_empty() {
            Self::EMPTY
        } else {
            b
        }
    }

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    #[inline]
    pub fn extent(&self) -> Vec3 {
        self.max - self.min
    }

    #[inline]
    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Surface area; zero for an empty box.
    #[inline]
    pub fn surface_area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// Index (0, 1, 2) of the longest side.
    #[inline]
    pub fn largest_axis(&self) -> usize {
        let e = self.extent();
        if e.x >= e.y && e.x >= e.z {
            0
        } else if e.y >= e.z {
            1
        } else {
            2
        }
    }

    /// Whether `other` lies entirely inside `self` (an empty `other` always does).
    pub fn contains(&self, other: &Aabb) -> bool {
        other.is_empty() || (self.min.cmple(other.min).all() && self.max.cmpge(other.max).all())
    }

    /// Entry distance of the ray into the box, clamped to `[ray.t_min, ray.t_max]`, or
    /// `None` when the ray misses the box within that interval.
    #[inline]
    pub fn ray_entry(&self, ray: &Ray) -> Option<f32> {
        let t = self.ray_entry_or_inf(ray);
        (t != f32::INFINITY).then_some(t)
    }

    /// Branch-free slab test: entry distance, or `+inf` on a miss. A ray lying exactly in
    /// the plane of a face (`0 * inf = NaN`) counts as inside that slab, as in the
    /// tree's node tests.
    #[inline(always)]
    pub fn ray_entry_or_inf(&self, ray: &Ray) -> f32 {
        SlabRay::new(ray).entry_or_inf(self.min, self.max)
    }
}

/// A ray prepared for many slab tests.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SlabRay {
    origin: Vec3,
    inv_dir: Vec3,
    /// Axes the ray runs down (negative inverse direction): their near plane is the max.
    down: BVec3,
    pub t_min: f32,
    pub t_max: f32,
}

/// `min` and `max` as plain compare-and-select, which compile to single `minss`/`maxss`
/// instructions (`f32::min` must also order NaNs, which costs several more). When an
/// argument is NaN they return the second one.
#[inline(always)]
pub(crate) fn fast_min(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

#[inline(always)]
pub(crate) fn fast_max(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

impl SlabRay {
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        Self {
            origin: ray.origin,
            inv_dir: ray.inv_dir,
            down: ray.inv_dir.cmplt(Vec3::ZERO),
            t_min: ray.t_min,
            t_max: ray.t_max,
        }
    }

    /// Entry distance into the box `[min, max]` within `[t_min, t_max]`, or `+inf`.
    #[inline(always)]
    pub fn entry_or_inf(&self, min: Vec3, max: Vec3) -> f32 {
        let t0 = (min - self.origin) * self.inv_dir;
        let t1 = (max - self.origin) * self.inv_dir;
        // Near and far planes by the direction's sign, as the wide kernels pick them: a
        // ray lying in a face's plane (zero direction component) gives `0 * inf = NaN`
        // there, and ordering `t0` and `t1` by value would make that `+inf`, a miss.
        // Each compare-and-select below returns its second argument when the first is
        // NaN, and every second argument is a number, so such an axis is dropped: the
        // ray counts as inside that slab, and the other axes still bound it.
        let near = Vec3::select(self.down, t1, t0);
        let far = Vec3::select(self.down, t0, t1);
        let enter = fast_max(near.x, fast_max(near.y, fast_max(near.z, self.t_min)));
        let exit = fast_min(far.x, fast_min(far.y, fast_min(far.z, f32::INFINITY))) * FAR_SLACK;
        let exit = fast_min(exit, self.t_max);
        if enter <= exit {
            enter
        } else {
            f32::INFINITY
        }
    }
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_box() -> Aabb {
        Aabb::new(Vec3::ZERO, Vec3::ONE)
    }

    #[test]
    fn empty_box_is_identity_of_union() {
        let b = unit_box();
        assert_eq!(Aabb::EMPTY.union(b), b);
        assert!(Aabb::EMPTY.is_empty());
        assert_eq!(Aabb::EMPTY.surface_area(), 0.0);
    }

    #[test]
    fn surface_area_of_unit_cube_is_six() {
        assert_eq!(unit_box().surface_area(), 6.0);
    }

    #[test]
    fn ray_hits_box_in_front() {
        let ray = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X, 0.0, f32::INFINITY);
        assert_eq!(unit_box().ray_entry(&ray), Some(1.0));
    }

    #[test]
    fn ray_misses_box_behind_origin() {
        let ray = Ray::new(Vec3::new(2.0, 0.5, 0.5), Vec3::X, 0.0, f32::INFINITY);
        assert_eq!(unit_box().ray_entry(&ray), None);
    }

    #[test]
    fn ray_starting_inside_enters_at_t_min() {
        let ray = Ray::new(Vec3::splat(0.5), Vec3::Y, 0.0, f32::INFINITY);
        assert_eq!(unit_box().ray_entry(&ray), Some(0.0));
    }

    #[test]
    fn t_max_limits_the_hit() {
        let ray = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X, 0.0, 0.5);
        assert_eq!(unit_box().ray_entry(&ray), None);
    }

    #[test]
    fn axis_parallel_ray_inside_slab_hits() {
        // Direction has zero y and z: inv_dir is infinite on those axes.
        let ray = Ray::new(Vec3::new(-1.0, 0.25, 0.5), Vec3::X, 0.0, f32::INFINITY);
        assert_eq!(unit_box().ray_entry(&ray), Some(1.0));
    }

    #[test]
    fn axis_parallel_ray_outside_slab_misses() {
        let ray = Ray::new(Vec3::new(-1.0, 2.0, 0.5), Vec3::X, 0.0, f32::INFINITY);
        assert_eq!(unit_box().ray_entry(&ray), None);
    }

    #[test]
    fn flat_box_is_hit_head_on() {
        let flat = Aabb::new(Vec3::new(0.0, 0.0, 1.0), Vec3::new(1.0, 1.0, 1.0));
        let ray = Ray::new(Vec3::new(0.5, 0.5, 0.0), Vec3::Z, 0.0, f32::INFINITY);
        assert_eq!(flat.ray_entry(&ray), Some(1.0));
    }

    /// A ray lying in the plane of a face (zero direction component, `0 * inf = NaN`)
    /// touches the box: counted as a hit on either face, for either sign of zero, so a
    /// tree never culls a node whose primitives such a ray can hit.
    #[test]
    fn ray_in_a_face_plane_hits() {
        for y in [0.0, 1.0] {
            for dir in [Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, -0.0, 0.0)] {
                let ray = Ray::new(Vec3::new(-1.0, y, 0.5), dir, 0.0, f32::INFINITY);
                assert_eq!(unit_box().ray_entry(&ray), Some(1.0), "y = {y}, {dir:?}");
            }
        }
    }
}
