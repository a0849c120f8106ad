//! The GPU traversal kernel on its own: closest hits for a batch of rays equal the CPU's
//! (same primitive, distance within 1e-5 relative), for triangles, spheres and rotated
//! boxes together, through the GPU layout of several builders' trees.
//!
//! Runs on any adapter wgpu finds, the software Vulkan driver (lavapipe) included; skips
//! with a message only when no adapter can be created at all.

use canopy_bvh::RayQuery;
use canopy_bvh::{BuildParams, Builder, Hit, Ray};
use canopy_gpu::{Gpu, GpuError, GpuPrimitive, GpuScene, Tracer};
use canopy_render::geometry::{Cuboid, Shape, Sphere, Triangle};
use canopy_render::scene::Primitive;
use canopy_render::{Accel, AccelKind, BvhWidth};
use glam::{Mat3, Vec3};

fn gpu() -> Option<Gpu> {
    match Gpu::new() {
        Ok(gpu) => {
            eprintln!("GPU tests on {}", gpu.describe());
            Some(gpu)
        }
        Err(e @ GpuError::NoAdapter(_)) => {
            eprintln!("SKIPPED: no GPU adapter, GPU tests not run: {e}");
            None
        }
        Err(e) => panic!("{e}"),
    }
}

/// A fixed xorshift sequence in [0, 1).
fn sequence(seed: u32) -> impl FnMut() -> f32 {
    let mut s = seed;
    move || {
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        (s >> 8) as f32 / (1u32 << 24) as f32
    }
}

fn scene(n: usize) -> Vec<Primitive> {
    let mut next = sequence(7);
    let mut point =
        |scale: f32| Vec3::new(next(), next(), next()) * scale - Vec3::splat(scale / 2.0);
    let mut prims = Vec::new();
    for i in 0..n {
        let c = point(20.0);
        let shape = match i % 10 {
            0 => Shape::Sphere(Sphere {
                center: c,
                radius: 0.2 + point(1.0).x.abs(),
            }),
            1 => {
                let axis = point(2.0).normalize_or(Vec3::Y);
                Shape::Cuboid(Cuboid::new(
                    canopy_bvh::Aabb::new(
                        -point(1.0).abs() - Vec3::splat(0.1),
                        point(1.0).abs() + Vec3::splat(0.1),
                    ),
                    Mat3::from_axis_angle(axis, point(6.0).x),
                    c,
                ))
            }
            _ => Shape::Triangle(Triangle::new(c, c + point(2.0), c + point(2.0))),
        };
        prims.push(Primitive { shape, material: 0 });
    }
    prims
}

fn rays(n: usize) -> Vec<Ray> {
    let mut next = sequence(99);
    let mut point =
        |scale: f32| Vec3::new(next(), next(), next()) * scale - Vec3::splat(scale / 2.0);
    (0..n)
        .map(|i| {
            let origin = point(40.0);
            let dir = match i % 7 {
                // Some axis-aligned rays (zero direction components).
                0 => Vec3::new(0.0, 0.0, if origin.z > 0.0 { -1.0 } else { 1.0 }),
                _ => (point(16.0) - origin).normalize(),
            };
            let t_max = if i % 5 == 0 { 15.0 } else { f32::INFINITY };
            Ray::new(origin, dir, 0.0, t_max)
        })
        .collect()
}

/// Same primitive and distance within 1e-5 relative; where they differ, the GPU's
/// primitive must be hit by the CPU at the same distance (a tie). Returns disagreements
/// on hit or miss (rounding can decide a ray that grazes an edge).
fn compare(prims: &[Primitive], rays: &[Ray], cpu: &[Option<Hit>], gpu: &[Option<Hit>]) -> usize {
    let mut hit_or_miss = 0;
    for ((ray, c), g) in rays.iter().zip(cpu).zip(gpu) {
        match (c, g) {
            (Some(c), Some(g)) => {
                let close = (g.t - c.t).abs() <= 1e-5 * c.t.abs().max(1e-3);
                assert!(close, "{ray:?}: CPU {c:?}, GPU {g:?}");
                if g.prim != c.prim {
                    let t = prims[g.prim as usize].shape.intersect(ray);
                    assert!(
                        t.is_some_and(|t| (t - c.t).abs() <= 1e-5 * c.t.abs().max(1e-3)),
                        "{ray:?}: CPU {c:?}, GPU {g:?} is not a tie"
                    );
                }
            }
            (None, None) => {}
            _ => hit_or_miss += 1,
        }
    }
    hit_or_miss
}

#[test]
fn gpu_closest_hits_equal_the_cpu_ones() {
    let Some(gpu) = gpu() else { return };
    let prims = scene(3000);
    let rays = rays(20_000);
    let params = BuildParams::default();
    for builder in [Builder::BinnedSah, Builder::Sbvh, Builder::Lbvh] {
        let accel = Accel::build(
            AccelKind::Bvh(builder),
            BvhWidth::Two,
            &prims.clone().into(),
            &params,
        );
        let cpu: Vec<Option<Hit>> = rays.iter().map(|r| accel.intersect(r)).collect();
        let boxes: Vec<_> = prims.iter().map(|p| p.shape.bounds()).collect();
        let bvh = canopy_bvh::build_with_clipper(
            builder,
            &boxes,
            &params,
            &canopy_render::clipper(&prims),
        );
        let flat = GpuScene::with_bvh(&prims, &bvh).unwrap();
        let tracer = Tracer::new(&gpu, &flat).unwrap();
        let hits = tracer.closest(&rays).unwrap();
        assert_eq!(hits.len(), rays.len());
        let found = hits.iter().filter(|h| h.is_some()).count();
        assert!(found > rays.len() / 10, "{builder}: only {found} hits");
        let differing = compare(&prims, &rays, &cpu, &hits);
        assert!(
            differing <= rays.len() / 5000,
            "{builder}: {differing} rays hit on one side and missed on the other"
        );
    }
}

#[test]
fn nodes_and_primitives_split_over_several_bindings_give_the_same_hits() {
    let Some(gpu) = gpu() else { return };
    let prims = scene(3000);
    let rays = rays(5000);
    let flat = GpuScene::new(&prims, &BuildParams::default()).unwrap();
    let whole = Tracer::new(&gpu, &flat).unwrap().closest(&rays).unwrap();
    // Bindings of 1024 primitives (96 bytes each) or 1024 nodes (64 bytes each, as 2048
    // would not fit): three chunks of primitives, and three of this tree's nodes.
    let mut split = Gpu::new().unwrap();
    split.cap_binding_bytes(1024 * std::mem::size_of::<GpuPrimitive>() as u64);
    let nodes = flat.bvh().nodes().len();
    assert!((2049..=3072).contains(&nodes), "{nodes} nodes");
    let parts = Tracer::new(&split, &flat).unwrap().closest(&rays).unwrap();
    assert!(whole.iter().filter(|h| h.is_some()).count() > rays.len() / 10);
    assert_eq!(whole, parts);
}

#[test]
fn an_empty_scene_and_an_empty_batch_give_no_hits() {
    let Some(gpu) = gpu() else { return };
    let flat = GpuScene::new(&[], &BuildParams::default()).unwrap();
    let tracer = Tracer::new(&gpu, &flat).unwrap();
    let ray = Ray::new(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY);
    assert_eq!(tracer.closest(&[ray; 3]).unwrap(), vec![None; 3]);
    let flat = GpuScene::new(&scene(10), &BuildParams::default()).unwrap();
    let tracer = Tracer::new(&gpu, &flat).unwrap();
    assert!(tracer.closest(&[]).unwrap().is_empty());
}
