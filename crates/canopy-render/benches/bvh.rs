//! BVH benchmarks: build time of every builder on meshes and a reference scene,
//! closest-hit throughput of the resulting trees at every width, and camera rays one by
//! one against packets (`packets/`).
//!
//! `cargo bench -p canopy-render --bench bvh` (add a filter such as `build/dragon-202k`).
//! The dragons are read from `$CANOPY_MESHES`, else `../shared/assets/meshes` next to
//! the repository; without them those inputs are skipped with a note.

mod common;

use canopy_bvh::{build, Aabb, BuildParams, Builder, Bvh4, Bvh8, OptimizeBudget, Ray};
use canopy_bvh::{RayQuery, ALL_MASKS};
use canopy_render::{load_scene, Accel, AccelKind, BvhWidth, Scene};
use common::{camera_rays, incoherent_rays, mesh_dir, stream_camera_rays};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use std::time::Duration;

/// (label, scene) for every input that is available.
fn inputs() -> Vec<(&'static str, Scene)> {
    let bunny = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/meshes/bunny.ply").to_string();
    let dir = mesh_dir();
    let candidates = [
        ("bunny-3.7k", bunny),
        (
            "dragon-48k",
            dir.join("dragon_res3.ply").display().to_string(),
        ),
        (
            "dragon-202k",
            dir.join("dragon_res2.ply").display().to_string(),
        ),
        ("paper-5", "paper-5".to_string()),
    ];
    candidates
        .into_iter()
        .filter_map(|(label, source)| match load_scene(&source) {
            Ok(scene) => Some((label, scene.with_instances_baked())),
            Err(e) => {
                eprintln!("skipping {label}: {e}");
                None
            }
        })
        .collect()
}

fn build_times(c: &mut Criterion) {
    let params = BuildParams::default();
    for (label, scene) in inputs() {
        let boxes: Vec<Aabb> = scene.primitive_bounds();
        let clipper = canopy_render::clipper(&scene.primitives);
        let mut group = c.benchmark_group(format!("build/{label}"));
        group
            .sample_size(10)
            .warm_up_time(Duration::from_millis(500));
        group.throughput(Throughput::Elements(boxes.len() as u64));
        for &builder in Builder::ALL {
            group.bench_with_input(BenchmarkId::from_parameter(builder), &boxes, |b, boxes| {
                b.iter(|| canopy_bvh::build_with_clipper(builder, boxes, &params, &clipper))
            });
        }
        group.finish();
    }
}

fn closest_hit(c: &mut Criterion) {
    let params = BuildParams::default();
    for (label, scene) in inputs() {
        let boxes = scene.primitive_bounds();
        let rays = camera_rays(&scene, 256);
        let test = |p: u32, r: &Ray| scene.primitives[p as usize].shape.intersect(r);
        let mut group = c.benchmark_group(format!("trace/{label}"));
        group
            .sample_size(10)
            .warm_up_time(Duration::from_millis(500));
        group.throughput(Throughput::Elements(rays.len() as u64));
        for builder in [Builder::BinnedSah, Builder::Ploc, Builder::Lbvh] {
            let bvh = build(builder, &boxes, &params);
            let (bvh4, bvh8) = (Bvh4::from_bvh2(&bvh), Bvh8::from_bvh2(&bvh));
            group.bench_function(format!("{builder}/x2"), |b| {
                b.iter(|| {
                    rays.iter()
                        .filter(|r| bvh.intersect(r, test).is_some())
                        .count()
                })
            });
            group.bench_function(format!("{builder}/x4"), |b| {
                b.iter(|| {
                    rays.iter()
                        .filter(|r| bvh4.intersect(r, test).is_some())
                        .count()
                })
            });
            group.bench_function(format!("{builder}/x8"), |b| {
                b.iter(|| {
                    rays.iter()
                        .filter(|r| bvh8.intersect(r, test).is_some())
                        .count()
                })
            });
        }
        group.finish();
    }
}

/// Camera rays as the wavefront traces them (a row's pixels, 8 samples each side by
/// side): one by one (`intersect_each`) and in packets of 16 (`intersect_coherent`),
/// through the renderer's structure, over spheres (paper-1) and a mesh with spheres
/// (paper-3, paper-5).
fn camera_packets(c: &mut Criterion) {
    for name in ["paper-1", "paper-3", "paper-5"] {
        let scene = load_scene(name).expect("a built-in scene");
        let accel = Accel::default_for(&scene);
        let rays = stream_camera_rays(&scene, 128, 8);
        let mut hits = vec![None; rays.len()];
        let mut group = c.benchmark_group(format!("packets/{name}"));
        group
            .sample_size(10)
            .warm_up_time(Duration::from_millis(500));
        group.throughput(Throughput::Elements(rays.len() as u64));
        group.bench_function("one-by-one", |b| {
            b.iter(|| {
                let h = &mut hits;
                accel.intersect_each(rays.len(), ALL_MASKS, |i| rays[i], |i, x| h[i] = x)
            })
        });
        group.bench_function("packets", |b| {
            b.iter(|| {
                let h = &mut hits;
                accel.intersect_coherent(rays.len(), ALL_MASKS, |i| rays[i], |i, x| h[i] = x)
            })
        });
        group.finish();
    }
}

/// The trees issue 13 compares: how long each takes to build, its SAH and EPO (printed
/// once), and incoherent closest hits through it as the renderer lays it out (8-wide,
/// triangles packed). Rays come from one reference tree, so every tree traces the same.
fn tree_quality(c: &mut Criterion) {
    let params = BuildParams::default();
    let configs: [(&str, Builder, Option<OptimizeBudget>); 4] = [
        ("binned-sah", Builder::BinnedSah, None),
        ("sbvh", Builder::Sbvh, None),
        (
            "ploc+optimize",
            Builder::Ploc,
            Some(OptimizeBudget::Passes(4)),
        ),
        ("sweep-sah", Builder::SweepSah, None),
    ];
    for (label, scene) in inputs().into_iter().filter(|(l, _)| *l != "dragon-48k") {
        let build_accel = |builder, optimize| {
            let kind = AccelKind::Bvh(builder);
            Accel::build_optimized(kind, BvhWidth::Eight, &scene.primitives, &params, optimize)
        };
        let reference = build_accel(Builder::BinnedSah, None);
        let rays = incoherent_rays(&scene, &reference, 256);
        let mut group = c.benchmark_group(format!("quality/{label}"));
        group
            .sample_size(10)
            .warm_up_time(Duration::from_millis(500));
        group.throughput(Throughput::Elements(rays.len() as u64));
        for (name, builder, optimize) in configs {
            let accel = build_accel(builder, optimize);
            let tree = accel.tree().expect("a BVH");
            let stats = tree.stats(&params.sah);
            let area = |p: u32, region: &Aabb| {
                scene.primitives[p as usize]
                    .shape
                    .area_in_box(region)
                    .unwrap_or(0.0)
            };
            let epo = canopy_bvh::epo(tree.view(), &params.sah, area);
            eprintln!(
                "quality/{label}/{name}: build {:.1} ms, SAH {:.2}, EPO {epo:.2}, {} references",
                accel.build_time.as_secs_f64() * 1e3,
                stats.sah_cost,
                stats.references
            );
            group.bench_function(name, |b| {
                b.iter(|| rays.iter().filter(|r| accel.intersect(r).is_some()).count())
            });
        }
        group.finish();
    }
}

criterion_group!(
    benches,
    build_times,
    closest_hit,
    camera_packets,
    tree_quality
);
criterion_main!(benches);
