//! Camera rays one by one against the same rays in packets ([`RayQuery::closest_hits_into`]
//! with [`Coherence::Coherent`]),
//! single thread, in turns (this machine's speed drifts; turns expose both to the same
//! drift), best of the turns. The rays are those a wavefront stream holds: row by row,
//! each pixel's samples side by side. Checks that both give the same hits.
//! A profiling harness; renders of record are timed by `canopy render` and
//! `bench/mitsuba_render.sh`.
//!
//! With `--shadows`, the rays are instead shadow rays from where those camera rays hit
//! towards random points on the scene's first light (occlusion: one by one against
//! [`RayQuery::any_hits_into`] in packets; `bench/scenes/spheres-lit.toml`, and
//! `dragon-lit.toml` run from `bench/scenes`).
//!
//! With `--bounces`, the rays are diffuse bounces: from where those camera rays hit, in
//! random directions on the side they came from (closest hits, as camera rays). They
//! part ways below the top of the tree, so a packet goes on ray by ray once few of its
//! rays remain together.
//!
//! With `--write-rays DIR`, the camera or bounce rays and the scene's triangles (its boxes
//! as triangles too) are also written to `DIR/{camera,bounce}.bin` and `DIR/mesh.bin` in
//! the files of `bench/kernel_profile.py`, so that canopy's kernels and Embree's can be
//! timed on a render's own rays (`walk_profile`, `embree_profile`).
//!
//! `cargo run --release -p canopy-render --example packet_speed -- [scene ...]
//!  [--size 480x480] [--samples 8] [--turns 5] [--shadows | --bounces] [--write-rays DIR]`
use canopy_bvh::{Coherence, Hit, Ray, RayQuery, ALL_MASKS};
use canopy_render::accel::Accel;
use canopy_render::camera::Camera;
use canopy_render::lights::Lights;
use canopy_render::load_scene;
use canopy_render::rng::Rng;
use canopy_render::scene::Scene;
use glam::Vec3;
use std::time::{Duration, Instant};

fn main() {
    let mut args = std::env::args().skip(1);
    let (mut scenes, mut size, mut samples, mut turns) = (Vec::new(), (480, 480), 8u32, 5);
    let (mut shadows, mut bounces) = (false, false);
    let mut write_rays = None;
    while let Some(arg) = args.next() {
        let mut value = || args.next().expect("a value after each option");
        match arg.as_str() {
            "--size" => {
                let v = value();
                let (w, h) = v.split_once('x').expect("WIDTHxHEIGHT");
                size = (w.parse().expect("width"), h.parse().expect("height"));
            }
            "--samples" => samples = value().parse().expect("samples"),
            "--turns" => turns = value().parse().expect("turns"),
            "--shadows" => shadows = true,
            "--bounces" => bounces = true,
            "--write-rays" => write_rays = Some(std::path::PathBuf::from(value())),
            _ => scenes.push(arg),
        }
    }
    if scenes.is_empty() {
        scenes = ["paper-1", "paper-3", "paper-5"].map(String::from).to_vec();
    }
    for name in &scenes {
        let scene = load_scene(name).expect("a scene");
        let accel = Accel::default_for(&scene);
        let camera = Camera::new(&scene.camera, size.0, size.1);
        let mut rays = Vec::with_capacity((size.0 * size.1 * samples) as usize);
        for y in 0..size.1 {
            for x in 0..size.0 {
                for k in 0..samples {
                    let index = (y * size.0 + x) as u64;
                    let mut rng = Rng::for_sample(1, index, k as u64);
                    let s = (x as f32 + rng.next_f32()) / size.0 as f32;
                    let t = (y as f32 + rng.next_f32()) / size.1 as f32;
                    rays.push(camera.ray(s, t, &mut rng));
                }
            }
        }
        if shadows {
            time_shadows(name, &scene, &accel, &rays, turns);
            continue;
        }
        let kind = if bounces {
            rays = bounce_rays(&accel, &rays);
            "bounce"
        } else {
            "camera"
        };
        if let Some(dir) = &write_rays {
            write_kernel_profile_files(dir, &scene, &rays, kind);
        }
        let mut single = vec![None; rays.len()];
        let mut packets = vec![None; rays.len()];
        let (mut best_single, mut best_packets) = (Duration::MAX, Duration::MAX);
        for _ in 0..turns {
            if std::env::var_os("PACKETS_ONLY").is_none() {
                best_single = best_single.min(time(&rays, &mut single, |r, h| {
                    accel.closest_hits_into(r, h, ALL_MASKS, Coherence::Incoherent, &mut ())
                }));
            }
            best_packets = best_packets.min(time(&rays, &mut packets, |r, h| {
                accel.closest_hits_into(r, h, ALL_MASKS, Coherence::Coherent, &mut ())
            }));
        }
        let mut work = canopy_bvh::TraversalStats::default();
        for ray in &rays {
            let w = accel.traversal_cost(ray);
            work.nodes_visited += w.nodes_visited;
            work.primitives_tested += w.primitives_tested;
        }
        println!(
            "  per ray: {:.2} node visits, {:.2} primitive tests",
            work.nodes_visited as f64 / rays.len() as f64,
            work.primitives_tested as f64 / rays.len() as f64
        );
        let same = single == packets;
        let rate = |d: Duration| rays.len() as f64 / d.as_secs_f64() / 1e6;
        println!(
            "{name}: {} {kind} rays; one by one {:.2} Mrays/s, packets {:.2} Mrays/s ({:.2}x); same hits: {same}",
            rays.len(),
            rate(best_single),
            rate(best_packets),
            best_single.as_secs_f64() / best_packets.as_secs_f64(),
        );
        assert!(
            same || std::env::var_os("PACKETS_ONLY").is_some(),
            "packets must give the same hits"
        );
    }
}

/// Traces `rays` in the stream's chunks (one image row at a time), as the renderer does.
fn time(
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    trace: impl Fn(&[Ray], &mut [Option<Hit>]),
) -> Duration {
    let start = Instant::now();
    for (rays, hits) in rays.chunks(4096).zip(hits.chunks_mut(4096)) {
        trace(rays, hits);
    }
    start.elapsed()
}

/// The closest hit of each of `camera_rays`, one by one.
fn camera_hits(accel: &Accel, camera_rays: &[Ray]) -> Vec<Option<Hit>> {
    let mut hits = vec![None; camera_rays.len()];
    accel.intersect_each(
        camera_rays.len(),
        ALL_MASKS,
        |i| camera_rays[i],
        |i, h| hits[i] = h,
    );
    hits
}

/// Diffuse bounces from the hits of `camera_rays`: uniform directions on the side each
/// ray came from, in the stream's order (a pixel's samples side by side).
fn bounce_rays(accel: &Accel, camera_rays: &[Ray]) -> Vec<Ray> {
    let hits = camera_hits(accel, camera_rays);
    let mut rays = Vec::new();
    for (i, (ray, hit)) in camera_rays.iter().zip(&hits).enumerate() {
        let Some(hit) = hit else { continue };
        let mut rng = Rng::for_sample(11, i as u64, 0);
        let z = 1.0 - 2.0 * rng.next_f32();
        let phi = std::f32::consts::TAU * rng.next_f32();
        let r = (1.0 - z * z).max(0.0).sqrt();
        let mut dir = Vec3::new(r * phi.cos(), r * phi.sin(), z);
        if dir.dot(ray.dir) > 0.0 {
            dir = -dir;
        }
        rays.push(Ray::new(ray.at(hit.t * 0.9999), dir, 1e-4, f32::INFINITY));
    }
    rays
}

/// Shadow rays from the hits of `camera_rays` towards the scene's first light, one by
/// one against packets, best of `turns`.
fn time_shadows(name: &str, scene: &Scene, accel: &Accel, camera_rays: &[Ray], turns: u32) {
    let lights = Lights::new(scene);
    let &(_, light) = lights.emitters().first().expect("a scene with a light");
    let bounds = scene.primitives[light as usize].shape.bounds();
    let hits = camera_hits(accel, camera_rays);
    let mut rays = Vec::new();
    for (i, (ray, hit)) in camera_rays.iter().zip(&hits).enumerate() {
        let Some(hit) = hit else { continue };
        let mut rng = Rng::for_sample(7, i as u64, 0);
        let target = bounds.min
            + (bounds.max - bounds.min) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        let origin = ray.at(hit.t * 0.9999);
        rays.push(Ray::new(origin, target - origin, 1e-4, 0.999));
    }
    let (mut single, mut packets) = (vec![false; rays.len()], vec![false; rays.len()]);
    let (mut best_single, mut best_packets) = (Duration::MAX, Duration::MAX);
    for _ in 0..turns {
        let start = Instant::now();
        for (r, b) in rays.chunks(4096).zip(single.chunks_mut(4096)) {
            accel.any_hits_into(r, b, ALL_MASKS, Coherence::Incoherent);
        }
        best_single = best_single.min(start.elapsed());
        let start = Instant::now();
        for (r, b) in rays.chunks(4096).zip(packets.chunks_mut(4096)) {
            accel.any_hits_into(r, b, ALL_MASKS, Coherence::Coherent);
        }
        best_packets = best_packets.min(start.elapsed());
    }
    let blocked = single.iter().filter(|&&b| b).count();
    let rate = |d: Duration| rays.len() as f64 / d.as_secs_f64() / 1e6;
    println!(
        "{name}: {} shadow rays, {:.0}% blocked; one by one {:.2} Mrays/s, packets {:.2} Mrays/s ({:.2}x); same answers: {}",
        rays.len(),
        100.0 * blocked as f64 / rays.len().max(1) as f64,
        rate(best_single),
        rate(best_packets),
        best_single.as_secs_f64() / best_packets.as_secs_f64(),
        single == packets,
    );
    assert_eq!(single, packets, "packets must give the same answers");
}

/// Writes the scene's triangles (boxes by their faces' triangles; spheres left out) as
/// `dir/mesh.bin` and `rays` as `dir/{kind}.bin`, in `bench/kernel_profile.py`'s files:
/// counts as u64, then f32 and u32 arrays, little-endian.
fn write_kernel_profile_files(dir: &std::path::Path, scene: &Scene, rays: &[Ray], kind: &str) {
    use canopy_render::geometry::Shape;
    let triangles: Vec<[Vec3; 3]> = scene
        .primitives
        .iter()
        .flat_map(|p| match &p.shape {
            Shape::Triangle(t) => vec![t.v],
            Shape::Cuboid(c) => c.face_triangles(),
            Shape::Sphere(_) => Vec::new(),
        })
        .collect();
    let mut mesh = Vec::new();
    mesh.extend((3 * triangles.len() as u64).to_le_bytes());
    mesh.extend((triangles.len() as u64).to_le_bytes());
    let corners = triangles.iter().flatten().flat_map(|v| v.to_array());
    mesh.extend(corners.flat_map(f32::to_le_bytes));
    mesh.extend((0..3 * triangles.len() as u32).flat_map(u32::to_le_bytes));
    let mut ray_file = (rays.len() as u64).to_le_bytes().to_vec();
    ray_file.extend(
        rays.iter()
            .flat_map(|r| r.origin.to_array())
            .flat_map(f32::to_le_bytes),
    );
    ray_file.extend(
        rays.iter()
            .flat_map(|r| r.dir.to_array())
            .flat_map(f32::to_le_bytes),
    );
    for (name, bytes) in [
        ("mesh.bin".to_string(), mesh),
        (format!("{kind}.bin"), ray_file),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
}
