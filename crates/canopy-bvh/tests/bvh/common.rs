//! What several test modules share.

use canopy_bvh::{Blas, BlasParams, Builder, BvhWidth, TriangleMesh};
use glam::Vec3;

/// A xorshift stream of numbers in [0, 1] from `seed`.
pub fn uniform(mut state: u32) -> impl FnMut() -> f32 {
    move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state as f32 / u32::MAX as f32
    }
}

/// A closed torus (major radius 1, minor 0.35) with normals facing out, its tube's
/// radius rippled so that it is not convex anywhere: `rings` × `sides` quads.
pub fn torus(rings: u32, sides: u32) -> TriangleMesh {
    let tau = std::f32::consts::TAU;
    let mut vertices = Vec::new();
    for i in 0..rings {
        for j in 0..sides {
            let (u, v) = (i as f32 / rings as f32 * tau, j as f32 / sides as f32 * tau);
            let r = 0.35 * (1.0 + 0.2 * (3.0 * u).sin() * (2.0 * v).cos());
            let ring = 1.0 + r * v.cos();
            vertices.push(Vec3::new(ring * u.cos(), ring * u.sin(), r * v.sin()));
        }
    }
    let at = |i: u32, j: u32| (i % rings) * sides + j % sides;
    let mut indices = Vec::new();
    for i in 0..rings {
        for j in 0..sides {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            indices.push([a, b, c]);
            indices.push([a, c, d]);
        }
    }
    TriangleMesh::new(vertices, indices).unwrap()
}

/// Every builder at every width, and brute force.
pub fn structures(mesh: &TriangleMesh) -> Vec<(String, Blas<TriangleMesh>)> {
    let mut all = vec![(
        "brute force".to_string(),
        Blas::build(mesh.clone(), &BlasParams::new(None, BvhWidth::Two)),
    )];
    for builder in Builder::ALL {
        for width in BvhWidth::ALL {
            let blas = Blas::build(mesh.clone(), &BlasParams::new(Some(*builder), width));
            all.push((format!("{builder} width {width}"), blas));
        }
    }
    all
}
