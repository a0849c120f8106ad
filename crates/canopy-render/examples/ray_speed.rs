//! Single-thread traversal throughput of a mesh's 8-wide tree, as the renderer builds it:
//! primary and incoherent rays, closest hit and occlusion, for every instruction set this
//! CPU has. With `--leaf a,b,...` and `--builder x,y,...` it builds one tree per builder and
//! maximum leaf size and times them
//! in turns (this machine's speed drifts; turns expose every tree to the same drift).
//! A profiling harness; the benchmarks of record are the criterion benches and
//! `bench/embree_compare.sh`.
//!
//! `cargo run --release -p canopy-render --example ray_speed -- mesh.ply [--runs N]
//!  [--isa scalar|sse2|avx2|avx512] [--rays primary|incoherent|sorted] [--leaf 4,8] [--builder binned-sah,sbvh]
//!  [--no-stats]`
use canopy_bvh::{
    build_with_clipper, BuildParams, Builder, Bvh8, Isa, Ray, RayOrder, TraversalStats,
};
use canopy_render::accel::packed_params;
use canopy_render::camera::Camera;
use canopy_render::geometry::Shape;
use canopy_render::rng::Rng;
use canopy_render::{clipper, load_scene};
use glam::Vec3;
use std::time::Instant;

struct Options {
    mesh: String,
    runs: usize,
    isa: Option<Isa>,
    rays: Option<String>,
    leaf: Vec<u32>,
    builders: Vec<Builder>,
    /// Skip the counting pass (visits and tests per ray), as under a profiler.
    no_stats: bool,
}

fn options() -> Options {
    let mut args = std::env::args().skip(1);
    let mut o = Options {
        mesh: String::new(),
        runs: 5,
        isa: None,
        rays: None,
        leaf: vec![packed_params(&BuildParams::default()).max_leaf_size],
        builders: vec![Builder::BinnedSah],
        no_stats: false,
    };
    while let Some(arg) = args.next() {
        let mut value = || args.next().expect("a value after each option");
        match arg.as_str() {
            "--runs" => o.runs = value().parse().expect("runs"),
            "--isa" => o.isa = Some(value().parse().expect("an instruction set")),
            "--rays" => o.rays = Some(value()),
            "--no-stats" => o.no_stats = true,
            "--builder" => {
                o.builders = value()
                    .split(',')
                    .map(|b| b.parse().expect("builder names"))
                    .collect()
            }
            "--leaf" => {
                o.leaf = value()
                    .split(',')
                    .map(|l| l.parse().expect("leaf sizes"))
                    .collect()
            }
            _ => o.mesh = arg,
        }
    }
    o
}

fn main() {
    let o = options();
    let scene = load_scene(&o.mesh).expect("mesh").with_instances_baked();
    let tris: Vec<[Vec3; 3]> = scene
        .primitives
        .iter()
        .map(|p| match &p.shape {
            Shape::Triangle(t) => t.v,
            _ => panic!("a bare mesh has only triangles"),
        })
        .collect();
    let boxes = scene.primitive_bounds();
    let variants: Vec<(Builder, u32)> = o
        .builders
        .iter()
        .flat_map(|&b| o.leaf.iter().map(move |&l| (b, l)))
        .collect();
    let clip = clipper(&scene.primitives);
    let mut trees: Vec<Bvh8> = variants
        .iter()
        .map(|&(builder, max_leaf_size)| {
            let params = BuildParams {
                max_leaf_size,
                ..packed_params(&BuildParams::default())
            };
            let mut bvh = Bvh8::from_bvh2(&build_with_clipper(builder, &boxes, &params, &clip));
            bvh.pack_triangles(|p| Some(tris[p as usize]));
            bvh
        })
        .collect();

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
            let hit = trees[0].intersect(ray, |_, _| None::<f32>)?;
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
    // The same rays grouped by origin, as the batch calls order them for large trees.
    let sorted: Vec<Ray> = match RayOrder::by_origin(incoherent.len(), |i| incoherent[i].origin) {
        Some(order) => order
            .indices()
            .iter()
            .map(|&i| incoherent[i as usize])
            .collect(),
        None => incoherent.clone(),
    };
    let ray_sets = [
        ("primary", &primary),
        ("incoherent", &incoherent),
        ("sorted", &sorted),
    ];
    let ray_sets: Vec<_> = ray_sets
        .into_iter()
        .filter(|(kind, _)| o.rays.as_ref().is_none_or(|k| k == kind))
        .collect();

    for ((builder, leaf), bvh) in variants.iter().zip(&trees).filter(|_| !o.no_stats) {
        let st = bvh.stats(&BuildParams::default().sah);
        print!("{builder} max leaf {leaf}: {} nodes;", st.nodes);
        for (kind, rays) in &ray_sets {
            let mut stats = TraversalStats::default();
            for ray in rays.iter() {
                bvh.intersect_counted(ray, |_, _| None::<f32>, &mut stats);
            }
            let n = rays.len() as f64;
            print!(
                " {kind} ({} rays): {:.1} visits, {:.1} triangles per ray;",
                rays.len(),
                stats.nodes_visited as f64 / n,
                stats.primitives_tested as f64 / n
            );
        }
        println!();
    }
    for isa in Isa::supported() {
        if o.isa.is_some_and(|i| i != isa) {
            continue;
        }
        for bvh in &mut trees {
            bvh.set_isa(isa).unwrap();
        }
        for (kind, rays) in &ray_sets {
            // best[tree][query] over turns.
            let mut best = vec![[f64::MAX; 2]; trees.len()];
            for _ in 0..o.runs {
                for (bvh, best) in trees.iter().zip(&mut best) {
                    let start = Instant::now();
                    let hits = timed_closest(bvh, rays);
                    best[0] = best[0].min(start.elapsed().as_secs_f64());
                    let start = Instant::now();
                    let blocked = timed_occluded(bvh, rays);
                    best[1] = best[1].min(start.elapsed().as_secs_f64());
                    assert_eq!(hits, blocked, "closest and any hit disagree");
                }
            }
            let n = rays.len() as f64 / 1e6;
            for ((builder, leaf), best) in variants.iter().zip(&best) {
                println!(
                    "{isa:>6} {kind:>10} {builder:>10} max leaf {leaf:>2}: closest {:6.2}  occluded {:6.2} Mrays/s",
                    n / best[0],
                    n / best[1]
                );
            }
        }
    }
}

// The timed passes, kept out of line so that a profiler can count them alone
// (`valgrind --tool=callgrind --collect-atstart=no --toggle-collect='*timed_*'`).
#[inline(never)]
fn timed_closest(bvh: &Bvh8, rays: &[Ray]) -> usize {
    rays.iter()
        .filter(|r| bvh.intersect(r, |_, _| None::<f32>).is_some())
        .count()
}

#[inline(never)]
fn timed_occluded(bvh: &Bvh8, rays: &[Ray]) -> usize {
    rays.iter()
        .filter(|r| bvh.occluded(r, |_, _| false))
        .count()
}
