//! Single-thread traversal throughput of a mesh's 8-wide tree (as the renderer builds it),
//! for every instruction set this CPU has: primary and incoherent rays, closest hit and
//! occlusion. A quick profiling harness; the benchmarks of record are the criterion
//! benches and `bench/embree_compare.sh`.
//!
//! `cargo run --release -p canopy-render --example ray_speed -- mesh.ply [runs] [isa|all] [primary|incoherent]`
use canopy_bvh::{build, BuildParams, Builder, Bvh8, Isa, Ray, TraversalStats, PACK_LANES};
use canopy_render::camera::Camera;
use canopy_render::geometry::Shape;
use canopy_render::load_scene;
use canopy_render::rng::Rng;
use glam::Vec3;
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("a mesh file");
    let runs: usize = args.next().map_or(5, |r| r.parse().expect("runs"));
    let only: Option<Isa> = args
        .next()
        .filter(|i| i != "all")
        .map(|i| i.parse().expect("an instruction set"));
    let only_kind = args.next();
    let scene = load_scene(&path).expect("mesh");
    let tris: Vec<[Vec3; 3]> = scene
        .primitives
        .iter()
        .map(|p| match &p.shape {
            Shape::Triangle(t) => t.v,
            _ => panic!("a bare mesh has only triangles"),
        })
        .collect();
    let boxes = scene.primitive_bounds();
    let params = BuildParams {
        leaf_block: PACK_LANES as u32,
        ..BuildParams::default()
    };
    let mut bvh = Bvh8::from_bvh2(&build(Builder::BinnedSah, &boxes, &params));
    bvh.pack_triangles(|p| Some(tris[p as usize]));

    let side = 1024;
    let camera = Camera::new(&scene.camera, side, side);
    let mut rng = Rng::for_sample(0, 0, 0);
    let primary: Vec<Ray> = (0..side * side)
        .map(|i| {
            camera.ray(
                ((i % side) as f32 + 0.5) / side as f32,
                ((i / side) as f32 + 0.5) / side as f32,
                &mut rng,
            )
        })
        .collect();
    let scale = boxes
        .iter()
        .fold(canopy_bvh::Aabb::EMPTY, |a, &b| a.union(b))
        .extent()
        .length();
    let mut rng = Rng::for_sample(1, 0, 0);
    let mut incoherent: Vec<Ray> = primary
        .iter()
        .filter_map(|ray| {
            let hit = bvh.intersect(ray, |_, _| None::<f32>)?;
            let [a, b, c] = tris[hit.prim as usize];
            let mut n = (b - a).cross(c - a).normalize_or_zero();
            if n.dot(ray.dir) > 0.0 {
                n = -n;
            }
            Some(Ray::new(
                ray.at(hit.t) + n * 1e-4 * scale,
                rng.unit_vector(),
                0.0,
                f32::INFINITY,
            ))
        })
        .collect();
    // In random order, as `bench/embree_compare.py` draws them: consecutive rays start
    // far apart, so the tree is read from memory rather than from the cache.
    for i in (1..incoherent.len()).rev() {
        let j = (rng.next_f32() * (i + 1) as f32) as usize;
        incoherent.swap(i, j.min(i));
    }

    for (kind, rays) in [("primary", &primary), ("incoherent", &incoherent)] {
        let mut stats = TraversalStats::default();
        for ray in rays.iter() {
            bvh.intersect_counted(ray, |_, _| None::<f32>, &mut stats);
        }
        let n = rays.len() as f64;
        println!(
            "{kind}: {} rays; per closest-hit ray {:.1} visits (nodes and leaves), {:.1} triangles",
            rays.len(),
            stats.nodes_visited as f64 / n,
            stats.primitives_tested as f64 / n
        );
    }
    for isa in Isa::supported() {
        if only.is_some_and(|o| o != isa) {
            continue;
        }
        bvh.set_isa(isa).unwrap();
        for (kind, rays) in [("primary", &primary), ("incoherent", &incoherent)] {
            if only_kind.as_ref().is_some_and(|k| k != kind) {
                continue;
            }
            let best = |f: &dyn Fn() -> usize| {
                (0..runs)
                    .map(|_| {
                        let start = Instant::now();
                        std::hint::black_box(f());
                        start.elapsed().as_secs_f64()
                    })
                    .fold(f64::MAX, f64::min)
            };
            let closest = best(&|| {
                rays.iter()
                    .filter(|r| bvh.intersect(r, |_, _| None::<f32>).is_some())
                    .count()
            });
            let occluded = best(&|| {
                rays.iter()
                    .filter(|r| bvh.occluded(r, |_, _| false))
                    .count()
            });
            let n = rays.len() as f64 / 1e6;
            println!(
                "{isa:>6} {kind:>10}: closest {:6.2}  occluded {:6.2} Mrays/s",
                n / closest,
                n / occluded
            );
        }
    }
}
