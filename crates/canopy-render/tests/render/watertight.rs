//! No ray slips through a closed mesh: rays aimed exactly at the shared vertices and edges
//! of closed meshes must hit them, with the scene's own triangle test and through every
//! acceleration structure, in both triangle modes (the fast one drops only the
//! double-precision refinement, and stays closed).
//!
//! The rays are hard enough to matter: treating an edge function of exactly zero as a
//! miss (a common way to lose watertightness) lets about 10% of them through.

use canopy_bvh::RayQuery;
use canopy_bvh::{BuildParams, Builder, Ray, TriangleTest};
use canopy_render::geometry::{Shape, Triangle};
use canopy_render::scene::Primitive;
use canopy_render::{Accel, AccelKind, BvhWidth};
use glam::Vec3;
use std::collections::HashMap;

/// A closed icosphere: every vertex is stored once, so shared edges share exact floats.
fn icosphere(subdivisions: usize, centre: Vec3, radius: f32) -> (Vec<Vec3>, Vec<[usize; 3]>) {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut v: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut faces = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut midpoint: HashMap<(usize, usize), usize> = HashMap::new();
        let mut mid = |a: usize, b: usize, v: &mut Vec<Vec3>| {
            *midpoint.entry((a.min(b), a.max(b))).or_insert_with(|| {
                v.push(((v[a] + v[b]) * 0.5).normalize());
                v.len() - 1
            })
        };
        faces = faces
            .iter()
            .flat_map(|&[a, b, c]| {
                let (ab, bc, ca) = (mid(a, b, &mut v), mid(b, c, &mut v), mid(c, a, &mut v));
                [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            })
            .collect();
    }
    (v.into_iter().map(|p| centre + radius * p).collect(), faces)
}

/// Random points on a sphere of radius 4 around `centre` (a fixed sequence).
fn origins(n: usize, centre: Vec3) -> Vec<Vec3> {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    (0..n)
        .map(|_| {
            let z = 2.0 * next() - 1.0;
            let phi = std::f32::consts::TAU * next();
            let r = (1.0 - z * z).sqrt();
            centre + 4.0 * Vec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// Rays from outside aimed exactly at every vertex and at points along every edge, kept
/// only when their line passes well inside the mesh: a near-tangent ray may rightly pass
/// outside a silhouette edge (the faces are chords, inside the sphere).
fn rays_at_shared_features(
    v: &[Vec3],
    faces: &[[usize; 3]],
    centre: Vec3,
    radius: f32,
) -> Vec<Ray> {
    let mut targets: Vec<Vec3> = v.to_vec();
    for &[a, b, c] in faces {
        for (p, q) in [(a, b), (b, c), (c, a)] {
            for s in [0.5, 0.25, 0.731] {
                targets.push(v[p].lerp(v[q], s));
            }
        }
    }
    let from = origins(targets.len(), centre);
    targets
        .iter()
        .zip(&from)
        .map(|(&target, &origin)| {
            Ray::new(origin, (target - origin).normalize(), 0.0, f32::INFINITY)
        })
        .filter(|r| {
            let closest = r.origin + (centre - r.origin).dot(r.dir) * r.dir;
            (closest - centre).length() < 0.9 * radius
        })
        .collect()
}

/// A closed box whose six faces are n x n grids of quads, each split along a diagonal;
/// corners at awkward (not exactly representable) coordinates.
fn grid_box(n: usize, lo: Vec3, hi: Vec3) -> (Vec<Vec3>, Vec<[usize; 3]>) {
    let mut index: HashMap<[u32; 3], usize> = HashMap::new();
    let mut v = Vec::new();
    let mut faces = Vec::new();
    // Grid point (i, j, k) in 0..=n on each axis, stored once.
    let mut vertex = |i: usize, j: usize, k: usize, v: &mut Vec<Vec3>| {
        *index
            .entry([i as u32, j as u32, k as u32])
            .or_insert_with(|| {
                let f = |t: usize, a: f32, b: f32| a + (b - a) * t as f32 / n as f32;
                v.push(Vec3::new(
                    f(i, lo.x, hi.x),
                    f(j, lo.y, hi.y),
                    f(k, lo.z, hi.z),
                ));
                v.len() - 1
            })
    };
    for axis in 0..3 {
        for side in [0, n] {
            for a in 0..n {
                for b in 0..n {
                    let mut corner = |da: usize, db: usize| {
                        let mut c = [0; 3];
                        c[axis] = side;
                        c[(axis + 1) % 3] = a + da;
                        c[(axis + 2) % 3] = b + db;
                        vertex(c[0], c[1], c[2], &mut v)
                    };
                    let (p00, p10, p11, p01) =
                        (corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1));
                    faces.push([p00, p10, p11]);
                    faces.push([p00, p11, p01]);
                }
            }
        }
    }
    (v, faces)
}

/// Rays straight down the z axis through points on the diagonals of the box's top-face
/// quads: they cross a shared edge exactly where rounding decides.
fn rays_down_diagonals(v: &[Vec3], faces: &[[usize; 3]], top: f32) -> Vec<Ray> {
    let mut rays = Vec::new();
    for (f, &[a, _, c]) in faces.iter().enumerate() {
        // Faces come in pairs sharing the diagonal a-c; take the top ones, once per pair.
        if f % 2 == 1 || v[a].z != top || v[c].z != top {
            continue;
        }
        for i in 1..16 {
            let p = v[a].lerp(v[c], i as f32 / 16.0);
            rays.push(Ray::new(
                Vec3::new(p.x, p.y, top + 1.0),
                -Vec3::Z,
                0.0,
                f32::INFINITY,
            ));
        }
    }
    rays
}

#[test]
fn rays_at_shared_edges_and_vertices_never_escape() {
    let centre = Vec3::new(0.3, -0.2, 0.7);
    let radius = 1.3;
    let (sphere_v, sphere_faces) = icosphere(3, centre, radius);
    let (lo, hi) = (Vec3::new(3.1, 0.7, -0.3), Vec3::new(4.3, 1.9, 0.9));
    let (box_v, box_faces) = grid_box(24, lo, hi);
    let mut rays = rays_at_shared_features(&sphere_v, &sphere_faces, centre, radius);
    let top = box_v.iter().map(|p| p.z).fold(f32::MIN, f32::max);
    rays.extend(rays_down_diagonals(&box_v, &box_faces, top));
    assert!(rays.len() > 10_000, "{} rays", rays.len());
    // One scene holding both closed meshes.
    let offset = sphere_v.len();
    let v: Vec<Vec3> = sphere_v.into_iter().chain(box_v).collect();
    let faces: Vec<[usize; 3]> = sphere_faces
        .into_iter()
        .chain(box_faces.into_iter().map(|f| f.map(|i| i + offset)))
        .collect();
    let primitives: std::sync::Arc<Vec<Primitive>> = std::sync::Arc::new(
        faces
            .iter()
            .map(|&[a, b, c]| Primitive {
                shape: Shape::Triangle(Triangle::new(v[a], v[b], v[c])),
                material: 0,
            })
            .collect(),
    );

    let mut structures = vec![(
        "none",
        Accel::build(
            AccelKind::None,
            BvhWidth::Two,
            &primitives,
            &BuildParams::default(),
        ),
    )];
    for width in BvhWidth::ALL {
        structures.push((
            "bvh",
            Accel::build(
                AccelKind::default(),
                width,
                &primitives,
                &BuildParams::default(),
            ),
        ));
    }
    // Spatial splits clip triangles at planes through the mesh; the clipped boxes must
    // not lose a sliver of any triangle. Leaves of one triangle make the builder cut
    // neighbours apart, which takes spatial splits on these meshes.
    let clipping = BuildParams {
        max_duplication: 2.0,
        max_leaf_size: 1,
        ..BuildParams::default()
    };
    for width in BvhWidth::ALL {
        let accel = Accel::build(AccelKind::Bvh(Builder::Sbvh), width, &primitives, &clipping);
        let tree = accel.tree().unwrap();
        let references = tree.stats(&clipping.sah).references;
        assert!(
            tree.view().has_spatial_splits() && references > primitives.len() * 3 / 2,
            "{width}-wide sbvh: {references} references"
        );
        structures.push(("sbvh", accel));
    }
    for (name, accel) in structures {
        let fast = accel.clone().with_triangle_test(TriangleTest::Fast);
        for (mode, accel) in [("watertight", accel), ("fast", fast)] {
            let escaped = rays.iter().filter(|r| accel.intersect(r).is_none()).count();
            assert_eq!(
                escaped,
                0,
                "{name} ({mode}): {escaped} of {} rays slipped through",
                rays.len()
            );
        }
    }
}
