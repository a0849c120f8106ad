use super::{area_to_solid_angle, max_abs, Surface, SurfaceSample, POINT_ERROR_ULPS};
use canopy_bvh::{intersect_box, Aabb, KnownShape, Ray};
use glam::{Mat3, Vec2, Vec3};

/// A box given by its corners in its own frame, then rotated and translated into the
/// world: `world = rotation * local + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cuboid {
    pub local: Aabb,
    rotation: Mat3,
    pub translation: Vec3,
    /// Whether `rotation` is the identity: the box is only moved, as floors, walls and
    /// lights mostly are, and rays need no turning into its frame (see
    /// [`Cuboid::intersect`]). Kept beside the rotation, which is why that is private:
    /// comparing the matrix at every test spent most of what the shortcut saves.
    unturned: bool,
}

impl Cuboid {
    pub fn new(local: Aabb, rotation: Mat3, translation: Vec3) -> Self {
        Self {
            local,
            rotation,
            translation,
            unturned: rotation == Mat3::IDENTITY,
        }
    }

    pub fn axis_aligned(min: Vec3, max: Vec3) -> Self {
        Self::new(Aabb::new(min, max), Mat3::IDENTITY, Vec3::ZERO)
    }

    /// The rotation from the box's frame to the world's.
    pub fn rotation(&self) -> Mat3 {
        self.rotation
    }

    fn transform_point(&self, p: Vec3) -> Vec3 {
        self.rotation * p + self.translation
    }

    pub fn bounds(&self) -> Aabb {
        let (lo, hi) = (self.local.min, self.local.max);
        Aabb::from_points((0..8).map(|i| {
            let corner = Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            self.transform_point(corner)
        }))
    }

    /// The triangles of its faces, in the world: two per face with area (a flat box's
    /// rectangle counts once, as in [`Cuboid::area`]).
    pub fn face_triangles(&self) -> Vec<[Vec3; 3]> {
        let (lo, hi) = (self.local.min, self.local.max);
        let corner = |x: bool, y: bool, z: bool| {
            self.transform_point(Vec3::new(
                if x { hi.x } else { lo.x },
                if y { hi.y } else { lo.y },
                if z { hi.z } else { lo.z },
            ))
        };
        let mut triangles = Vec::with_capacity(12);
        let extent = self.local.extent();
        for axis in 0..3 {
            if extent[(axis + 1) % 3] * extent[(axis + 2) % 3] == 0.0 {
                continue; // a face without area
            }
            let sides: &[bool] = if lo[axis] == hi[axis] {
                &[false]
            } else {
                &[false, true]
            };
            for &side in sides {
                // The face's four corners, going round it.
                let at = |u: bool, v: bool| {
                    let mut c = [false; 3];
                    c[axis] = side;
                    c[(axis + 1) % 3] = u;
                    c[(axis + 2) % 3] = v;
                    corner(c[0], c[1], c[2])
                };
                let (a, b, c, d) = (
                    at(false, false),
                    at(true, false),
                    at(true, true),
                    at(false, true),
                );
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            }
        }
        triangles
    }

    // Between the box's frame and the world's (rotation keeps lengths, so a ray's `t` is
    // the same in both). `unturned` is the box's flag or false: an unturned box skips the
    // products with the identity, which give the same numbers but for the sign of a zero.

    #[inline(always)]
    fn point_in_box_frame(&self, unturned: bool, p: Vec3) -> Vec3 {
        match unturned {
            true => p - self.translation,
            false => self.rotation.transpose() * (p - self.translation),
        }
    }

    #[inline(always)]
    fn direction_in_box_frame(&self, unturned: bool, d: Vec3) -> Vec3 {
        match unturned {
            true => d,
            false => self.rotation.transpose() * d,
        }
    }

    #[inline(always)]
    fn point_in_world(&self, unturned: bool, p: Vec3) -> Vec3 {
        match unturned {
            true => p + self.translation,
            false => self.transform_point(p),
        }
    }

    #[inline(always)]
    fn direction_in_world(&self, unturned: bool, d: Vec3) -> Vec3 {
        match unturned {
            true => d,
            false => self.rotation * d,
        }
    }

    /// Slab test in the box's frame, returning the exit distance too, so that a ray that
    /// starts inside (refraction through a glass box) finds the far wall.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<f32> {
        self.intersect_in(self.unturned, ray)
    }

    /// [`Cuboid::intersect`], unturned boxes (`unturned`) taking the ray's own inverse
    /// direction. A zero's sign, the only difference, just swaps a slab's two distances;
    /// turning costs three divisions and two matrix products, where every ray of the lit
    /// dragon meets a floor and a wall.
    #[inline(always)]
    fn intersect_in(&self, unturned: bool, ray: &Ray) -> Option<f32> {
        let origin = self.point_in_box_frame(unturned, ray.origin);
        let inv_dir = match unturned {
            true => ray.inv_dir,
            false => self.direction_in_box_frame(false, ray.dir).recip(),
        };
        let (min, max) = (self.local.min, self.local.max);
        intersect_box(min, max, origin, inv_dir, ray.t_min, ray.t_max)
    }

    /// The box as one a tree tests itself ([`KnownShape::Box`]) where that gives this
    /// box's own hits bit for bit: unturned and not moved (a translation of `+0.0`
    /// exactly, which leaves the ray's origin as it is), as scene files' walls, floors and
    /// lights are.
    #[inline]
    pub fn as_known_shape(&self) -> Option<KnownShape> {
        let unmoved = self.translation.to_array().map(f32::to_bits) == [0; 3];
        (self.unturned && unmoved).then_some(KnownShape::Box(self.local))
    }

    /// Area of the surface across each axis (x, y, z): two faces, or one where the box is
    /// flat along that axis (its two faces are then the same points).
    fn surface_areas(&self) -> Vec3 {
        let e = self.local.extent();
        let sides = e.cmpgt(Vec3::ZERO);
        let faces = Vec3::new(e.y * e.z, e.x * e.z, e.x * e.y);
        Vec3::select(sides, 2.0 * faces, faces)
    }

    /// Area of the distinct surface points (a flat box counts its rectangle once).
    pub fn area(&self) -> f32 {
        self.surface_areas().element_sum()
    }

    fn error(&self) -> f32 {
        let magnitude =
            max_abs(self.translation) + max_abs(self.local.min).max(max_abs(self.local.max));
        POINT_ERROR_ULPS * magnitude
    }

    /// A point uniform over the surface's area: an axis by the area across it, a face,
    /// then a point on it. A flat box's rectangle faces the reference.
    #[inline(always)]
    pub fn sample_toward(&self, reference: Vec3, u: Vec2) -> Option<SurfaceSample> {
        self.sample_toward_in(self.unturned, reference, u)
    }

    /// [`Cuboid::sample_toward`], `unturned` as in [`Cuboid::intersect_in`].
    #[inline(always)]
    fn sample_toward_in(&self, unturned: bool, reference: Vec3, u: Vec2) -> Option<SurfaceSample> {
        let areas = self.surface_areas();
        // Pick the axis with u.x and reuse what is left of it for the face and the point.
        let mut pick = u.x * areas.element_sum();
        let mut axis = 0;
        while axis < 2 && pick >= areas[axis] {
            pick -= areas[axis];
            axis += 1;
        }
        if areas[axis] <= 0.0 {
            return None;
        }
        let rest = (pick / areas[axis]).clamp(0.0, 1.0);
        let (lo, hi) = (self.local.min, self.local.max);
        let flat = lo[axis] == hi[axis];
        let (positive, along) = if flat {
            let to_reference = self.point_in_box_frame(unturned, reference);
            (to_reference[axis] >= lo[axis], rest)
        } else if rest >= 0.5 {
            (true, 2.0 * rest - 1.0)
        } else {
            (false, 2.0 * rest)
        };
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        let mut local = Vec3::ZERO;
        local[axis] = if positive { hi[axis] } else { lo[axis] };
        local[a] = lo[a] + along.min(1.0) * (hi[a] - lo[a]);
        local[b] = lo[b] + u.y * (hi[b] - lo[b]);
        let mut local_normal = Vec3::ZERO;
        local_normal[axis] = if positive { 1.0 } else { -1.0 };
        let p = self.point_in_world(unturned, local);
        let normal = self.direction_in_world(unturned, local_normal);
        SurfaceSample::by_area(self.area(), reference, p, normal, self.error())
    }

    pub fn pdf_toward(&self, reference: Vec3, p: Vec3, normal: Vec3) -> f32 {
        area_to_solid_angle(1.0 / self.area(), reference, p, normal).unwrap_or(0.0)
    }

    /// The rectangle of a flat box (one of its extents zero, the other two not), for
    /// drawing many points on it as a light; `None` for a solid box or one without area.
    pub fn rectangle(&self) -> Option<Rectangle> {
        let extent = self.local.extent();
        let flat = (0..3).find(|&axis| extent[axis] == 0.0)?;
        let (a, b) = ((flat + 1) % 3, (flat + 2) % 3);
        if !(extent[a] > 0.0 && extent[b] > 0.0) {
            return None;
        }
        let along = |axis: usize| {
            let mut v = Vec3::ZERO;
            v[axis] = extent[axis];
            self.direction_in_world(self.unturned, v)
        };
        let mut normal = Vec3::ZERO;
        normal[flat] = 1.0;
        Some(Rectangle {
            corner: self.point_in_world(self.unturned, self.local.min),
            edges: [along(a), along(b)],
            normal: self.direction_in_world(self.unturned, normal),
            area_pdf: 1.0 / self.area(),
            error: self.error(),
        })
    }

    #[inline(always)]
    pub fn surface(&self, ray: &Ray, t: f32) -> Surface {
        self.surface_in(self.unturned, ray, t)
    }

    /// [`Cuboid::surface`], `unturned` as in [`Cuboid::intersect_in`].
    #[inline(always)]
    fn surface_in(&self, unturned: bool, ray: &Ray, t: f32) -> Surface {
        let dir = self.direction_in_box_frame(unturned, ray.dir);
        let mut p = self.point_in_box_frame(unturned, ray.origin) + t * dir;
        // The face hit is the one the point is relatively closest to; a flat box's thin
        // axis always wins.
        let center = self.local.center();
        let half = 0.5 * self.local.extent();
        let offset = p - center;
        let closeness = |i: usize| {
            if half[i] > 0.0 {
                offset[i].abs() / half[i]
            } else {
                f32::INFINITY
            }
        };
        let axis = (0..3)
            .max_by(|&a, &b| closeness(a).total_cmp(&closeness(b)))
            .unwrap_or(0);
        // A flat box has two faces in one plane: take the one facing the ray.
        let positive = if half[axis] > 0.0 {
            offset[axis] >= 0.0
        } else {
            dir[axis] < 0.0
        };
        let mut local_normal = Vec3::ZERO;
        local_normal[axis] = if positive { 1.0 } else { -1.0 };
        // Snap onto the face plane, which removes the error along the normal.
        p[axis] = if positive {
            self.local.max[axis]
        } else {
            self.local.min[axis]
        };
        let normal = self.direction_in_world(unturned, local_normal);
        Surface {
            p: self.point_in_world(unturned, p),
            geometric_normal: normal,
            shading_normal: normal,
            error: self.error(),
        }
    }
}

/// A flat box's rectangle in the world ([`Cuboid::rectangle`]), its light samples made
/// in a few multiply-adds: a rectangle light (the Cornell box's, the lit dragon's) is
/// sampled at every vertex, and [`Cuboid::sample_toward`] works out the face from the
/// box's areas and moves the point into the world each time (a sixth of the Cornell
/// box's render went to drawing light samples).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rectangle {
    corner: Vec3,
    edges: [Vec3; 2],
    /// Unit normal of the flat axis's positive side.
    normal: Vec3,
    area_pdf: f32,
    error: f32,
}

impl Rectangle {
    /// [`Cuboid::sample_toward`] of the box it came from: the same point for the same
    /// `u` (`u.x` along the first edge, `u.y` along the second) up to rounding, facing
    /// the reference, with the same density.
    #[inline]
    pub fn sample_toward(&self, reference: Vec3, u: Vec2) -> Option<SurfaceSample> {
        let p = self.corner + u.x * self.edges[0] + u.y * self.edges[1];
        let normal = match self.normal.dot(reference - self.corner) >= 0.0 {
            true => self.normal,
            false => -self.normal,
        };
        let pdf = area_to_solid_angle(self.area_pdf, reference, p, normal)?;
        Some(SurfaceSample {
            p,
            normal,
            error: self.error,
            pdf,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: Vec3, d: Vec3) -> Ray {
        Ray::new(o, d, 0.0, f32::INFINITY)
    }

    fn unit() -> Cuboid {
        Cuboid::axis_aligned(Vec3::ZERO, Vec3::ONE)
    }

    #[test]
    fn hit_from_outside_gives_entry_and_face_normal() {
        let r = ray(Vec3::new(0.5, 0.5, -2.0), Vec3::Z);
        let t = unit().intersect(&r).unwrap();
        assert_eq!(t, 2.0);
        assert_eq!(unit().surface(&r, t).geometric_normal, -Vec3::Z);
    }

    #[test]
    fn origin_inside_hits_the_exit_wall() {
        let r = ray(Vec3::splat(0.5), Vec3::X);
        let t = unit().intersect(&r).unwrap();
        assert_eq!(t, 0.5);
        assert_eq!(unit().surface(&r, t).geometric_normal, Vec3::X);
    }

    #[test]
    fn box_behind_the_origin_is_missed() {
        assert_eq!(
            unit().intersect(&ray(Vec3::new(0.5, 0.5, 2.0), Vec3::Z)),
            None
        );
    }

    #[test]
    fn miss_beside_the_box() {
        assert_eq!(
            unit().intersect(&ray(Vec3::new(1.5, 0.5, -2.0), Vec3::Z)),
            None
        );
    }

    #[test]
    fn rotated_box_is_hit_on_its_rotated_face() {
        // Rotate 45 degrees about y: the corner now points at a ray coming along +x.
        let c = Cuboid::new(
            Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0)),
            Mat3::from_rotation_y(std::f32::consts::FRAC_PI_4),
            Vec3::new(5.0, 0.0, 0.0),
        );
        let r = ray(Vec3::new(0.0, 0.0, 0.0), Vec3::X);
        let t = c.intersect(&r).unwrap();
        assert!((t - (5.0 - 2f32.sqrt())).abs() < 1e-5, "t = {t}");
        let b = c.bounds();
        assert!((b.min.x - (5.0 - 2f32.sqrt())).abs() < 1e-5);
    }

    #[test]
    fn face_triangles_cover_the_surface() {
        let c = Cuboid::new(
            Aabb::new(Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0)),
            Mat3::from_rotation_z(0.3),
            Vec3::ONE,
        );
        let area: f32 = c
            .face_triangles()
            .iter()
            .map(|t| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length())
            .sum();
        assert!((area - c.area()).abs() < 1e-4, "{area} vs {}", c.area());
        let flat = Cuboid::axis_aligned(Vec3::ZERO, Vec3::new(2.0, 0.0, 3.0));
        assert_eq!(flat.face_triangles().len(), 2);
    }

    /// A flat box's rectangle draws the point the box's own sampler draws for the same
    /// numbers (up to rounding), facing the same side, with the same density; flat along
    /// each axis, turned or not, moved or not. Solid boxes and flat ones without area
    /// have no rectangle.
    #[test]
    fn rectangles_sample_as_their_flat_boxes_do() {
        let flats = [
            Cuboid::axis_aligned(Vec3::new(-0.5, 3.0, 0.2), Vec3::new(0.5, 3.0, 1.2)),
            Cuboid::axis_aligned(
                Vec3::new(213.0, 555.0, 227.0),
                Vec3::new(343.0, 555.0, 332.0),
            ),
            Cuboid::new(
                Aabb::new(Vec3::new(0.0, -1.0, -1.0), Vec3::new(0.0, 1.0, 2.0)),
                Mat3::IDENTITY,
                Vec3::new(0.3, -0.2, 1.7),
            ),
            Cuboid::new(
                Aabb::new(Vec3::new(-1.0, -2.0, 0.5), Vec3::new(1.5, 2.0, 0.5)),
                Mat3::from_euler(glam::EulerRot::XYZ, 0.4, -1.1, 2.0),
                Vec3::new(-3.0, 1.0, 4.0),
            ),
        ];
        let mut rng = crate::rng::Rng::for_sample(11, 0, 0);
        let mut next = || rng.next_f32();
        let mut drawn = 0;
        for c in flats {
            let rectangle = c.rectangle().expect("a flat box with area");
            let size = c.bounds().extent().length() + c.translation.length();
            let (center, scale) = (c.bounds().center(), c.bounds().extent().max_element());
            for _ in 0..3000 {
                let offset = Vec3::new(next(), next(), next()) * 2.0 - Vec3::ONE;
                let reference = center + 3.0 * scale * offset;
                let u = Vec2::new(next(), next());
                let (Some(ours), Some(theirs)) = (
                    rectangle.sample_toward(reference, u),
                    c.sample_toward(reference, u),
                ) else {
                    panic!("a point seen from {reference}");
                };
                assert!(
                    ours.p.distance(theirs.p) <= 1e-5 * size,
                    "{ours:?} {theirs:?}"
                );
                assert!(
                    ours.normal.distance(theirs.normal) <= 1e-6,
                    "{ours:?} {theirs:?}"
                );
                assert_eq!(ours.error, theirs.error);
                let relative = (ours.pdf - theirs.pdf).abs() / theirs.pdf;
                assert!(relative <= 1e-4, "{ours:?} {theirs:?}");
                // The density the integrator weighs BSDF samples that hit it with.
                let pdf = c.pdf_toward(reference, ours.p, ours.normal);
                assert!((ours.pdf - pdf).abs() <= 1e-4 * pdf, "{} {pdf}", ours.pdf);
                drawn += 1;
            }
        }
        assert_eq!(drawn, 12_000);
        assert_eq!(unit().rectangle(), None);
        let line = Cuboid::axis_aligned(Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(line.rectangle(), None);
    }

    #[test]
    fn flat_box_gets_the_normal_of_its_thin_axis() {
        let light = Cuboid::axis_aligned(Vec3::new(0.0, 2.0, 0.0), Vec3::new(1.0, 2.0, 1.0));
        let r = ray(Vec3::new(0.5, 0.0, 0.5), Vec3::Y);
        let t = light.intersect(&r).unwrap();
        assert_eq!(t, 2.0);
        assert_eq!(light.surface(&r, t).geometric_normal, -Vec3::Y);
    }

    /// An unturned box's shortcuts answer as turning by the identity does (the general
    /// path): hits, misses, surfaces and light samples, from outside and inside, for solid
    /// and flat boxes.
    #[test]
    fn unturned_boxes_answer_as_turning_by_the_identity_does() {
        let boxes = [
            Cuboid::axis_aligned(Vec3::new(-1.0, 0.5, -2.0), Vec3::new(2.0, 1.5, 0.25)),
            Cuboid::axis_aligned(Vec3::new(-0.5, 3.0, 0.2), Vec3::new(0.5, 3.0, 1.2)),
            Cuboid::new(
                Aabb::new(Vec3::new(0.0, -1.0, -1.0), Vec3::new(0.0, 1.0, 2.0)),
                Mat3::IDENTITY,
                Vec3::new(0.3, -0.2, 1.7),
            ),
        ];
        let mut rng = crate::rng::Rng::for_sample(7, 0, 0);
        let mut point = |scale: f32| {
            let v = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            (v * 2.0 - Vec3::ONE) * scale
        };
        for c in boxes {
            assert!(c.unturned);
            let mut hits = 0;
            // Rays aimed about the box, a quarter of them from within its bounds.
            let (center, extent) = (c.bounds().center(), c.bounds().extent());
            for i in 0..4000 {
                let origin = match i % 4 {
                    0 => center + 0.4 * point(1.0) * extent,
                    _ => point(5.0),
                };
                let r = ray(origin, center + 0.75 * point(1.0) * extent - origin);
                let t = c.intersect_in(true, &r);
                assert_eq!(t, c.intersect_in(false, &r), "{r:?}");
                // Where a tree may keep the box, its test gives the same bits.
                if let Some(known) = c.as_known_shape() {
                    let bits = |t: Option<f32>| t.map(f32::to_bits);
                    assert_eq!(bits(known.intersect(&r)), bits(t), "{r:?}");
                }
                if let Some(t) = t {
                    hits += 1;
                    assert_eq!(c.surface_in(true, &r, t), c.surface_in(false, &r, t));
                }
                let (reference, u) = (point(5.0), point(1.0).abs().truncate());
                assert_eq!(
                    c.sample_toward_in(true, reference, u),
                    c.sample_toward_in(false, reference, u),
                    "{reference} {u}"
                );
            }
            assert!((1000..4000).contains(&hits), "{hits} hits");
        }
        let turned = Cuboid::new(boxes[0].local, Mat3::from_rotation_x(0.5), Vec3::ONE);
        assert!(!turned.unturned);
        // Only boxes neither turned nor moved are offered to trees.
        let kept = boxes.map(|c| c.as_known_shape().is_some());
        assert_eq!(kept, [true, true, false]);
        assert_eq!(turned.as_known_shape(), None);
    }
}
