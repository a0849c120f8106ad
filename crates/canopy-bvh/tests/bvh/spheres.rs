//! Spheres and boxes a wide tree keeps beside its leaves and tests itself, one ray at a
//! time or in packets of coherent rays: the same closest hits (primitive and distance,
//! bit for bit), the same occlusion and the same every-hit lists as a loop over every
//! primitive, in every layout and instruction set, before and after the spheres move.

use crate::common;

use canopy_bvh::{
    intersect_box, intersect_sphere, intersect_triangle, Aabb, Blas, BlasParams, Builder, BvhWidth,
    Geometry, Hit, Isa, KnownShape, PrimHit, Ray, RayQuery, ShearedRay, ALL_MASKS, PACKET,
};
use common::uniform;
use glam::Vec3;

/// Spheres, and some boxes (half of them offered to the tree as known shapes, half left
/// to the closure) and triangles (which wide trees pack) among them.
#[derive(Clone)]
struct Balls {
    spheres: Vec<(Vec3, f32)>,
    /// Every `box_every`-th primitive is its sphere's box instead.
    box_every: usize,
    /// Every `triangle_every`-th primitive (counted from the second) is a triangle across
    /// its sphere instead.
    triangle_every: usize,
}

impl Balls {
    fn is_box(&self, prim: u32) -> bool {
        self.box_every > 0 && prim as usize % self.box_every == self.box_every - 1
    }

    fn triangle_of(&self, prim: u32) -> Option<[Vec3; 3]> {
        let every = self.triangle_every;
        if every == 0 || prim as usize % every != 1 % every || self.is_box(prim) {
            return None;
        }
        let (c, r) = self.spheres[prim as usize];
        Some([
            c + Vec3::new(r, 0.0, 0.0),
            c + Vec3::new(0.0, r, 0.3 * r),
            c + Vec3::new(-r, -0.5 * r, 0.0),
        ])
    }

    fn sphere_box(&self, prim: u32) -> Aabb {
        let (c, r) = self.spheres[prim as usize];
        Aabb::new(c - r, c + r)
    }
}

impl Geometry for Balls {
    fn len(&self) -> usize {
        self.spheres.len()
    }

    fn bounds(&self, prim: u32) -> Aabb {
        match self.triangle_of(prim) {
            Some(v) => v.iter().fold(Aabb::EMPTY, |b, &p| b.union(Aabb::new(p, p))),
            None => self.sphere_box(prim),
        }
    }

    fn triangle(&self, prim: u32) -> Option<[Vec3; 3]> {
        self.triangle_of(prim)
    }

    fn known_shape(&self, prim: u32) -> Option<KnownShape> {
        if self.triangle_of(prim).is_some() {
            return None;
        }
        if self.is_box(prim) {
            return prim
                .is_multiple_of(2)
                .then(|| KnownShape::Box(self.sphere_box(prim)));
        }
        let (center, radius) = self.spheres[prim as usize];
        Some(KnownShape::Sphere { center, radius })
    }

    fn has_triangles(&self) -> bool {
        self.triangle_every > 0
    }

    fn intersect(&self, prim: u32, ray: &Ray, sheared: &ShearedRay) -> Option<PrimHit> {
        if let Some(v) = self.triangle_of(prim) {
            return intersect_triangle(&v, ray, sheared);
        }
        let t = match self.is_box(prim) {
            true => {
                let b = self.sphere_box(prim);
                intersect_box(b.min, b.max, ray.origin, ray.inv_dir, ray.t_min, ray.t_max)
            }
            false => {
                let (c, r) = self.spheres[prim as usize];
                intersect_sphere(c, r, ray)
            }
        };
        t.map(PrimHit::from)
    }
}

/// `count` spheres in a slab above a huge ground sphere (the report's scenes), some
/// duplicated (ties go to the lower index) and some nested.
fn balls(count: usize, box_every: usize, triangle_every: usize, seed: u32) -> Balls {
    let mut u = uniform(seed);
    let mut spheres = vec![(Vec3::new(0.0, -1000.0, 0.0), 1000.0)];
    while spheres.len() < count {
        let c = Vec3::new(20.0 * u() - 10.0, 2.0 * u(), 20.0 * u() - 10.0);
        let r = 0.05 + 0.6 * u();
        spheres.push((c, r));
        match spheres.len() % 17 {
            0 => spheres.push((c, r)),
            5 => spheres.push((c, 0.5 * r)),
            _ => {}
        }
    }
    spheres.truncate(count);
    Balls {
        spheres,
        box_every,
        triangle_every,
    }
}

/// Camera rays as a wavefront stream holds them (each pixel's samples side by side, a
/// defocused lens), shadow rays towards a point light, then scattered rays from points in the scene, some with a finite
/// range, and a few rays that are not traceable. The count is not a multiple of a packet.
fn rays(seed: u32) -> Vec<Ray> {
    let mut u = uniform(seed);
    let eye = Vec3::new(13.0, 2.0, 3.0);
    let mut rays = Vec::new();
    for y in 0..24 {
        for x in 0..32 {
            for _ in 0..6 {
                let target = Vec3::new(
                    (x as f32 + u()) / 32.0 * 20.0 - 10.0,
                    3.0 - (y as f32 + u()) / 24.0 * 4.0,
                    0.0,
                );
                let origin = eye + 0.1 * Vec3::new(u() - 0.5, u() - 0.5, 0.0);
                rays.push(Ray::new(origin, target - origin, 0.0, f32::INFINITY));
            }
        }
    }
    // Shadow rays from neighbouring ground points to a point light, each ending short
    // of it: packets where some rays are blocked and some reach the light.
    let light = Vec3::new(1.0, 8.0, -2.0);
    for z in 0..20 {
        for x in 0..40 {
            let p = Vec3::new(x as f32 / 2.0 - 10.0 + 0.1 * u(), 0.0, z as f32 - 10.0);
            rays.push(Ray::new(p, light - p, 1e-3, 0.999));
        }
    }
    for i in 0..1500 {
        let origin = Vec3::new(20.0 * u() - 10.0, 2.5 * u(), 20.0 * u() - 10.0);
        let dir = Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5);
        let t_max = if i % 3 == 0 { 4.0 * u() } else { f32::INFINITY };
        rays.push(Ray::new(origin, dir, 0.0, t_max));
    }
    rays.push(Ray::new(Vec3::NAN, Vec3::X, 0.0, f32::INFINITY));
    rays.push(Ray::new(eye, Vec3::ZERO, 0.0, f32::INFINITY));
    rays.push(Ray::new(eye, -eye, f32::NAN, f32::INFINITY));
    rays.insert(100, Ray::new(eye, -eye, 0.0, f32::NAN));
    rays
}

fn closest_each(blas: &impl RayQuery, rays: &[Ray]) -> Vec<Option<Hit>> {
    let mut hits = vec![None; rays.len()];
    blas.intersect_each(rays.len(), ALL_MASKS, |i| rays[i], |i, h| hits[i] = h);
    hits
}

fn closest_in_packets(blas: &impl RayQuery, rays: &[Ray]) -> Vec<Option<Hit>> {
    let mut hits = vec![None; rays.len()];
    blas.intersect_coherent(rays.len(), ALL_MASKS, |i| rays[i], |i, h| hits[i] = h);
    hits
}

fn occluded_each(blas: &impl RayQuery, rays: &[Ray]) -> Vec<bool> {
    let mut blocked = vec![false; rays.len()];
    blas.occluded_each(rays.len(), ALL_MASKS, |i| rays[i], |i, b| blocked[i] = b);
    blocked
}

fn occluded_in_packets(blas: &impl RayQuery, rays: &[Ray]) -> Vec<bool> {
    let mut blocked = vec![false; rays.len()];
    blas.occluded_coherent(rays.len(), ALL_MASKS, |i| rays[i], |i, b| blocked[i] = b);
    blocked
}

/// Every hit of `ray` in `blas`'s tree, as (primitive, distance bits) in order.
fn every_hit(blas: &Blas<Balls>, ray: &Ray) -> Vec<(u32, u32)> {
    let geometry = blas.geometry();
    let mut hits = Vec::new();
    let test: common::Closest = &|p, r| geometry.intersect(p, r, &ShearedRay::new(r));
    let tree = blas.tree().unwrap();
    let found: &mut dyn FnMut(Hit, _) = &mut |hit: Hit, _| hits.push((hit.prim, hit.t.to_bits()));
    tree.for_each_hit(ray, test, found);
    hits.sort_unstable();
    hits
}

fn every_hit_by_brute_force(geometry: &Balls, ray: &Ray) -> Vec<(u32, u32)> {
    let sheared = ShearedRay::new(ray);
    (0..geometry.len() as u32)
        .filter_map(|p| Some((p, geometry.intersect(p, ray, &sheared)?.t.to_bits())))
        .collect()
}

/// Every layout, leaf size and instruction set against brute force, for `geometry`.
fn check_against_brute_force(geometry: &Balls, rays: &[Ray], what: &str) {
    let brute = Blas::build(geometry.clone(), &BlasParams::new(None, BvhWidth::Eight));
    let expected = closest_each(&brute, rays);
    let expected_blocked: Vec<bool> = rays.iter().map(|r| brute.occluded(r)).collect();
    // Most camera and scattered rays hit; most shadow rays reach the light.
    assert!(expected.iter().filter(|h| h.is_some()).count() > rays.len() / 3);
    let small_ones_hit = expected.iter().flatten().any(|h| h.prim != 0);
    assert_eq!(
        small_ones_hit,
        geometry.len() > 1,
        "{what}: rays meet the small spheres"
    );
    for width in BvhWidth::ALL {
        for leaf in [1, 4, 8] {
            let mut params = BlasParams::new(Some(Builder::BinnedSah), width);
            params.build.max_leaf_size = leaf;
            let mut blas = Blas::build(geometry.clone(), &params);
            let keeps = blas.tree().is_some_and(|t| t.has_kept_shapes());
            assert_eq!(
                keeps,
                width != BvhWidth::Two,
                "{what}: {width} wide keeps its shapes"
            );
            for isa in Isa::supported() {
                blas.tree_mut().unwrap().set_isa(isa).unwrap();
                let context = format!("{what}, {width} wide, leaves of {leaf}, {isa:?}");
                let single = closest_each(&blas, rays);
                let packets = closest_in_packets(&blas, rays);
                for (i, expected) in expected.iter().enumerate() {
                    let bits = |h: &Option<Hit>| h.map(|h| (h.prim, h.t.to_bits()));
                    assert_eq!(bits(&single[i]), bits(expected), "{context}: ray {i} alone");
                    assert_eq!(
                        bits(&packets[i]),
                        bits(expected),
                        "{context}: ray {i} in a packet"
                    );
                }
                assert_eq!(occluded_each(&blas, rays), expected_blocked, "{context}");
                assert_eq!(
                    occluded_in_packets(&blas, rays),
                    expected_blocked,
                    "{context}: in packets"
                );
                for (i, ray) in rays.iter().enumerate().step_by(7) {
                    assert_eq!(
                        every_hit(&blas, ray),
                        every_hit_by_brute_force(geometry, ray),
                        "{context}: every hit of ray {i}"
                    );
                }
            }
        }
    }
}

#[test]
fn kept_spheres_give_brute_force_answers_alone_and_in_packets() {
    for (count, seed) in [(1, 3), (7, 5), (PACKET + 1, 7), (300, 11)] {
        let geometry = balls(count, 0, 0, seed);
        check_against_brute_force(&geometry, &rays(seed + 1), &format!("{count} spheres"));
    }
}

/// A field of spheres is built in packs, four spheres to a pack, tested in SIMD lanes
/// (the tests above check its answers); with a quarter of boxes among them it keeps its
/// shapes beside the leaves instead.
#[test]
fn mostly_spheres_are_built_in_packs() {
    for (box_every, packed) in [(0, true), (4, false)] {
        for width in [BvhWidth::Four, BvhWidth::Eight] {
            let params = BlasParams::new(Some(Builder::BinnedSah), width);
            let blas = Blas::build(balls(300, box_every, 0, 11), &params);
            let tree = blas.tree().expect("a tree");
            assert_eq!(tree.has_triangle_packs(), packed, "boxes every {box_every}");
            assert!(tree.has_kept_shapes());
        }
    }
}

#[test]
fn boxes_among_the_spheres_are_kept_or_go_to_the_closure() {
    let geometry = balls(200, 4, 0, 13);
    check_against_brute_force(&geometry, &rays(17), "spheres and boxes");
}

/// Boxes alone, as a Cornell box's walls are (some nested, some rays starting inside):
/// half kept, half tested by the closure.
#[test]
fn kept_boxes_give_brute_force_answers_alone_and_in_packets() {
    for (count, seed) in [(2, 37), (PACKET + 3, 41), (120, 43)] {
        let geometry = balls(count, 1, 0, seed);
        check_against_brute_force(&geometry, &rays(seed + 1), &format!("{count} boxes"));
    }
}

#[test]
fn spheres_beside_triangle_packs_are_tested_there() {
    let geometry = balls(300, 7, 3, 29);
    check_against_brute_force(&geometry, &rays(31), "spheres, boxes and triangles");
}

/// Spheres and boxes kept beside the leaves, or in the triangle packs' lanes (the second
/// geometry), move with the geometry.
#[test]
fn moved_spheres_and_boxes_are_tested_where_they_are_now() {
    for (box_every, triangle_every) in [(0, 0), (5, 3)] {
        let params = BlasParams::new(Some(Builder::BinnedSah), BvhWidth::Eight);
        let mut blas = Blas::build(balls(150, box_every, triangle_every, 19), &params);
        let rays = rays(23);
        let before = closest_in_packets(&blas, &rays);
        blas.update(|g| {
            for (c, r) in &mut g.spheres[1..] {
                *c += Vec3::new(0.3, 0.1, -0.2);
                *r *= 1.1;
            }
        })
        .unwrap();
        let moved = blas.geometry().clone();
        let brute = Blas::build(moved, &BlasParams::new(None, BvhWidth::Eight));
        let expected = closest_each(&brute, &rays);
        let blocked: Vec<bool> = rays.iter().map(|r| brute.occluded(r)).collect();
        assert_ne!(before, expected, "the move changes some hits");
        assert_eq!(closest_in_packets(&blas, &rays), expected);
        assert_eq!(closest_each(&blas, &rays), expected);
        assert_eq!(occluded_each(&blas, &rays), blocked);
    }
}
