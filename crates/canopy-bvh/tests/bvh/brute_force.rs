//! Every builder must answer closest-hit and any-hit queries exactly as a loop over all
//! primitives does. Primitives here are boxes, tested with the same slab test.

use crate::common::{Blocks, Closest};
use canopy_bvh::{
    build, optimize, Aabb, BuildParams, Builder, Bvh4, Bvh8, Hit, Isa, OptimizeBudget, Ray, Tree,
};
use glam::Vec3;
use proptest::prelude::*;

fn brute_force_closest(boxes: &[Aabb], ray: &Ray) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    for (i, b) in boxes.iter().enumerate() {
        if let Some(t) = b.ray_entry(ray) {
            let hit = Hit::new(i as u32, t.into());
            if best.is_none_or(|b| hit.is_before(&b)) {
                best = Some(hit);
            }
        }
    }
    best
}

fn check_against_brute_force(boxes: &[Aabb], rays: &[Ray], params: &BuildParams) {
    for &builder in Builder::ALL {
        let bvh = build(builder, boxes, params);
        bvh.validate(boxes)
            .unwrap_or_else(|e| panic!("{builder}: {e}"));
        let stats = bvh.stats(&params.sah);
        assert!(stats.max_leaf_size <= params.max_leaf_size.max(1) as usize);
        let mut bvh4 = Bvh4::from_bvh2(&bvh);
        let mut bvh8 = Bvh8::from_bvh2(&bvh);
        bvh4.validate(boxes)
            .unwrap_or_else(|e| panic!("{builder} x4: {e}"));
        bvh8.validate(boxes)
            .unwrap_or_else(|e| panic!("{builder} x8: {e}"));
        let closest: Closest<f32> = &|p, r| boxes[p as usize].ray_entry(r);
        let any: Blocks = &|p, r| boxes[p as usize].ray_entry(r).is_some();
        // Every node kernel this CPU has (the scalar twin included) on the same rays.
        for isa in Isa::supported() {
            bvh4.set_isa(isa).unwrap();
            bvh8.set_isa(isa).unwrap();
            for ray in rays {
                let expected = brute_force_closest(boxes, ray);
                assert_eq!(
                    bvh4.intersect(ray, closest),
                    expected,
                    "{builder} x4 {isa}: {ray:?}"
                );
                assert_eq!(
                    bvh8.intersect(ray, closest),
                    expected,
                    "{builder} x8 {isa}: {ray:?}"
                );
                let hit = expected.is_some();
                assert_eq!(bvh4.occluded(ray, any), hit, "{builder} x4 {isa}: {ray:?}");
                assert_eq!(bvh8.occluded(ray, any), hit, "{builder} x8 {isa}: {ray:?}");
            }
        }
        // The GPU layout, walked by its CPU twin.
        let gpu = Tree::for_gpu(&bvh);
        gpu.validate(boxes)
            .unwrap_or_else(|e| panic!("{builder} gpu layout: {e}"));
        for ray in rays {
            let expected = brute_force_closest(boxes, ray);
            assert_eq!(
                gpu.intersect_counted(ray, closest, &mut ()),
                expected,
                "{builder} gpu layout: {ray:?}"
            );
            assert_eq!(
                gpu.occluded(ray, any),
                expected.is_some(),
                "{builder} gpu layout"
            );
        }
        // The binary tree (the wide ones are checked per kernel above), and the same tree
        // after a pass of the optimiser.
        let (optimized, report) = optimize(&bvh, &params.sah, OptimizeBudget::Passes(1));
        optimized
            .validate(boxes)
            .unwrap_or_else(|e| panic!("{builder} optimised: {e}"));
        assert!(
            report.sah_after <= report.sah_before * (1.0 + 1e-5),
            "{builder}: {report:?}"
        );
        for ray in rays {
            let expected = brute_force_closest(boxes, ray);
            for (tree, what) in [(&bvh, "x2"), (&optimized, "x2 optimised")] {
                assert_eq!(
                    tree.intersect(ray, closest),
                    expected,
                    "{builder} {what}: closest hit for {ray:?}"
                );
                let hit = expected.is_some();
                assert_eq!(
                    tree.occluded(ray, any),
                    hit,
                    "{builder} {what}: any hit for {ray:?}"
                );
            }
        }
    }
}

fn vec3(range: std::ops::Range<f32>) -> impl Strategy<Value = Vec3> {
    (range.clone(), range.clone(), range).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

fn random_box() -> impl Strategy<Value = Aabb> {
    (vec3(-10.0..10.0), vec3(0.0..2.0)).prop_map(|(min, size)| Aabb::new(min, min + size))
}

/// Rays from anywhere in (and around) the scene, in any direction, some with short t_max.
fn random_ray() -> impl Strategy<Value = Ray> {
    (
        vec3(-15.0..15.0),
        vec3(-1.0..1.0),
        prop_oneof![Just(f32::INFINITY), 0.1f32..20.0],
    )
        .prop_filter("non-zero direction", |(_, d, _)| d.length() > 1e-3)
        .prop_map(|(o, d, t_max)| Ray::new(o, d.normalize(), 0.0, t_max))
}

/// Rays aimed at the centre of one of the boxes, so that most of them hit something.
fn rays_at(boxes: &[Aabb], origins: &[Vec3]) -> Vec<Ray> {
    origins
        .iter()
        .zip(boxes.iter().cycle())
        .filter_map(|(&o, b)| {
            let d = b.center() - o;
            (d.length() > 1e-4).then(|| Ray::new(o, d.normalize(), 0.0, f32::INFINITY))
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn random_boxes_match_brute_force(
        boxes in prop::collection::vec(random_box(), 1..300),
        rays in prop::collection::vec(random_ray(), 32),
        origins in prop::collection::vec(vec3(-15.0..15.0), 32),
        max_leaf_size in 1u32..8,
        max_duplication in prop_oneof![Just(0.3f32), 0.0f32..3.0],
    ) {
        let params = BuildParams { max_leaf_size, max_duplication, ..BuildParams::default() };
        let mut all_rays = rays;
        all_rays.extend(rays_at(&boxes, &origins));
        check_against_brute_force(&boxes, &all_rays, &params);
    }

    #[test]
    fn coincident_centroids_match_brute_force(
        sizes in prop::collection::vec(vec3(0.0..3.0), 1..100),
        rays in prop::collection::vec(random_ray(), 32),
    ) {
        // All boxes share one centre: no split plane separates them.
        let boxes: Vec<Aabb> = sizes.iter().map(|&s| Aabb::new(-s, s)).collect();
        check_against_brute_force(&boxes, &rays, &BuildParams::default());
    }

    #[test]
    fn flat_boxes_match_brute_force(
        corners in prop::collection::vec((vec3(-10.0..10.0), 0.0f32..3.0, 0.0f32..3.0), 1..100),
        rays in prop::collection::vec(random_ray(), 32),
    ) {
        // Zero thickness in z, like axis-aligned triangles.
        let boxes: Vec<Aabb> = corners
            .iter()
            .map(|&(min, w, h)| Aabb::new(min, min + Vec3::new(w, h, 0.0)))
            .collect();
        check_against_brute_force(&boxes, &rays, &BuildParams::default());
    }

    #[test]
    fn huge_and_tiny_boxes_together_match_brute_force(
        tiny in prop::collection::vec(vec3(-1.0..1.0), 1..100),
        rays in prop::collection::vec(random_ray(), 32),
    ) {
        let mut boxes: Vec<Aabb> = tiny.iter().map(|&p| Aabb::new(p, p + Vec3::splat(1e-4))).collect();
        boxes.push(Aabb::new(Vec3::splat(-1e4), Vec3::splat(1e4)));
        boxes.push(Aabb::new(Vec3::new(-1e3, -2.0, -1e3), Vec3::new(1e3, -1.0, 1e3)));
        check_against_brute_force(&boxes, &rays, &BuildParams::default());
    }
}

#[test]
fn empty_input_gives_an_empty_tree_that_never_hits() {
    for &builder in Builder::ALL {
        let bvh = build(builder, &[], &BuildParams::default());
        assert_eq!(bvh.validate(&[]), Ok(()));
        let ray = Ray::new(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY);
        assert_eq!(bvh.intersect(&ray, |_, _| Some(1.0)), None);
        assert!(!bvh.occluded(&ray, |_, _| true));
        let always: Closest<f32> = &|_, _| Some(1.0);
        assert_eq!(Bvh4::from_bvh2(&bvh).intersect(&ray, always), None);
    }
}

#[test]
fn one_primitive_gives_a_single_leaf() {
    let boxes = [Aabb::new(Vec3::ZERO, Vec3::ONE)];
    for &builder in Builder::ALL {
        let bvh = build(builder, &boxes, &BuildParams::default());
        assert_eq!(bvh.nodes().len(), 1, "{builder}");
        assert!(bvh.nodes()[0].is_leaf());
        let ray = Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z, 0.0, f32::INFINITY);
        let entry: Closest<f32> = &|p, r| boxes[p as usize].ray_entry(r);
        let hit = Bvh8::from_bvh2(&bvh).intersect(&ray, entry);
        assert_eq!(hit, Some(Hit::new(0, 1.0.into())));
    }
}

/// The i-th box of a pattern.
type BoxPattern = fn(usize) -> Aabb;

/// Sizes 1..=100 of several degenerate patterns, every builder: well-formed trees.
#[test]
fn every_builder_makes_valid_trees_on_degenerate_patterns_of_every_size() {
    let patterns: [(&str, BoxPattern); 4] = [
        ("same box", |_| Aabb::new(Vec3::ZERO, Vec3::ONE)),
        ("points on a line", |i| {
            Aabb::new(Vec3::new(i as f32, 0.0, 0.0), Vec3::new(i as f32, 0.0, 0.0))
        }),
        ("flat grid", |i| {
            let p = Vec3::new((i % 7) as f32, (i / 7) as f32, 0.0);
            Aabb::new(p, p + Vec3::new(1.0, 1.0, 0.0))
        }),
        ("exponential sizes", |i| {
            Aabb::new(
                Vec3::splat(-(1.5f32).powi(i as i32 % 40)),
                Vec3::splat((1.5f32).powi(i as i32 % 40)),
            )
        }),
    ];
    for (name, pattern) in patterns {
        for n in 1..=100 {
            let boxes: Vec<Aabb> = (0..n).map(pattern).collect();
            for &builder in Builder::ALL {
                for max_leaf_size in [1, 4] {
                    let params = BuildParams {
                        max_leaf_size,
                        ..BuildParams::default()
                    };
                    let bvh = build(builder, &boxes, &params);
                    bvh.validate(&boxes)
                        .unwrap_or_else(|e| panic!("{builder} on {name} x{n}: {e}"));
                    assert!(
                        bvh.stats(&params.sah).max_leaf_size <= max_leaf_size as usize,
                        "{builder} on {name} x{n}"
                    );
                    Bvh4::from_bvh2(&bvh)
                        .validate(&boxes)
                        .unwrap_or_else(|e| panic!("{builder} x4 on {name} x{n}: {e}"));
                    Bvh8::from_bvh2(&bvh)
                        .validate(&boxes)
                        .unwrap_or_else(|e| panic!("{builder} x8 on {name} x{n}: {e}"));
                    let (optimized, _) = optimize(&bvh, &params.sah, OptimizeBudget::Passes(2));
                    optimized
                        .validate(&boxes)
                        .unwrap_or_else(|e| panic!("{builder} optimised on {name} x{n}: {e}"));
                }
            }
        }
    }
}

#[test]
fn two_identical_boxes_tie_to_the_lower_index() {
    let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
    let boxes = [b, b];
    let params = BuildParams {
        max_leaf_size: 1,
        ..BuildParams::default()
    };
    let bvh = build(Builder::BinnedSah, &boxes, &params);
    let ray = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X, 0.0, f32::INFINITY);
    let hit = bvh.intersect(&ray, |p, r| boxes[p as usize].ray_entry(r));
    assert_eq!(hit, Some(Hit::new(0, 1.0.into())));
}

#[test]
fn every_leaf_respects_max_leaf_size_on_a_large_input() {
    let boxes: Vec<Aabb> = (0..5000)
        .map(|i| {
            let p = Vec3::new((i % 17) as f32, (i % 31) as f32, (i % 7) as f32);
            Aabb::new(p, p + Vec3::splat(0.5))
        })
        .collect();
    for &builder in Builder::ALL {
        for max_leaf_size in [1, 2, 4, 16] {
            let params = BuildParams {
                max_leaf_size,
                ..BuildParams::default()
            };
            let bvh = build(builder, &boxes, &params);
            bvh.validate(&boxes)
                .unwrap_or_else(|e| panic!("{builder}: {e}"));
            assert!(
                bvh.stats(&params.sah).max_leaf_size <= max_leaf_size as usize,
                "{builder}"
            );
        }
    }
}
