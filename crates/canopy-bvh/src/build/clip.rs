//! Splitting a primitive by an axis-aligned plane, for builders with spatial splits.
//!
//! canopy-bvh knows primitives by their boxes only, so a builder that cuts primitives
//! (`sbvh`) asks a [`Clipper`], which the caller implements with the geometry it has.
//! Any `Fn(prim, within, axis, position) -> (Aabb, Aabb)` closure is one; [`split_box`]
//! and [`split_triangle`] are the two answers most callers need.

use crate::Aabb;
use glam::Vec3;

/// Splits primitives by planes.
pub trait Clipper: Sync {
    /// The part of primitive `prim` that lies inside `within`, cut by the plane
    /// `point[axis] == position`: the boxes of the parts below and above the plane, each
    /// inside `within` ([`Aabb::EMPTY`] for a side with no part). Every point of the
    /// primitive inside `within` must lie in one of the two boxes.
    fn split(&self, prim: u32, within: Aabb, axis: usize, position: f32) -> (Aabb, Aabb);
}

impl<F> Clipper for F
where
    F: Fn(u32, Aabb, usize, f32) -> (Aabb, Aabb) + Sync,
{
    #[inline]
    fn split(&self, prim: u32, within: Aabb, axis: usize, position: f32) -> (Aabb, Aabb) {
        self(prim, within, axis, position)
    }
}

/// The clipper of primitives known only by their boxes: it cuts the box itself, which is
/// exact for boxes and conservative for anything else (a sphere's corner pieces).
pub struct SplitBoxes;

impl Clipper for SplitBoxes {
    #[inline]
    fn split(&self, _prim: u32, within: Aabb, axis: usize, position: f32) -> (Aabb, Aabb) {
        split_box(within, axis, position)
    }
}

/// `within` cut by the plane `point[axis] == position`.
#[inline]
pub fn split_box(within: Aabb, axis: usize, position: f32) -> (Aabb, Aabb) {
    let (mut below, mut above) = (within, within);
    below.max[axis] = below.max[axis].min(position);
    above.min[axis] = above.min[axis].max(position);
    (empty_if_inverted(below), empty_if_inverted(above))
}

/// The triangle `v` inside `within`, cut by the plane `point[axis] == position`: the
/// boxes of its vertices and edge crossings on each side, clipped to `within`
/// (Stich et al. 2009, section 4.2). Crossings are widened by a few units in the last
/// place on the other two axes, so rounding never leaves a sliver of the triangle
/// outside both boxes.
pub fn split_triangle(v: [Vec3; 3], within: Aabb, axis: usize, position: f32) -> (Aabb, Aabb) {
    let (mut below, mut above) = (Aabb::EMPTY, Aabb::EMPTY);
    for i in 0..3 {
        let (a, b) = (v[i], v[(i + 1) % 3]);
        let (da, db) = (a[axis] - position, b[axis] - position);
        if da <= 0.0 {
            below = below.grow(a);
        }
        if da >= 0.0 {
            above = above.grow(a);
        }
        if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
            let t = da / (da - db);
            let mut p = a + (b - a) * t;
            p[axis] = position;
            let mut slack = a.abs().max(b.abs()) * (4.0 * f32::EPSILON);
            slack[axis] = 0.0;
            let crossing = Aabb::new(p - slack, p + slack);
            below = below.union(crossing);
            above = above.union(crossing);
        }
    }
    (below.intersection(within), above.intersection(within))
}

fn empty_if_inverted(b: Aabb) -> Aabb {
    if b.is_empty() {
        Aabb::EMPTY
    } else {
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TRIANGLE: [Vec3; 3] = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(4.0, 0.0, 1.0),
        Vec3::new(0.0, 2.0, 3.0),
    ];

    fn bounds(v: [Vec3; 3]) -> Aabb {
        Aabb::from_points(v)
    }

    #[test]
    fn a_box_splits_into_two_halves_that_share_the_plane() {
        let b = Aabb::new(Vec3::ZERO, Vec3::splat(2.0));
        let (below, above) = split_box(b, 1, 0.5);
        assert_eq!(below, Aabb::new(Vec3::ZERO, Vec3::new(2.0, 0.5, 2.0)));
        assert_eq!(above, Aabb::new(Vec3::new(0.0, 0.5, 0.0), Vec3::splat(2.0)));
        assert_eq!(split_box(b, 0, 3.0), (b, Aabb::EMPTY));
        assert_eq!(split_box(b, 2, -1.0), (Aabb::EMPTY, b));
    }

    #[test]
    fn a_triangle_split_is_tighter_than_its_box_split_and_covers_it() {
        let whole = bounds(TRIANGLE);
        let (below, above) = split_triangle(TRIANGLE, whole, 0, 2.0);
        // Below x = 2: the crossing points (2, 0, 0.5) and (2, 1, 2) and the vertices at
        // x = 0; above: (4, 0, 1) and the crossings.
        assert!(below.max.x == 2.0 && above.min.x == 2.0);
        assert!((below.max.y - 2.0).abs() < 1e-5 && (above.max.y - 1.0).abs() < 1e-5);
        assert!((above.min.z - 0.5).abs() < 1e-5 && (above.max.z - 2.0).abs() < 1e-5);
        // Every point of the triangle lies in one of the boxes.
        for i in 0..=40 {
            for j in 0..=(40 - i) {
                let (u, w) = (i as f32 / 40.0, j as f32 / 40.0);
                let p = TRIANGLE[0] * (1.0 - u - w) + TRIANGLE[1] * u + TRIANGLE[2] * w;
                let inside = |b: Aabb| b.contains(&Aabb::new(p, p));
                assert!(inside(below) || inside(above), "{p}");
            }
        }
    }

    #[test]
    fn a_triangle_split_stays_within_the_box_given() {
        let within = Aabb::new(Vec3::new(1.0, 0.0, 0.0), Vec3::new(3.0, 1.0, 3.0));
        let (below, above) = split_triangle(TRIANGLE, within, 0, 2.0);
        assert!(within.contains(&below) && within.contains(&above));
        // A plane beyond the triangle leaves everything on one side.
        let whole = bounds(TRIANGLE);
        assert_eq!(
            split_triangle(TRIANGLE, whole, 2, 5.0),
            (whole, Aabb::EMPTY)
        );
        assert_eq!(
            split_triangle(TRIANGLE, whole, 2, -1.0),
            (Aabb::EMPTY, whole)
        );
    }

    #[test]
    fn closures_are_clippers() {
        let clip =
            |_: u32, within: Aabb, axis: usize, position: f32| split_box(within, axis, position);
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        assert_eq!(clip.split(7, b, 0, 0.5), SplitBoxes.split(7, b, 0, 0.5));
    }
}
