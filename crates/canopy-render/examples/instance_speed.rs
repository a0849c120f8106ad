//! Instancing against baking: renders a scene with mesh instances as it is (each mesh
//! stored once, a top-level structure over the instances) and, unless `--no-baked`, with
//! every instance's triangles baked into world space, in turns; prints build time, render
//! time and Mrays/s of each. With `--grid N` it first places the scene's first instance
//! N × N times (N² instances, 10,000 for N = 100), for scenes far too large to bake.
//!
//! `cargo run --release -p canopy-render --example instance_speed -- SCENE [--spp N]
//!  [--size WxH] [--turns N] [--grid N] [--no-baked]`
use canopy_bvh::{BuildParams, RayQuery};
use canopy_render::{load_scene, render, Accel, AccelKind, BvhWidth, Scene};
use glam::{Affine3A, Vec3};
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let name = args.next().expect("a scene name or file");
    let (mut spp, mut size, mut turns, mut grid, mut baked) = (4, (320, 240), 2, 0, true);
    while let Some(a) = args.next() {
        let mut value = || args.next().expect("a value");
        match a.as_str() {
            "--spp" => spp = value().parse().unwrap(),
            "--turns" => turns = value().parse().unwrap(),
            "--grid" => grid = value().parse().unwrap(),
            "--size" => {
                let v = value();
                let (w, h) = v.split_once('x').unwrap();
                size = (w.parse().unwrap(), h.parse().unwrap());
            }
            "--no-baked" => baked = false,
            other => panic!("unknown option {other}"),
        }
    }
    let mut scene = load_scene(&name).unwrap();
    scene.settings.spp = spp;
    (scene.settings.width, scene.settings.height) = size;
    if grid > 0 {
        place_grid(&mut scene, grid);
    }
    println!(
        "{name}: {} primitives, {} meshes ({} triangles stored), {} instances placing {} triangles",
        scene.primitives.len(),
        scene.meshes.len(),
        scene
            .meshes
            .iter()
            .map(|m| m.mesh.indices().len())
            .sum::<usize>(),
        scene.instances.len(),
        scene.instanced_triangles()
    );
    let flat = baked.then(|| scene.with_instances_baked());
    for turn in 0..turns {
        run(&format!("instanced, turn {turn}"), &scene, true);
        if let Some(flat) = &flat {
            run(&format!("baked,     turn {turn}"), flat, false);
        }
    }
}

/// Replaces the instances by `n` × `n` copies of the first, spaced by its size.
fn place_grid(scene: &mut Scene, n: u32) {
    let first = scene.instances[0];
    let mesh = &scene.meshes[first.mesh as usize].mesh;
    let extent = mesh
        .vertices()
        .iter()
        .fold(canopy_bvh::Aabb::EMPTY, |b, &v| b.grow(v))
        .extent();
    let step = first.to_world.transform_vector3(extent).abs() * 1.1;
    let centre = Vec3::new(n as f32 - 1.0, 0.0, n as f32 - 1.0) * 0.5 * step;
    scene.instances = (0..n * n)
        .map(|i| {
            let offset = Vec3::new((i % n) as f32, 0.0, (i / n) as f32) * step - centre;
            let mut copy = first;
            copy.to_world = Affine3A::from_translation(offset) * first.to_world;
            copy
        })
        .collect();
}

fn run(label: &str, scene: &Scene, instanced: bool) {
    let start = Instant::now();
    let params = BuildParams::default();
    let accel = match instanced {
        true => Accel::for_scene(scene, AccelKind::default(), BvhWidth::Eight, &params, None),
        false => Accel::build(
            AccelKind::default(),
            BvhWidth::Eight,
            &scene.primitives,
            &params,
        ),
    };
    let build = start.elapsed();
    let top = accel.world().build_time();
    let (_, stats) = render(scene, &accel, &|| {});
    println!(
        "{label}: build {:8.2} ms (top {:6.2} ms), render {:7.3} s, {:6.2} Mrays/s, scene box {:?}",
        build.as_secs_f64() * 1e3,
        top.as_secs_f64() * 1e3,
        stats.elapsed.as_secs_f64(),
        stats.mrays_per_second(),
        accel.bounds().extent()
    );
}
