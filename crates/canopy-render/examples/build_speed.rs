//! Where a mesh's build time goes, as the renderer and the Python `Bvh` build a packed
//! 8-wide tree: primitive boxes, the binary build, the collapse to 8-wide and the triangle
//! packing, each the best of `--runs`, for each thread count of `--threads`, timed in
//! turns. It also prints the binary tree's SAH cost and a hash of its leaf order, to check
//! that a faster version of a builder still builds the same tree.
//! A profiling harness; the benchmark of record is `bench/embree_compare.sh`.
//!
//! `cargo run --release -p canopy-render --example build_speed -- mesh.ply [--runs N]
//!  [--threads 1,2] [--builder binned-sah]`
use canopy_bvh::{build_with_clipper, BuildParams, Builder, Bvh8};
use canopy_render::accel::packed_params;
use canopy_render::{clipper, load_scene};
use rayon::prelude::*;
use std::time::{Duration, Instant};

const PHASES: [&str; 4] = ["boxes", "build", "collapse", "pack"];

fn main() {
    let mut args = std::env::args().skip(1);
    let (mut mesh, mut runs, mut threads, mut builder) =
        (String::new(), 9, vec![1, 2], Builder::BinnedSah);
    while let Some(arg) = args.next() {
        let mut value = || args.next().expect("a value after each option");
        match arg.as_str() {
            "--runs" => runs = value().parse().expect("runs"),
            "--builder" => builder = value().parse().expect("a builder"),
            "--threads" => {
                threads = value()
                    .split(',')
                    .map(|t| t.parse().expect("thread counts"))
                    .collect()
            }
            _ => mesh = arg,
        }
    }
    let scene = load_scene(&mesh).expect("mesh").with_instances_baked();
    let params = packed_params(&BuildParams::default());
    let clip = clipper(&scene.primitives);
    let pools: Vec<_> = threads
        .iter()
        .map(|&t| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .expect("a thread pool")
        })
        .collect();
    let mut best = vec![[Duration::MAX; 4]; pools.len()];
    let mut tree = None;
    for _ in 0..runs {
        for (pool, best) in pools.iter().zip(&mut best) {
            pool.install(|| {
                let mut t = Instant::now();
                let mut lap = |phase: usize| {
                    best[phase] = best[phase].min(t.elapsed());
                    t = Instant::now();
                };
                let boxes: Vec<_> = scene
                    .primitives
                    .par_iter()
                    .map(|p| p.shape.bounds())
                    .collect();
                lap(0);
                let bvh = build_with_clipper(builder, &boxes, &params, &clip);
                lap(1);
                let mut wide = Bvh8::from_bvh2(&bvh);
                lap(2);
                wide.pack_triangles(|p| scene.primitives[p as usize].shape.triangle_vertices());
                lap(3);
                tree.get_or_insert_with(|| (bvh.stats(&params.sah), bvh.prim_indices().to_vec()));
            });
        }
    }
    if let Some((stats, order)) = &tree {
        // FNV-1a over the leaf order: equal for equal trees.
        let hash = order.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &p| {
            (h ^ u64::from(p)).wrapping_mul(0x100_0000_01b3)
        });
        println!(
            "{builder}: SAH {:.4}, {} nodes, leaf order hash {hash:016x}",
            stats.sah_cost, stats.nodes
        );
    }
    for (t, best) in threads.iter().zip(&best) {
        let total: Duration = best.iter().sum();
        let phases: Vec<String> = PHASES
            .iter()
            .zip(best)
            .map(|(name, d)| format!("{name} {:.1}", d.as_secs_f64() * 1e3))
            .collect();
        println!(
            "{t} threads: {:.1} ms = {} (ms, best of {runs})",
            total.as_secs_f64() * 1e3,
            phases.join(", ")
        );
    }
}
