//! The 8-wide walk alone, for experiments on the traversal kernel: a mesh's `Blas` (binned
//! SAH, 8 wide, packed leaves, as `canopy.Bvh` builds it) and one thread tracing the rays
//! of a file in order, as `bench/kernel_profile.py` writes them. It needs only canopy-bvh,
//! so a change to the kernel rebuilds in a fraction of the renderer's time.
//!
//! `walk_profile MESH RAYS closest|occluded|count|build RUNS [--no-stats] [--fast] [--made]
//! [--isa NAME]` prints the best pass's nanoseconds per ray (`build`: the best build's
//! milliseconds, the rays left alone) and, unless `--no-stats`, node
//! visits and primitive tests per ray (of the closest-hit walk). `--isa` picks the
//! kernels' instruction set (`avx2` times the AVX2 kernels on an AVX-512 CPU). `count` counts each ray's crossings
//! of the surface, the rays in one batch, as `canopy.RayScene.count_intersections` does.
//! With `--made` (closest and occluded only), each ray is made as the walk asks for it,
//! from arrays of origins and directions, by a function out of line (as a caller's
//! closure that the compiler does not inline makes it: `canopy.Bvh`'s batch calls),
//! instead of copied from an array of rays made before. Under callgrind, count the
//! `profiled_*` functions alone (`--collect-atstart=no --toggle-collect='*profiled_*'`).
use canopy_bvh::{
    Blas, BlasParams, Builder, BvhWidth, Hit, HitsAlong, Ray, RayQuery, SurfaceQuery,
    TraversalStats, TriangleMesh, TriangleTest, ALL_MASKS,
};
use glam::Vec3;
use std::time::Instant;

fn read_bytes(path: &str) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

fn u64_at(bytes: &[u8], at: usize) -> usize {
    u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes")) as usize
}

fn words<T>(bytes: &[u8], at: usize, n: usize, word: fn([u8; 4]) -> T) -> Vec<T> {
    bytes[at..at + 4 * n]
        .chunks_exact(4)
        .map(|b| word(b.try_into().expect("4 bytes")))
        .collect()
}

/// The mesh file: vertex and triangle counts (u64), vertices (f32 xyz), triangles (u32).
fn read_mesh(path: &str) -> TriangleMesh {
    let bytes = read_bytes(path);
    let (nv, nf) = (u64_at(&bytes, 0), u64_at(&bytes, 8));
    let v = words(&bytes, 16, 3 * nv, f32::from_le_bytes);
    let f = words(&bytes, 16 + 12 * nv, 3 * nf, u32::from_le_bytes);
    let vertices = v.chunks_exact(3).map(Vec3::from_slice).collect();
    let indices = f.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    TriangleMesh::new(vertices, indices).expect("a valid mesh")
}

/// The ray file: a count (u64), origins (f32 xyz), directions (f32 xyz).
fn read_rays(path: &str) -> Vec<Ray> {
    let bytes = read_bytes(path);
    let n = u64_at(&bytes, 0);
    let o = words(&bytes, 8, 3 * n, f32::from_le_bytes);
    let d = words(&bytes, 8 + 12 * n, 3 * n, f32::from_le_bytes);
    (0..n)
        .map(|i| {
            let at = 3 * i..3 * i + 3;
            Ray::new(
                Vec3::from_slice(&o[at.clone()]),
                Vec3::from_slice(&d[at]),
                0.0,
                f32::INFINITY,
            )
        })
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        eprintln!(
            "usage: walk_profile MESH RAYS closest|occluded|count|build RUNS [--no-stats] [--fast]"
        );
        std::process::exit(2);
    }
    let mesh = read_mesh(&args[0]);
    let rays = read_rays(&args[1]);
    let closest = args[2] == "closest";
    let count = args[2] == "count";
    let runs: usize = args[3].parse().expect("a number of passes");
    let params = BlasParams {
        triangle_test: match args.iter().any(|a| a == "--fast") {
            true => TriangleTest::Fast,
            false => TriangleTest::Watertight,
        },
        ..BlasParams::new(Some(Builder::BinnedSah), BvhWidth::Eight)
    };
    if args[2] == "build" {
        // The rays are not traced: the best build's time, with the threads rayon is given.
        let best = (0..runs.max(1))
            .map(|_| {
                let (mesh, start) = (mesh.clone(), Instant::now());
                std::hint::black_box(Blas::build(mesh, &params));
                start.elapsed().as_secs_f64()
            })
            .fold(f64::MAX, f64::min);
        println!("ms_per_build {:.3}", best * 1e3);
        return;
    }
    let mut blas = Blas::build(mesh, &params);
    if let Some(at) = args.iter().position(|a| a == "--isa") {
        let isa = args.get(at + 1).expect("--isa NAME");
        let isa = isa.parse().unwrap_or_else(|e| panic!("{e}"));
        let tree = blas.tree_mut().expect("a tree");
        tree.set_isa(isa).unwrap_or_else(|e| panic!("{e}"));
    }
    let made = args.iter().any(|a| a == "--made");
    let origins: Vec<[f32; 3]> = rays.iter().map(|r| r.origin.to_array()).collect();
    let directions: Vec<[f32; 3]> = rays.iter().map(|r| r.dir.to_array()).collect();
    let mut answered = 0;
    let mut best = f64::MAX;
    for _ in 0..runs.max(1) {
        let start = Instant::now();
        answered = match (closest, made) {
            _ if count => profiled_count(&blas, &rays),
            (true, false) => profiled_closest(&blas, rays.len(), |i| rays[i]),
            (false, false) => profiled_occluded(&blas, rays.len(), |i| rays[i]),
            (true, true) => {
                profiled_closest(&blas, rays.len(), |i| make_ray(&origins, &directions, i))
            }
            (false, true) => {
                profiled_occluded(&blas, rays.len(), |i| make_ray(&origins, &directions, i))
            }
        };
        best = best.min(start.elapsed().as_secs_f64());
    }
    print!(
        "ns_per_ray {:.3} hits {answered}",
        best * 1e9 / rays.len() as f64
    );
    if !args.iter().any(|a| a == "--no-stats") {
        let mut stats = TraversalStats::default();
        for ray in &rays {
            blas.intersect_counted(ray, ALL_MASKS, &mut stats);
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

/// Ray `i` of the arrays, made out of line (`--made`).
#[inline(never)]
fn make_ray(origins: &[[f32; 3]], directions: &[[f32; 3]], i: usize) -> Ray {
    Ray::new(
        Vec3::from(origins[i]),
        Vec3::from(directions[i]),
        0.0,
        f32::INFINITY,
    )
}

// The counted passes, kept out of line so that a profiler can count them alone.
#[inline(never)]
fn profiled_closest(blas: &Blas<TriangleMesh>, n: usize, ray: impl FnMut(usize) -> Ray) -> usize {
    let mut hits = 0;
    blas.intersect_each(n, ALL_MASKS, ray, |_, hit: Option<Hit>| {
        hits += hit.is_some() as usize
    });
    hits
}

#[inline(never)]
fn profiled_count(blas: &Blas<TriangleMesh>, rays: &[Ray]) -> usize {
    let mut counts = vec![0; rays.len()];
    blas.count_hits_each(rays, ALL_MASKS, HitsAlong::Crossings, &mut counts);
    counts.iter().sum()
}

#[inline(never)]
fn profiled_occluded(blas: &Blas<TriangleMesh>, n: usize, ray: impl FnMut(usize) -> Ray) -> usize {
    let mut blocked = 0;
    blas.occluded_each(n, ALL_MASKS, ray, |_, occluded: bool| {
        blocked += occluded as usize
    });
    blocked
}
