//! The renderer's structure over its own primitives: moved in place and refitted
//! ([`Accel::update_primitives`]), it answers as a structure built anew over the moved
//! primitives does, in every width, by brute force too; a tree with spatial splits
//! refuses and stays as it was.

use canopy_bvh::{BuildParams, Builder, Ray, RayQuery, RefitError};
use canopy_render::geometry::{Shape, Triangle};
use canopy_render::scene::Primitive;
use canopy_render::{Accel, AccelKind, BvhWidth};
use glam::Vec3;
use std::sync::Arc;

/// A xorshift stream of numbers in [0, 1).
fn uniform(mut state: u32) -> impl FnMut() -> f32 {
    move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state >> 8) as f32 / (1 << 24) as f32
    }
}

/// Long slivers in every direction (spatial splits cut them) and small triangles.
fn triangles(seed: u32) -> Vec<[Vec3; 3]> {
    let mut next = uniform(seed);
    let mut point = move || Vec3::new(next(), next(), next()) * 4.0;
    (0..600)
        .map(|i| {
            let (a, b) = (point(), point());
            match i % 3 {
                0 => [a, b, a + 0.01 * (b - a) + Vec3::splat(0.02)],
                _ => [
                    a,
                    a + 0.2 * (b - a).normalize(),
                    a + Vec3::new(0.0, 0.15, 0.1),
                ],
            }
        })
        .collect()
}

fn primitives(triangles: &[[Vec3; 3]]) -> Arc<Vec<Primitive>> {
    Arc::new(
        triangles
            .iter()
            .map(|&[a, b, c]| Primitive {
                shape: Shape::Triangle(Triangle::new(a, b, c)),
                material: 0,
            })
            .collect(),
    )
}

fn rays(seed: u32) -> Vec<Ray> {
    let mut next = uniform(seed);
    (0..2000)
        .map(|_| {
            let o = Vec3::new(next(), next(), next()) * 8.0 - Vec3::splat(2.0);
            let target = Vec3::new(next(), next(), next()) * 4.0;
            Ray::new(o, (target - o).normalize(), 0.0, f32::INFINITY)
        })
        .collect()
}

/// Each ray's closest hit (primitive and distance bits) and any-hit answer.
fn answers(accel: &Accel, rays: &[Ray]) -> Vec<(Option<(u32, u32)>, bool)> {
    rays.iter()
        .map(|r| {
            let hit = accel.intersect(r).map(|h| (h.prim, h.t.to_bits()));
            (hit, accel.occluded(r))
        })
        .collect()
}

#[test]
fn moved_primitives_are_refitted_and_answer_as_a_new_build() {
    let (before, after) = (triangles(3), triangles(4));
    let rays = rays(5);
    let mut kinds = vec![(AccelKind::None, BvhWidth::Two)];
    for builder in [Builder::BinnedSah, Builder::Lbvh, Builder::Ploc] {
        kinds.extend(BvhWidth::ALL.map(|width| (AccelKind::Bvh(builder), width)));
    }
    let params = BuildParams::default();
    for (kind, width) in kinds {
        let mut accel = Accel::build(kind, width, &primitives(&before), &params);
        accel
            .update_primitives(|prims| {
                for (p, &[a, b, c]) in prims.iter_mut().zip(&after) {
                    p.shape = Shape::Triangle(Triangle::new(a, b, c));
                }
            })
            .unwrap();
        let fresh = Accel::build(kind, width, &primitives(&after), &params);
        assert_eq!(
            answers(&accel, &rays),
            answers(&fresh, &rays),
            "{kind} {width}"
        );
        if let Some(tree) = accel.tree() {
            let boxes: Vec<_> = accel
                .primitives()
                .iter()
                .map(|p| p.shape.bounds())
                .collect();
            tree.validate(&boxes).unwrap();
        }
    }
}

#[test]
fn a_tree_with_spatial_splits_refuses_to_be_refitted_and_stays_as_it_was() {
    let before = triangles(6);
    let rays = rays(7);
    let params = BuildParams::default();
    let sbvh = AccelKind::Bvh(Builder::Sbvh);
    let mut accel = Accel::build(sbvh, BvhWidth::Eight, &primitives(&before), &params);
    assert!(accel.tree().unwrap().view().has_spatial_splits());
    let expected = answers(&accel, &rays);
    let mut edited = false;
    let refused = accel.update_primitives(|_| edited = true);
    assert!(
        matches!(refused, Err(RefitError::SpatialSplits)),
        "{refused:?}"
    );
    assert!(!edited, "the edit ran");
    assert_eq!(answers(&accel, &rays), expected);
}
