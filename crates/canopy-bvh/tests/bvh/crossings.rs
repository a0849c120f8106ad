//! Crossings of a surface along a ray: where a ray passes exactly through an edge or a
//! vertex that triangles share, it crosses the surface there once (not once per
//! triangle, as the watertight test alone reports it), so a ray through a closed
//! surface crosses it an even number of times — on every structure, as a loop over the
//! triangles counts them.

use crate::common::{structures, torus, uniform};
use canopy_bvh::{HitsAlong, Ray, SurfaceQuery, TriangleMesh, ALL_MASKS};
use glam::Vec3;

/// The cube [-1, 1]³, two triangles a face, facing out.
fn cube() -> TriangleMesh {
    let vertices = (0..8)
        .map(|i| {
            Vec3::new(
                [-1.0, 1.0][i & 1],
                [-1.0, 1.0][i >> 1 & 1],
                [-1.0, 1.0][i >> 2],
            )
        })
        .collect();
    let quads = [
        [0, 2, 3, 1], // z = -1
        [4, 5, 7, 6], // z = +1
        [0, 1, 5, 4], // y = -1
        [2, 6, 7, 3], // y = +1
        [0, 4, 6, 2], // x = -1
        [1, 3, 7, 5], // x = +1
    ];
    let indices = quads
        .iter()
        .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
        .collect();
    TriangleMesh::new(vertices, indices).unwrap()
}

/// The octahedron |x| + |y| + |z| <= 1, facing out.
fn octahedron() -> TriangleMesh {
    let vertices = vec![Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
    let mut indices = Vec::new();
    for (x, y) in [(0, 2), (2, 1), (1, 3), (3, 0)] {
        indices.push([x, y, 4]);
        indices.push([y, x, 5]);
    }
    TriangleMesh::new(vertices, indices).unwrap()
}

/// Directions whose shear onto the ray's plane is exact in single precision, so that a
/// ray aimed at an edge or a vertex passes exactly through it.
fn exact_directions() -> Vec<Vec3> {
    let mut all = Vec::new();
    for d in [
        [1, 0, 0],
        [0, 1, 0],
        [0, 0, 1],
        [1, 1, 0],
        [1, 0, 1],
        [0, 1, 1],
        [1, 1, 1],
        [1, -1, 1],
        [2, 1, 0],
        [1, 2, -1],
    ] {
        let d = Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32);
        all.extend([d, -d]);
    }
    all
}

/// The vertices, edge midpoints and face centres of `mesh`.
fn features(mesh: &TriangleMesh) -> Vec<Vec3> {
    let mut points = mesh.vertices().to_vec();
    for &[a, b, c] in mesh.indices() {
        let [a, b, c] = [a, b, c].map(|i| mesh.vertices()[i as usize]);
        points.extend([
            (a + b) * 0.5,
            (b + c) * 0.5,
            (c + a) * 0.5,
            (a + b + c) / 3.0,
        ]);
    }
    points
}

/// Counts along lines through `mesh`'s features from far outside: (crossings, triangle
/// hits) summed, after checking every structure against the loop and every count of
/// crossings against `expected(line)`.
fn check_lines(
    mesh: &TriangleMesh,
    inside: impl Fn(Vec3) -> bool,
    directions: &[Vec3],
) -> (usize, usize) {
    let loop_only = &structures(mesh)[0].1;
    let (mut crossings, mut triangles) = (0, 0);
    for &through in &features(mesh) {
        for &d in directions {
            let ray = Ray::new(through - 8.0 * d, d, 0.0, f32::INFINITY);
            let crossed = loop_only.hits(&ray, ALL_MASKS, HitsAlong::Crossings);
            let hit = loop_only.hits(&ray, ALL_MASKS, HitsAlong::Triangles);
            // A line through the inside of a convex solid crosses it twice; one that
            // only touches it twice or never.
            let enters = hit.len() >= 2 && inside(ray.at((hit[0].t + hit[hit.len() - 1].t) / 2.0));
            match enters {
                true => assert_eq!(crossed.len(), 2, "{ray:?}: {crossed:?}"),
                false => assert!(crossed.len().is_multiple_of(2), "{ray:?}: {crossed:?}"),
            }
            for (name, blas) in structures(mesh) {
                for (along, expected) in [
                    (HitsAlong::Crossings, &crossed),
                    (HitsAlong::Triangles, &hit),
                ] {
                    assert_eq!(
                        &blas.hits(&ray, ALL_MASKS, along),
                        expected,
                        "{name}, {along:?}: {ray:?}"
                    );
                    let count = blas.count_hits(&ray, ALL_MASKS, along);
                    assert_eq!(count, expected.len(), "{name}, {along:?}: {ray:?}");
                }
            }
            (crossings, triangles) = (crossings + crossed.len(), triangles + hit.len());
        }
    }
    (crossings, triangles)
}

#[test]
fn lines_through_a_cubes_edges_and_corners_cross_it_twice_or_not_at_all() {
    let inside = |p: Vec3| p.abs().max_element() < 1.0 - 1e-4;
    let (crossings, triangles) = check_lines(&cube(), inside, &exact_directions());
    // Each triangle around the crossed edge or corner reports it.
    assert!(
        triangles > crossings + 1000,
        "{triangles} hits, {crossings} crossings"
    );
}

#[test]
fn lines_through_an_octahedrons_edges_and_corners_cross_it_twice_or_not_at_all() {
    let inside = |p: Vec3| p.abs().element_sum() < 1.0 - 1e-4;
    let (crossings, triangles) = check_lines(&octahedron(), inside, &exact_directions());
    assert!(
        triangles > crossings + 500,
        "{triangles} hits, {crossings} crossings"
    );
}

#[test]
fn a_face_diagonal_is_crossed_once_and_per_triangle_hits_remain_on_request() {
    // The ray of the issue: through the diagonal of the cube's z faces (both split
    // along x = y): four triangles hit, two crossings.
    let blas = &structures(&cube())[1].1;
    let ray = Ray::new(Vec3::new(0.25, 0.25, -5.0), Vec3::Z, 0.0, f32::INFINITY);
    assert_eq!(blas.hits(&ray, ALL_MASKS, HitsAlong::Triangles).len(), 4);
    let crossed = blas.hits(&ray, ALL_MASKS, HitsAlong::Crossings);
    let at: Vec<f32> = crossed.iter().map(|h| h.t).collect();
    assert_eq!(at, [4.0, 6.0]);
}

#[test]
fn faces_back_to_back_are_two_crossings() {
    let vertices = vec![Vec3::ZERO, Vec3::X, Vec3::Y];
    let mesh = TriangleMesh::new(vertices, vec![[0, 1, 2], [0, 2, 1]]).unwrap();
    for (name, blas) in structures(&mesh) {
        let ray = Ray::new(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z, 0.0, f32::INFINITY);
        assert_eq!(
            blas.hits(&ray, ALL_MASKS, HitsAlong::Crossings).len(),
            2,
            "{name}"
        );
    }
}

#[test]
fn lines_through_a_curved_closed_surfaces_vertices_cross_it_an_even_number_of_times() {
    // Directions in general position: the shear rounds, and each line passes within
    // rounding of the vertex it is aimed at.
    let mesh = torus(24, 12);
    let blas = &structures(&mesh)[1].1;
    let mut next = uniform(21);
    let mut odd = Vec::new();
    let mut crossings = 0;
    for &through in mesh.vertices() {
        for _ in 0..8 {
            let d = (Vec3::new(next(), next(), next()) - 0.5).normalize_or(Vec3::X);
            let ray = Ray::new(through - 6.0 * d, d, 0.0, f32::INFINITY);
            let crossed = blas.hits(&ray, ALL_MASKS, HitsAlong::Crossings).len();
            crossings += crossed;
            if crossed % 2 == 1 {
                odd.push(ray);
            }
        }
    }
    assert!(crossings > 2000, "{crossings}");
    assert!(
        odd.is_empty(),
        "{} odd counts, e.g. {:?}",
        odd.len(),
        &odd[..odd.len().min(3)]
    );
}

#[test]
fn inside_a_closed_surface_is_counted_exactly_by_signed_crossings() {
    // Points on the torus's triangles moved off them by 1e-4 of its size: where the far
    // field of a winding number is least accurate, the signed crossings of one ray are
    // still the exact (integer) winding number.
    let mesh = torus(24, 12);
    let mut next = uniform(33);
    let points: Vec<Vec3> = (0..300)
        .map(|i| {
            let [a, b, c] = mesh.vertices_of(i % mesh.indices().len() as u32);
            let (s, t) = (next() * 0.5, next() * 0.5);
            let on = a + s * (b - a) + t * (c - a);
            on + (Vec3::new(next(), next(), next()) - 0.5).normalize_or(Vec3::Z) * 1e-4
        })
        .collect();
    let mut inside = 0;
    for (name, blas) in structures(&mesh) {
        for &q in &points {
            let counted = blas.inside_winding_number(q);
            // No far field: every triangle's solid angle, summed.
            let exact = blas.winding_number_within(q, f32::INFINITY);
            assert_eq!(counted, exact.round(), "{name}: {q} ({exact})");
            inside += counted as usize;
        }
    }
    assert!(inside > 1000, "{inside}");
}

#[test]
fn inside_a_surface_with_a_hole_is_told_by_the_winding_number() {
    // Half the torus: not closed, so rays' crossings would depend on the ray.
    let closed = torus(24, 12);
    let half = closed.indices()[..closed.indices().len() / 2].to_vec();
    let open = TriangleMesh::new(closed.vertices().to_vec(), half).unwrap();
    let blas = &structures(&open)[1].1;
    let mut next = uniform(34);
    for _ in 0..200 {
        let q = (Vec3::new(next(), next(), next()) - 0.5) * 3.0;
        let fast = blas.inside_winding_number(q);
        assert_eq!(
            fast,
            blas.winding_number_within(q, canopy_bvh::INSIDE_FAR_FIELD)
        );
    }
}
