//! What the benchmarks share: where the large meshes are, and camera rays.
#![allow(dead_code)] // each benchmark uses its own subset

use canopy_bvh::Ray;
use canopy_bvh::RayQuery;
use canopy_render::camera::Camera;
use canopy_render::rng::Rng;
use canopy_render::Scene;
use std::path::PathBuf;

/// `$CANOPY_MESHES`, else `../shared/assets/meshes` next to the repository.
pub fn mesh_dir() -> PathBuf {
    std::env::var_os("CANOPY_MESHES")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../../../shared/assets/meshes"
            ))
        })
}

/// Camera rays through a `side` x `side` grid, one per pixel centre.
pub fn camera_rays(scene: &Scene, side: u32) -> Vec<Ray> {
    let camera = Camera::new(&scene.camera, side, side);
    let mut rng = Rng::for_sample(0, 0, 0);
    (0..side * side)
        .map(|i| {
            camera.ray(
                ((i % side) as f32 + 0.5) / side as f32,
                ((i / side) as f32 + 0.5) / side as f32,
                &mut rng,
            )
        })
        .collect()
}

/// Camera rays as a wavefront stream holds them: a `side` x `side` image row by row,
/// `samples` jittered rays through each pixel side by side (each from its own random
/// stream, through the lens of a defocused camera).
pub fn stream_camera_rays(scene: &Scene, side: u32, samples: u32) -> Vec<Ray> {
    let camera = Camera::new(&scene.camera, side, side);
    let mut rays = Vec::with_capacity((side * side * samples) as usize);
    for pixel in 0..side * side {
        let (x, y) = (pixel % side, pixel / side);
        for sample in 0..samples {
            let mut rng = Rng::for_sample(0, pixel as u64, sample as u64);
            let s = (x as f32 + rng.next_f32()) / side as f32;
            let t = (y as f32 + rng.next_f32()) / side as f32;
            rays.push(camera.ray(s, t, &mut rng));
        }
    }
    rays
}

/// Incoherent rays: from the surface points that camera rays through a `side` x `side`
/// grid hit (backed off a little along the camera ray), in uniform random directions.
pub fn incoherent_rays(scene: &Scene, accel: &canopy_render::Accel, side: u32) -> Vec<Ray> {
    let scale = scene
        .primitive_bounds()
        .iter()
        .fold(canopy_bvh::Aabb::EMPTY, |a, &b| a.union(b))
        .extent()
        .max_element();
    let mut rng = Rng::for_sample(1, 0, 0);
    camera_rays(scene, side)
        .iter()
        .filter_map(|ray| {
            let hit = accel.intersect(ray)?;
            let origin = ray.origin + ray.dir * hit.t - ray.dir * (1e-4 * scale);
            Some(Ray::new(origin, rng.unit_vector(), 0.0, f32::INFINITY))
        })
        .collect()
}
