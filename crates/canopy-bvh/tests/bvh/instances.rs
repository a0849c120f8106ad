//! Instances (TLAS over BLAS) against brute force: every builder × layout × kernel gives,
//! for every ray, the hit of a loop over every instance and every primitive. Transforms
//! include rotations, mirrors (negative determinant) and non-uniform scale.

use crate::common;
use common::uniform;

use canopy_bvh::{
    intersect_triangle, Aabb, Blas, BlasParams, Boxes, Builder, BvhWidth, Geometry, Hit, Instance,
    InstanceError, Isa, Ray, RayQuery, RefitError, ShearedRay, Tlas, TriangleMesh, ALL_MASKS,
};
use glam::{Affine3A, Quat, Vec3};

/// A soup of `n` small triangles in the unit cube, sharing vertices in fans.
fn mesh(n: usize, seed: u32) -> TriangleMesh {
    let mut next = uniform(seed);
    let mut vertices = Vec::new();
    let mut indices = Vec::new();
    for _ in 0..n.div_ceil(2) {
        let a = Vec3::new(next(), next(), next());
        let first = vertices.len() as u32;
        for _ in 0..4 {
            vertices.push(a + (Vec3::new(next(), next(), next()) - 0.5) * 0.5);
        }
        indices.push([first, first + 1, first + 2]);
        indices.push([first, first + 2, first + 3]);
    }
    indices.truncate(n);
    TriangleMesh::new(vertices, indices).unwrap()
}

/// Rotation, non-uniform scale (mirrored where `mirror`) and translation.
fn transform(next: &mut impl FnMut() -> f32, mirror: bool) -> Affine3A {
    let axis = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize_or(Vec3::Y);
    let rotation = Quat::from_axis_angle(axis, next() * std::f32::consts::TAU);
    let mut scale = Vec3::new(0.3 + 1.7 * next(), 0.3 + 1.7 * next(), 0.3 + 1.7 * next());
    if mirror {
        scale.y = -scale.y;
    }
    let translation = (Vec3::new(next(), next(), next()) - 0.5) * 4.0;
    Affine3A::from_scale_rotation_translation(scale, rotation, translation)
}

/// Three meshes placed 24 times: every fourth instance mirrored, masks 1, 2, 4 in turn.
fn scene() -> (Vec<TriangleMesh>, Vec<Instance>) {
    let meshes = vec![mesh(150, 11), mesh(60, 12), mesh(1, 13)];
    let mut next = uniform(99);
    let instances = (0..24)
        .map(|i| {
            Instance::new(i % 3, transform(&mut next, i % 4 == 3))
                .with_mask(1 << (i % 3))
                .with_id(1000 + i)
        })
        .collect();
    (meshes, instances)
}

fn rays(count: usize, seed: u32) -> Vec<Ray> {
    let mut next = uniform(seed);
    (0..count)
        .map(|i| {
            let o = (Vec3::new(next(), next(), next()) - 0.5) * 12.0;
            let towards = (Vec3::new(next(), next(), next()) - 0.5) * 3.0 + 0.5;
            let t_max = if i % 7 == 0 { 2.0 } else { f32::INFINITY };
            Ray::new(o, (towards - o).normalize(), 0.0, t_max)
        })
        .collect()
}

/// The closest hit by a loop over every instance and every triangle, each tested in the
/// instance's space; ties to the lower instance, then primitive.
fn brute_force(
    meshes: &[TriangleMesh],
    instances: &[Instance],
    ray: &Ray,
    mask: u32,
) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    for (inst, instance) in instances.iter().enumerate() {
        if instance.mask & mask == 0 {
            continue;
        }
        let local = instance.ray_to_local(ray);
        let sheared = ShearedRay::new(&local);
        let mesh = &meshes[instance.blas as usize];
        for prim in 0..mesh.len() as u32 {
            if let Some(h) = intersect_triangle(&mesh.vertices_of(prim), &local, &sheared) {
                let hit = Hit {
                    inst: inst as u32,
                    ..Hit::new(prim, h)
                };
                if best.is_none_or(|b| hit.is_before(&b)) {
                    best = Some(hit);
                }
            }
        }
    }
    best
}

fn bits(hit: Option<Hit>) -> Option<(u32, u32, u32, u32, u32)> {
    hit.map(|h| (h.inst, h.prim, h.t.to_bits(), h.u.to_bits(), h.v.to_bits()))
}

fn tlas(params: &BlasParams, isa: Isa) -> Tlas<Blas<TriangleMesh>> {
    let (meshes, instances) = scene();
    let blases = meshes
        .into_iter()
        .map(|m| {
            let mut blas = Blas::build(m, params);
            if let Some(tree) = blas.tree_mut() {
                tree.set_isa(isa).unwrap();
            }
            blas
        })
        .collect();
    let mut tlas = Tlas::build(blases, instances, params).unwrap();
    tlas.set_isa(isa).unwrap();
    tlas
}

#[test]
fn every_builder_layout_and_kernel_gives_brute_force_hits_through_instances() {
    let (meshes, instances) = scene();
    let rays = rays(1500, 5);
    let masks = [ALL_MASKS, 0b101];
    let expected: Vec<Vec<Option<Hit>>> = masks
        .iter()
        .map(|&m| {
            rays.iter()
                .map(|r| brute_force(&meshes, &instances, r, m))
                .collect()
        })
        .collect();
    let hits = expected[0].iter().filter(|h| h.is_some()).count();
    assert!(hits > rays.len() / 4, "the rays should often hit: {hits}");
    let mirrored_hits = expected[0]
        .iter()
        .flatten()
        .filter(|h| h.inst % 4 == 3)
        .count();
    assert!(
        mirrored_hits > 20,
        "mirrored instances should be hit: {mirrored_hits}"
    );
    let builders = Builder::ALL.iter().map(|&b| Some(b)).chain([None]);
    for builder in builders {
        for width in BvhWidth::ALL {
            for isa in Isa::supported() {
                let params = BlasParams::new(builder, width);
                let tlas = tlas(&params, isa);
                let name = format!("{builder:?} x{width} {isa}");
                for (m, &mask) in masks.iter().enumerate() {
                    for (i, ray) in rays.iter().enumerate() {
                        let want = expected[m][i];
                        let got = tlas.intersect_masked(ray, mask);
                        assert_eq!(bits(got), bits(want), "{name} mask {mask:b} ray {i}");
                        assert_eq!(
                            tlas.occluded_masked(ray, mask),
                            want.is_some(),
                            "{name} mask {mask:b} ray {i}"
                        );
                    }
                    let mut batch = vec![None; rays.len()];
                    tlas.intersect_batch(&rays, &mut batch, mask);
                    let mut blocked = vec![false; rays.len()];
                    tlas.occluded_batch(&rays, &mut blocked, mask);
                    for i in 0..rays.len() {
                        assert_eq!(bits(batch[i]), bits(expected[m][i]), "{name} batch {i}");
                        assert_eq!(blocked[i], expected[m][i].is_some(), "{name} batch {i}");
                    }
                }
            }
        }
    }
}

/// Baking every instance's triangles into world space gives the same hits, up to the
/// rounding of the transforms: the same instance and primitive, t within 1e-4 relative
/// (where two surfaces lie within that of each other along a ray, either may win).
#[test]
fn instanced_hits_equal_hits_on_the_meshes_baked_into_the_world() {
    let (meshes, instances) = scene();
    let tlas = tlas(&BlasParams::default(), Isa::best());
    let mut baked = Vec::new();
    let mut owner = Vec::new();
    for (inst, instance) in instances.iter().enumerate() {
        let mesh = &meshes[instance.blas as usize];
        for prim in 0..mesh.len() as u32 {
            baked.push(mesh.vertices_of(prim).map(|v| instance.point_to_world(v)));
            owner.push((inst as u32, prim));
        }
    }
    let (mut same, mut near_ties) = (0, 0);
    for ray in rays(3000, 8) {
        let sheared = ShearedRay::new(&ray);
        let mut world: Vec<(f32, usize)> = baked
            .iter()
            .enumerate()
            .filter_map(|(k, v)| intersect_triangle(v, &ray, &sheared).map(|h| (h.t, k)))
            .collect();
        world.sort_by(|a, b| a.0.total_cmp(&b.0));
        let got = tlas.intersect(&ray);
        match (got, world.first()) {
            (None, None) => {}
            (Some(h), Some(&(t, k))) => {
                assert!((h.t - t).abs() <= 1e-4 * t.max(1.0), "{} vs {t}", h.t);
                if (h.inst, h.prim) == owner[k] {
                    same += 1;
                } else {
                    // Another surface within rounding of the first.
                    let second = world.get(1).map_or(f32::INFINITY, |w| w.0);
                    assert!(second - t <= 1e-4 * t.max(1.0), "{h:?} vs {:?}", owner[k]);
                    near_ties += 1;
                }
            }
            (got, first) => {
                // Only a ray grazing an edge may hit in one space and miss in the other.
                panic!("{got:?} vs {first:?} on {ray:?}");
            }
        }
    }
    assert!(same > 500, "{same} agreeing hits");
    assert!(near_ties <= same / 100, "{near_ties} near ties");
}

/// One instance with the identity transform answers exactly as its structure alone.
#[test]
fn one_identity_instance_is_its_structure() {
    let mesh = mesh(400, 21);
    let params = BlasParams::default();
    let blas = Blas::build(mesh.clone(), &params);
    let tlas = Tlas::build(
        vec![Blas::build(mesh, &params)],
        vec![Instance::new(0, Affine3A::IDENTITY)],
        &params,
    )
    .unwrap();
    for ray in rays(2000, 3) {
        assert_eq!(bits(tlas.intersect(&ray)), bits(blas.intersect(&ray)));
        assert_eq!(tlas.occluded(&ray), blas.occluded(&ray));
    }
    // An empty structure beside it changes nothing but the instance index.
    let beside_empty: Tlas<Blas<TriangleMesh>> = Tlas::build(
        vec![Blas::build(TriangleMesh::default(), &params), blas.clone()],
        vec![
            Instance::new(0, Affine3A::IDENTITY),
            Instance::new(1, Affine3A::IDENTITY),
        ],
        &params,
    )
    .unwrap();
    for ray in rays(500, 9) {
        let want = blas.intersect(&ray).map(|h| Hit { inst: 1, ..h });
        assert_eq!(bits(beside_empty.intersect(&ray)), bits(want));
    }
    // A mask that the instance does not take sees nothing.
    let masked = Tlas::build(
        vec![blas],
        vec![Instance::new(0, Affine3A::IDENTITY).with_mask(2)],
        &params,
    )
    .unwrap();
    assert!(rays(200, 4)
        .iter()
        .all(|r| masked.intersect_masked(r, 1).is_none()));
}

/// Moving the instances rebuilds the top tree: the hits are those of a TLAS built with
/// the new transforms from the start.
#[test]
fn moved_instances_answer_as_instances_placed_there() {
    let params = BlasParams::default();
    let mut moving = tlas(&params, Isa::best());
    let mut next = uniform(1234);
    let transforms: Vec<Affine3A> = (0..24).map(|i| transform(&mut next, i % 5 == 0)).collect();
    moving.set_transforms(&transforms).unwrap();
    let (meshes, instances) = scene();
    let placed: Vec<Instance> = instances
        .iter()
        .zip(&transforms)
        .map(|(i, &t)| i.with_transform(t))
        .collect();
    for ray in rays(1000, 6) {
        let want = brute_force(&meshes, &placed, &ray, ALL_MASKS);
        assert_eq!(bits(moving.intersect(&ray)), bits(want));
    }
    // A bad transform changes nothing.
    let mut bad = transforms.clone();
    bad[7] = Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0));
    assert_eq!(
        moving.set_transforms(&bad).unwrap_err(),
        InstanceError::Singular {
            instance: 7,
            determinant: 0.0
        }
    );
    assert_eq!(moving.instances()[7].to_world(), &transforms[7]);
}

#[test]
fn bad_instances_are_refused_by_name() {
    let blases = vec![Blas::build(mesh(10, 1), &BlasParams::default())];
    let params = BlasParams::default();
    let nan = Affine3A::from_translation(Vec3::new(f32::NAN, 0.0, 0.0));
    let err = Tlas::build(blases.clone(), vec![Instance::new(0, nan)], &params).unwrap_err();
    assert_eq!(err, InstanceError::NonFinite { instance: 0 });
    let instances = vec![
        Instance::new(0, Affine3A::IDENTITY),
        Instance::new(3, Affine3A::IDENTITY),
    ];
    let err = Tlas::build(blases, instances, &params).unwrap_err();
    assert!(
        err.to_string().contains("instance 1 places structure 3"),
        "{err}"
    );
}

/// Refit after moving vertices answers as a structure built over the moved mesh, in every
/// layout; after spatial splits it is refused and the mesh is left as it was.
#[test]
fn refit_after_moving_vertices_answers_as_a_rebuild() {
    let mesh = mesh(600, 31);
    let mut next = uniform(32);
    let moved: Vec<Vec3> = mesh
        .vertices()
        .iter()
        .map(|v| *v + Vec3::new(next(), next(), next()) * 0.2 + Vec3::new(0.0, v.x * 0.5, 0.0))
        .collect();
    let rays = rays(2000, 33);
    for width in BvhWidth::ALL {
        let params = BlasParams::new(Some(Builder::BinnedSah), width);
        let mut refitted = Blas::build(mesh.clone(), &params);
        refitted
            .update(|m| m.set_vertices(moved.clone()).unwrap())
            .unwrap();
        let boxes: Vec<Aabb> = (0..600).map(|p| refitted.geometry().bounds(p)).collect();
        refitted.tree().unwrap().validate(&boxes).unwrap();
        let rebuilt = Blas::build(refitted.geometry().clone(), &BlasParams::new(None, width));
        for ray in &rays {
            assert_eq!(
                bits(refitted.intersect(ray)),
                bits(rebuilt.intersect(ray)),
                "x{width}"
            );
            assert_eq!(refitted.occluded(ray), rebuilt.occluded(ray), "x{width}");
        }
    }
    let mut split = Blas::build(
        mesh.clone(),
        &BlasParams::new(Some(Builder::Sbvh), BvhWidth::Eight),
    );
    if split.tree().unwrap().view().has_spatial_splits() {
        let err = split.update(|m| m.set_vertices(moved.clone()).unwrap());
        assert_eq!(err, Err(RefitError::SpatialSplits));
        assert_eq!(split.geometry().vertices(), mesh.vertices());
    }
}

/// Boxes as user primitives, instanced: brute force's answer, and a BLAS of no
/// primitives answers nothing.
#[test]
fn boxes_and_empty_structures_through_instances() {
    let mut next = uniform(41);
    let boxes: Vec<Aabb> = (0..300)
        .map(|_| {
            let a = Vec3::new(next(), next(), next()) * 4.0;
            Aabb::new(a, a + Vec3::new(next(), next(), next()) * 0.3)
        })
        .collect();
    let params = BlasParams::default();
    let blases = vec![
        Blas::build(Boxes(boxes.clone()), &params),
        Blas::build(Boxes(Vec::new()), &params),
    ];
    let to_world = Affine3A::from_rotation_y(0.7) * Affine3A::from_translation(Vec3::splat(-2.0));
    let instances = vec![
        Instance::new(0, to_world),
        Instance::new(1, Affine3A::IDENTITY),
    ];
    let tlas = Tlas::build(blases, instances.clone(), &params).unwrap();
    for ray in rays(2000, 42) {
        let local = instances[0].ray_to_local(&ray);
        let want = boxes
            .iter()
            .enumerate()
            .filter_map(|(i, b)| b.ray_entry(&local).map(|t| Hit::new(i as u32, t.into())))
            .reduce(|a, b| if b.is_before(&a) { b } else { a });
        assert_eq!(bits(tlas.intersect(&ray)), bits(want));
        assert!(tlas.blases()[1].intersect(&ray).is_none());
    }
}

/// Counting a query through instances changes no answer and counts the work of both
/// levels: at least the top tree's nodes and the primitives of the instance hit.
#[test]
fn counted_queries_through_instances_answer_alike_and_count_both_levels() {
    let tlas = tlas(&BlasParams::default(), Isa::best());
    let mut hits = 0;
    for ray in rays(500, 17) {
        let mut stats = canopy_bvh::TraversalStats::default();
        let hit = tlas.intersect_counted(&ray, ALL_MASKS, &mut stats);
        assert_eq!(bits(hit), bits(tlas.intersect(&ray)));
        assert_eq!(stats, tlas.traversal_cost(&ray));
        if hit.is_some() {
            hits += 1;
            assert!(
                stats.nodes_visited >= 2 && stats.primitives_tested >= 1,
                "{stats:?}"
            );
        }
    }
    assert!(hits > 50);
}

/// The closure forms (`closest_hits`, `any_hits`) make their rays a slice at a time
/// (`CLOSURE_CHUNK`): across the slices' edges, coherent or not, through instances and
/// through one structure alone, every ray is made once and answered once, in order, as
/// the brute-force loop answers it.
#[test]
fn closure_batches_answer_every_ray_in_order_across_their_slices() {
    use canopy_bvh::{Coherence, RayBatch, CLOSURE_CHUNK};
    let (meshes, instances) = scene();
    let rays = rays(2 * CLOSURE_CHUNK + 37, 23);
    let instanced = tlas(&BlasParams::default(), Isa::best());
    let alone = Blas::build(meshes[0].clone(), &BlasParams::default());
    let alone_at = [Instance::new(0, Affine3A::IDENTITY)];
    for coherence in [Coherence::Incoherent, Coherence::Coherent] {
        for (name, structure, meshes, placed) in [
            (
                "instances",
                &instanced as &dyn Answers,
                &meshes[..],
                &instances[..],
            ),
            (
                "one structure",
                &alone as &dyn Answers,
                &meshes[..1],
                &alone_at[..],
            ),
        ] {
            let (made, hits, blocked) = structure.answers(&rays, coherence);
            let context = format!("{name}, {coherence:?}");
            assert_eq!(
                made,
                (0..rays.len()).collect::<Vec<_>>(),
                "{context}: rays made"
            );
            for (i, ray) in rays.iter().enumerate() {
                let want = brute_force(meshes, placed, ray, ALL_MASKS);
                assert_eq!(hits[i].0, i, "{context}: hits in order");
                assert_eq!(bits(hits[i].1), bits(want), "{context}: ray {i}");
                assert_eq!(
                    blocked[i],
                    (i, want.is_some()),
                    "{context}: ray {i} blocked"
                );
            }
        }
    }

    /// Both closure forms over `rays`: the rays made (in the order asked for), and the
    /// answers as given (ray number, answer).
    trait Answers {
        #[allow(clippy::type_complexity)]
        fn answers(
            &self,
            rays: &[Ray],
            coherence: Coherence,
        ) -> (Vec<usize>, Vec<(usize, Option<Hit>)>, Vec<(usize, bool)>);
    }
    impl<Q: RayQuery> Answers for Q {
        fn answers(
            &self,
            rays: &[Ray],
            coherence: Coherence,
        ) -> (Vec<usize>, Vec<(usize, Option<Hit>)>, Vec<(usize, bool)>) {
            let batch = RayBatch::new(rays.len()).with(coherence);
            let (mut made, mut hits, mut blocked) = (Vec::new(), Vec::new(), Vec::new());
            let ray = |i: usize| {
                made.push(i);
                rays[i]
            };
            self.closest_hits(batch, ray, |i, h| hits.push((i, h)), &mut ());
            self.any_hits(batch, |i| rays[i], |i, b| blocked.push((i, b)));
            (made, hits, blocked)
        }
    }
}
