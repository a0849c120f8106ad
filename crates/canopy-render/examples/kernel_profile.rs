//! canopy's side of `bench/kernel_profile.py`: the closest-hit or occlusion query over the
//! mesh and rays that script wrote (the same files Embree's side reads), on one thread, in
//! the files' order, through the batch call Python's `canopy.Bvh` uses (`Accel`, built as
//! `canopy.Bvh(vertices, faces)` builds it).
//!
//! Prints the best pass's nanoseconds per ray and, from a counting pass, node visits and
//! primitive tests per ray. Under callgrind only the `profiled_*` functions are counted
//! (`--collect-atstart=no --toggle-collect='*profiled_*'`); the script runs it with one
//! pass and `--no-stats` there.
//!
//! `kernel_profile MESH RAYS closest|occluded RUNS [--no-stats] [--fast]` (`--fast`: the
//! fast triangle test, Embree's default mode's counterpart)
use canopy_bvh::{
    BuildParams, BvhWidth, Hit, Ray, RayQuery, TraversalStats, TriangleTest, ALL_MASKS,
};
use canopy_render::geometry::{Shape, Triangle};
use canopy_render::scene::Primitive;
use canopy_render::{Accel, AccelKind};
use glam::Vec3;
use std::sync::Arc;
use std::time::Instant;

fn read_bytes(path: &str) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

fn u64_at(bytes: &[u8], at: usize) -> usize {
    u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes")) as usize
}

fn f32s(bytes: &[u8], at: usize, n: usize) -> Vec<f32> {
    bytes[at..at + 4 * n]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
        .collect()
}

fn u32s(bytes: &[u8], at: usize, n: usize) -> Vec<u32> {
    bytes[at..at + 4 * n]
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
        .collect()
}

/// The mesh file: vertex and triangle counts (u64), vertices (f32 xyz), triangles (u32).
fn read_mesh(path: &str) -> Vec<Primitive> {
    let bytes = read_bytes(path);
    let (nv, nf) = (u64_at(&bytes, 0), u64_at(&bytes, 8));
    let v = f32s(&bytes, 16, 3 * nv);
    let f = u32s(&bytes, 16 + 12 * nv, 3 * nf);
    let vertex = |i: u32| Vec3::from_slice(&v[3 * i as usize..3 * i as usize + 3]);
    f.chunks_exact(3)
        .map(|t| Primitive {
            shape: Shape::Triangle(Triangle::new(vertex(t[0]), vertex(t[1]), vertex(t[2]))),
            material: 0,
        })
        .collect()
}

/// The ray file: a count (u64), origins (f32 xyz), directions (f32 xyz).
fn read_rays(path: &str) -> Vec<Ray> {
    let bytes = read_bytes(path);
    let n = u64_at(&bytes, 0);
    let o = f32s(&bytes, 8, 3 * n);
    let d = f32s(&bytes, 8 + 12 * n, 3 * n);
    (0..n)
        .map(|i| {
            Ray::new(
                Vec3::from_slice(&o[3 * i..3 * i + 3]),
                Vec3::from_slice(&d[3 * i..3 * i + 3]),
                0.0,
                f32::INFINITY,
            )
        })
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        eprintln!("usage: kernel_profile MESH RAYS closest|occluded RUNS [--no-stats] [--fast]");
        std::process::exit(2);
    }
    let primitives = Arc::new(read_mesh(&args[0]));
    let rays = read_rays(&args[1]);
    let closest = args[2] == "closest";
    let runs: usize = args[3].parse().expect("a number of passes");
    let no_stats = args.iter().any(|a| a == "--no-stats");
    let triangle_test = match args.iter().any(|a| a == "--fast") {
        true => TriangleTest::Fast,
        false => TriangleTest::Watertight,
    };

    let kind: AccelKind = "binned-sah".parse().expect("a builder");
    let accel = Accel::build(kind, BvhWidth::Eight, &primitives, &BuildParams::default())
        .with_triangle_test(triangle_test);
    let mut answered = 0;
    let mut best = f64::MAX;
    for _ in 0..runs.max(1) {
        let start = Instant::now();
        answered = match closest {
            true => profiled_closest(&accel, &rays),
            false => profiled_occluded(&accel, &rays),
        };
        best = best.min(start.elapsed().as_secs_f64());
    }
    print!(
        "ns_per_ray {:.3} hits {answered}",
        best * 1e9 / rays.len() as f64
    );
    if !no_stats {
        let mut stats = TraversalStats::default();
        for ray in &rays {
            accel.intersect_counted(ray, ALL_MASKS, &mut stats);
        }
        let n = rays.len() as f64;
        print!(
            " visits_per_ray {:.2} tests_per_ray {:.2}",
            stats.nodes_visited as f64 / n,
            stats.primitives_tested as f64 / n
        );
    }
    println!();
}

// The counted passes, kept out of line so that a profiler can count them alone.
#[inline(never)]
fn profiled_closest(accel: &Accel, rays: &[Ray]) -> usize {
    let mut hits = 0;
    accel.intersect_each(
        rays.len(),
        ALL_MASKS,
        |i| rays[i],
        |_, hit: Option<Hit>| hits += hit.is_some() as usize,
    );
    hits
}

#[inline(never)]
fn profiled_occluded(accel: &Accel, rays: &[Ray]) -> usize {
    let mut blocked = 0;
    accel.occluded_each(
        rays.len(),
        ALL_MASKS,
        |i| rays[i],
        |_, b: bool| blocked += b as usize,
    );
    blocked
}
