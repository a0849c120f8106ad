//! Point queries, winding numbers and every hit along a ray against brute force: every
//! builder × layout (and brute force itself) gives a loop over every triangle's answer,
//! for a structure on its own and for instances placed by rotations, mirrors and
//! non-uniform scale.

use crate::common;
use common::{structures, torus, uniform};

use canopy_bvh::{
    closest_point_on_triangle, crosses_triangle, intersect_triangle, solid_angle, Blas, BlasParams,
    Builder, BvhWidth, Hit, HitsAlong, Instance, PrimHit, Ray, ShearedRay, SurfaceQuery, Tlas,
    TriangleMesh, ALL_MASKS, INSIDE_FAR_FIELD,
};
use glam::{Affine3A, Quat, Vec3};

/// Query points around `bounds`: inside, outside, near the surface and far away.
fn points(count: usize, seed: u32, scale: f32) -> Vec<Vec3> {
    let mut next = uniform(seed);
    (0..count)
        .map(|_| (Vec3::new(next(), next(), next()) - 0.5) * scale)
        .collect()
}

/// The nearest triangle by a loop over every one (`world` places the mesh), ties to
/// the lower instance, then triangle: (instance, triangle, distance).
fn nearest_by_loop(meshes: &[(&TriangleMesh, Affine3A)], query: Vec3) -> (u32, u32, f32) {
    let mut best = (u32::MAX, u32::MAX, f32::INFINITY);
    for (inst, (mesh, world)) in meshes.iter().enumerate() {
        for prim in 0..mesh.indices().len() as u32 {
            let v = mesh.vertices_of(prim).map(|x| world.transform_point3(x));
            let (point, _) = closest_point_on_triangle(query, &v);
            let d2 = point.distance_squared(query);
            if d2 < best.2 {
                best = (inst as u32, prim, d2);
            }
        }
    }
    (best.0, best.1, best.2.sqrt())
}

fn exact_winding_number(mesh: &TriangleMesh, query: Vec3) -> f64 {
    let total: f64 = (0..mesh.indices().len() as u32)
        .map(|p| solid_angle(query, &mesh.vertices_of(p)))
        .sum();
    total / (4.0 * std::f64::consts::PI)
}

#[test]
fn the_nearest_point_is_brute_forces_for_every_builder_and_layout() {
    let mesh = torus(24, 12);
    let queries = points(300, 7, 4.0);
    let expected: Vec<_> = queries
        .iter()
        .map(|&q| nearest_by_loop(&[(&mesh, Affine3A::IDENTITY)], q))
        .collect();
    for (name, blas) in structures(&mesh) {
        for (q, &(_, prim, distance)) in queries.iter().zip(&expected) {
            let found = blas
                .closest_point(*q, f32::INFINITY)
                .expect("a mesh has a nearest point");
            assert_eq!(
                (found.prim, found.distance),
                (prim, distance),
                "{name}, query {q}"
            );
            let v = mesh.vertices_of(found.prim);
            let at = v[0] + found.u * (v[1] - v[0]) + found.v * (v[2] - v[0]);
            assert!(
                at.distance(found.point) < 1e-5,
                "{name}: barycentrics name the point"
            );
            assert_eq!(blas.distance(*q), distance, "{name}");
        }
        // Nothing within a limit shorter than the distance.
        let q = Vec3::new(0.0, 0.0, 3.0);
        let d = blas.distance(q);
        assert!(blas.closest_point(q, d * 0.99).is_none(), "{name}");
        assert!(blas.closest_point(q, d).is_some(), "{name}");
    }
}

#[test]
fn winding_numbers_tell_inside_from_outside_for_every_builder_and_layout() {
    let mesh = torus(24, 12);
    let queries = points(400, 8, 3.2);
    for (name, blas) in structures(&mesh) {
        let (mut worst, mut worst_inside) = (0.0f64, 0.0f64);
        for &q in &queries {
            let exact = exact_winding_number(&mesh, q);
            let fast = blas.winding_number(q);
            worst = worst.max((fast - exact).abs());
            let coarse = blas.winding_number_within(q, INSIDE_FAR_FIELD);
            worst_inside = worst_inside.max((coarse - exact).abs());
            // The exact number is 0 or 1 up to rounding away from the surface.
            if blas.distance(q) > 1e-3 {
                assert_eq!(
                    blas.contains(q),
                    exact > 0.5,
                    "{name}: {q} (winding {fast})"
                );
                let signed = blas.signed_distance(q);
                assert_eq!(signed.abs(), blas.distance(q));
                assert_eq!(signed < 0.0, exact > 0.5, "{name}: negative inside");
            }
        }
        // Second-order far fields two radii away: about 1e-2 at worst here.
        assert!(worst < 0.03, "{name}: far-field error {worst}");
        // Inside tests' coarser far field: about 0.08 at worst here; the margin is 0.5.
        assert!(
            worst_inside < 0.15,
            "{name}: inside far-field error {worst_inside}"
        );
    }
}

#[test]
fn an_open_surface_has_fractional_winding_numbers() {
    // Half of the torus's triangles: points in the tube see part of a shell.
    let closed = torus(24, 12);
    let half: Vec<[u32; 3]> = closed.indices()[..closed.indices().len() / 2].to_vec();
    let open = TriangleMesh::new(closed.vertices().to_vec(), half).unwrap();
    let blas = Blas::build(open.clone(), &BlasParams::default());
    for q in points(200, 9, 3.0) {
        let (fast, exact) = (blas.winding_number(q), exact_winding_number(&open, q));
        assert!((fast - exact).abs() < 0.03, "{q}: {fast} against {exact}");
    }
}

/// Every hit that `along` counts by a loop over every triangle of every instance, sorted.
fn hits_by_loop(
    meshes: &[(&TriangleMesh, Instance)],
    ray: &Ray,
    mask: u32,
    along: HitsAlong,
) -> Vec<Hit> {
    let test = match along {
        HitsAlong::Crossings => crosses_triangle,
        HitsAlong::Triangles => intersect_triangle,
    };
    let mut hits = Vec::new();
    for (inst, (mesh, instance)) in meshes.iter().enumerate() {
        if instance.mask & mask == 0 {
            continue;
        }
        let local = instance.ray_to_local(ray);
        let sheared = ShearedRay::new(&local);
        for prim in 0..mesh.indices().len() as u32 {
            if let Some(h) = test(&mesh.vertices_of(prim), &local, &sheared) {
                hits.push(Hit {
                    inst: inst as u32,
                    ..Hit::new(prim, h)
                });
            }
        }
    }
    hits.sort_by(|a, b| {
        a.t.total_cmp(&b.t)
            .then((a.inst, a.prim).cmp(&(b.inst, b.prim)))
    });
    hits
}

fn rays(count: usize, seed: u32) -> Vec<Ray> {
    let mut next = uniform(seed);
    (0..count)
        .map(|i| {
            let o = (Vec3::new(next(), next(), next()) - 0.5) * 8.0;
            let towards = (Vec3::new(next(), next(), next()) - 0.5) * 2.0;
            let t_max = if i % 5 == 0 { 3.0 } else { f32::INFINITY };
            Ray::new(o, (towards - o).normalize(), 0.0, t_max)
        })
        .collect()
}

#[test]
fn every_hit_along_a_ray_is_brute_forces_for_every_builder_and_layout() {
    let mesh = torus(24, 12);
    let alone = [(&mesh, Instance::new(0, Affine3A::IDENTITY))];
    let mut crossed = 0;
    for (name, blas) in structures(&mesh) {
        for ray in rays(200, 10) {
            for along in [HitsAlong::Crossings, HitsAlong::Triangles] {
                let expected = hits_by_loop(&alone, &ray, ALL_MASKS, along);
                crossed += expected.len();
                let found = blas.hits(&ray, ALL_MASKS, along);
                assert_eq!(found, expected, "{name}, {along:?}: {ray:?}");
                assert_eq!(blas.count_hits(&ray, ALL_MASKS, along), expected.len());
            }
        }
    }
    assert!(crossed > 1000, "the rays cross the torus ({crossed} hits)");
}

/// Checks that `structure`'s batch forms answer `rays` as brute force answers each:
/// [`SurfaceQuery::hits_each`] lists each ray's hits after the ray before's, and
/// [`SurfaceQuery::count_hits_each`] counts them.
fn check_batch(
    name: &str,
    structure: &impl SurfaceQuery,
    meshes: &[(&TriangleMesh, Instance)],
    rays: &[Ray],
    mask: u32,
) -> usize {
    let mut listed = 0;
    for along in [HitsAlong::Crossings, HitsAlong::Triangles] {
        let expected: Vec<Vec<Hit>> = rays
            .iter()
            .map(|ray| hits_by_loop(meshes, ray, mask, along))
            .collect();
        let mut counts = vec![usize::MAX; rays.len()];
        structure.count_hits_each(rays, mask, along, &mut counts);
        let expected_counts: Vec<usize> = expected.iter().map(Vec::len).collect();
        assert_eq!(counts, expected_counts, "{name}, {along:?}, mask {mask}");
        // Left over from an earlier batch: cleared first.
        let mut hits = vec![
            Hit::new(
                7,
                PrimHit {
                    t: 1.0,
                    u: 0.0,
                    v: 0.0
                }
            );
            3
        ];
        counts.fill(usize::MAX);
        structure.hits_each(rays, mask, along, &mut hits, &mut counts);
        assert_eq!(counts, expected_counts, "{name}, {along:?}, mask {mask}");
        assert_eq!(hits, expected.concat(), "{name}, {along:?}, mask {mask}");
        listed += hits.len();
    }
    listed
}

/// Rays for a batch: [`rays`], with rays that miss everything among them (one that is
/// not traceable, one that leaves the scene at once).
fn batch_rays() -> Vec<Ray> {
    let mut batch = rays(150, 21);
    batch.insert(40, Ray::new(Vec3::NAN, Vec3::X, 0.0, f32::INFINITY));
    batch.insert(
        90,
        Ray::new(Vec3::splat(50.0), Vec3::ONE, 0.0, f32::INFINITY),
    );
    batch
}

#[test]
fn batches_of_rays_count_and_list_every_hit_as_brute_force_for_every_builder_and_layout() {
    let mesh = torus(24, 12);
    let alone = [(&mesh, Instance::new(0, Affine3A::IDENTITY))];
    let batch = batch_rays();
    let mut listed = 0;
    for (name, blas) in structures(&mesh) {
        listed += check_batch(&name, &blas, &alone, &batch, ALL_MASKS);
        // A structure placed alone as itself answers through its own batch walk; a mask
        // that refuses it leaves every ray without a hit.
        let index = 0;
        let masked = Instance::new(index, Affine3A::IDENTITY).with_mask(2);
        let top = Tlas::build(vec![blas], vec![masked], &BlasParams::default()).unwrap();
        let placed = [(&mesh, masked)];
        for mask in [ALL_MASKS, 1, 2] {
            check_batch(&format!("{name} alone"), &top, &placed, &batch, mask);
        }
    }
    assert!(listed > 1000, "the rays cross the torus ({listed} hits)");
}

fn placed(next: &mut impl FnMut() -> f32, mirror: bool) -> Affine3A {
    let axis = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize_or(Vec3::Y);
    let rotation = Quat::from_axis_angle(axis, next() * std::f32::consts::TAU);
    let mut scale = Vec3::new(0.4 + next(), 0.4 + next(), 0.4 + next());
    if mirror {
        scale.z = -scale.z;
    }
    let translation = (Vec3::new(next(), next(), next()) - 0.5) * 6.0;
    Affine3A::from_scale_rotation_translation(scale, rotation, translation)
}

#[test]
fn instances_answer_in_world_measure_for_every_top_builder_and_layout() {
    let meshes = [torus(16, 8), torus(10, 6)];
    let mut next = uniform(5);
    let instances: Vec<Instance> = (0..8)
        .map(|i| {
            let world = match i {
                0 => Affine3A::IDENTITY,
                _ => placed(&mut next, i % 3 == 2),
            };
            Instance::new(i % 2, world).with_mask(1 << (i % 2))
        })
        .collect();
    let world: Vec<(&TriangleMesh, Affine3A)> = instances
        .iter()
        .map(|i| (&meshes[i.blas as usize], *i.to_world()))
        .collect();
    let placed: Vec<(&TriangleMesh, Instance)> = instances
        .iter()
        .map(|i| (&meshes[i.blas as usize], *i))
        .collect();
    let queries = points(150, 12, 9.0);
    let blas_params = BlasParams::default();
    for builder in [None, Some(Builder::BinnedSah), Some(Builder::Ploc)] {
        for width in BvhWidth::ALL {
            let blases = meshes
                .iter()
                .map(|m| Blas::build(m.clone(), &blas_params))
                .collect();
            let tlas =
                Tlas::build(blases, instances.clone(), &BlasParams::new(builder, width)).unwrap();
            let name = format!("top {builder:?} width {width}");
            for &q in &queries {
                let (inst, prim, distance) = nearest_by_loop(&world, q);
                let found = tlas.closest_point(q, f32::INFINITY).unwrap();
                assert_eq!(
                    (found.inst, found.prim, found.distance),
                    (inst, prim, distance),
                    "{name}: {q}"
                );
                // Inside any one instance (a mirror keeps inside inside).
                let inside = instances.iter().any(|i| {
                    let local = i.to_local().transform_point3(q);
                    exact_winding_number(&meshes[i.blas as usize], local) > 0.5
                });
                if distance > 1e-3 {
                    assert_eq!(tlas.contains(q), inside, "{name}: {q}");
                }
            }
            for ray in rays(100, 13) {
                for mask in [ALL_MASKS, 1, 2] {
                    for along in [HitsAlong::Crossings, HitsAlong::Triangles] {
                        let expected = hits_by_loop(&placed, &ray, mask, along);
                        assert_eq!(tlas.hits(&ray, mask, along), expected, "{name}, {along:?}");
                        assert_eq!(tlas.count_hits(&ray, mask, along), expected.len());
                    }
                }
            }
            for mask in [ALL_MASKS, 1, 2] {
                check_batch(&name, &tlas, &placed, &batch_rays(), mask);
            }
        }
    }
}

#[test]
fn an_edited_mesh_is_measured_as_it_is_now() {
    let mut blas = Blas::build(torus(16, 8), &BlasParams::default());
    let in_tube = Vec3::new(1.0, 0.0, 0.0);
    assert!(blas.contains(in_tube));
    let before = blas.distance(Vec3::ZERO);
    blas.update(|mesh| {
        let moved = mesh
            .vertices()
            .iter()
            .map(|v| *v + Vec3::new(10.0, 0.0, 0.0))
            .collect();
        mesh.set_vertices(moved).unwrap();
    })
    .unwrap();
    assert!(
        !blas.contains(in_tube),
        "the winding moments follow the edit"
    );
    assert!(blas.contains(in_tube + Vec3::new(10.0, 0.0, 0.0)));
    assert!(blas.distance(Vec3::ZERO) > before + 8.0);
}
