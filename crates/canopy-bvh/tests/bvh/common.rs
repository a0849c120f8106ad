//! What several test modules share.

use canopy_bvh::{Blas, BlasParams, Builder, BvhWidth, Hit, PrimHit, Ray, TriangleMesh};
use glam::Vec3;

// The closures the tests give a tree's queries, as trait objects of a few types. A tree
// query is compiled (every kernel, for every instruction set and width) once for each
// type of closure it is given, and every closure has a type of its own: with a closure
// per call, those copies were most of this crate's build.

/// A test of the primitives a tree leaves to its caller, for closest hits.
pub type Closest<'a, P = PrimHit> = &'a dyn Fn(u32, &Ray) -> Option<P>;
/// A test of the primitives a tree leaves to its caller, for occlusion.
pub type Blocks<'a> = &'a dyn Fn(u32, &Ray) -> bool;
/// Makes ray `i` of a batch.
pub type MakeRay<'a> = &'a dyn Fn(usize) -> Ray;
/// Takes the closest hit of ray `i` of a batch.
pub type TakeHit<'a> = &'a mut dyn FnMut(usize, Option<Hit>);
/// Takes whether ray `i` of a batch is blocked.
pub type TakeBlocked<'a> = &'a mut dyn FnMut(usize, bool);

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
