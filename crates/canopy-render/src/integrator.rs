//! Unidirectional path tracing over image rows, in parallel with rayon.

use crate::accel::Accel;
use crate::camera::Camera;
use crate::film::Film;
use crate::geometry::Surface;
use crate::rng::Rng;
use crate::scene::Scene;
use canopy_bvh::{Ray, TraversalCounter, TraversalStats};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// What a render did, for the closing summary.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderStats {
    /// Ray segments traced (camera and scattered rays).
    pub rays: u64,
    /// Node visits and primitive tests over all rays; zero unless counted
    /// ([`render_counted`]).
    pub traversal: TraversalStats,
    /// Samples whose radiance was NaN or infinite; they were dropped from the image.
    pub invalid_samples: u64,
    pub elapsed: Duration,
}

impl RenderStats {
    pub fn mrays_per_second(&self) -> f64 {
        self.rays as f64 / self.elapsed.as_secs_f64().max(1e-9) / 1e6
    }
}

/// Renders `scene` with its own settings. `on_row_done` is called once per finished
/// row (from worker threads), for progress reporting.
///
/// The result is bit-identical for any number of threads: every pixel is computed by one
/// thread, its samples summed in order, each from its own random stream.
pub fn render(
    scene: &Scene,
    accel: &Accel,
    on_row_done: &(dyn Fn() + Sync),
) -> (Film, RenderStats) {
    render_with::<()>(scene, accel, on_row_done)
}

/// [`render`], also counting the BVH work of every ray into [`RenderStats::traversal`]
/// (slightly slower; the image is the same).
pub fn render_counted(
    scene: &Scene,
    accel: &Accel,
    on_row_done: &(dyn Fn() + Sync),
) -> (Film, RenderStats) {
    render_with::<TraversalStats>(scene, accel, on_row_done)
}

/// A traversal counter that can report its totals (nothing, for `()`).
trait RowCounter: TraversalCounter + Default {
    fn totals(&self) -> TraversalStats;
}

impl RowCounter for () {
    fn totals(&self) -> TraversalStats {
        TraversalStats::default()
    }
}

impl RowCounter for TraversalStats {
    fn totals(&self) -> TraversalStats {
        *self
    }
}

fn render_with<C: RowCounter>(
    scene: &Scene,
    accel: &Accel,
    on_row_done: &(dyn Fn() + Sync),
) -> (Film, RenderStats) {
    let mut accumulator = Accumulator::new(scene.settings.width, scene.settings.height);
    let stats = accumulate::<C>(
        scene,
        accel,
        &mut accumulator,
        scene.settings.spp,
        on_row_done,
    );
    (accumulator.film(), stats)
}

/// A render in progress: every pixel's sum of samples (in sample order) and how many
/// samples each pixel has. Adding the rest later gives exactly the image of an
/// uninterrupted render.
#[derive(Clone, Debug, PartialEq)]
pub struct Accumulator {
    pub width: u32,
    pub height: u32,
    /// Sum of the radiance samples of each pixel, row by row from the top.
    pub sums: Vec<Vec3>,
    /// Samples every pixel has received.
    pub samples: u32,
    /// Ray segments traced and samples dropped as NaN/inf, over all passes.
    pub rays: u64,
    pub invalid_samples: u64,
}

impl Accumulator {
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            sums: vec![Vec3::ZERO; width as usize * height as usize],
            samples: 0,
            rays: 0,
            invalid_samples: 0,
        }
    }

    /// The mean of the samples so far.
    pub fn film(&self) -> Film {
        let n = self.samples.max(1) as f32;
        Film {
            width: self.width,
            height: self.height,
            pixels: self.sums.iter().map(|s| *s / n).collect(),
        }
    }
}

/// Adds the next `count` samples (indices `samples .. samples + count`) to every pixel
/// of `accumulator`, which must match the scene's image size.
pub fn render_samples(
    scene: &Scene,
    accel: &Accel,
    accumulator: &mut Accumulator,
    count: u32,
    on_row_done: &(dyn Fn() + Sync),
) -> RenderStats {
    accumulate::<()>(scene, accel, accumulator, count, on_row_done)
}

fn accumulate<C: RowCounter>(
    scene: &Scene,
    accel: &Accel,
    accumulator: &mut Accumulator,
    count: u32,
    on_row_done: &(dyn Fn() + Sync),
) -> RenderStats {
    let settings = scene.settings;
    assert_eq!(
        (accumulator.width, accumulator.height),
        (settings.width, settings.height),
        "accumulator and scene differ in image size"
    );
    let camera = Camera::new(&scene.camera, settings.width, settings.height);
    let first_sample = accumulator.samples;
    let rays = AtomicU64::new(0);
    let invalid = AtomicU64::new(0);
    let nodes = AtomicU64::new(0);
    let prims = AtomicU64::new(0);
    let start = Instant::now();
    let width = settings.width as usize;
    accumulator
        .sums
        .par_chunks_mut(width.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            let mut row_rays = 0;
            let mut row_invalid = 0;
            let mut counter = C::default();
            for (x, sum) in row.iter_mut().enumerate() {
                let index = (y * width + x) as u64;
                for sample in first_sample..first_sample + count {
                    let mut rng = Rng::for_sample(settings.seed, index, sample as u64);
                    let s = (x as f32 + rng.next_f32()) / settings.width as f32;
                    let t = (y as f32 + rng.next_f32()) / settings.height as f32;
                    let ray = camera.ray(s, t, &mut rng);
                    let l = trace_path(scene, accel, ray, &mut rng, &mut row_rays, &mut counter);
                    if l.is_finite() {
                        *sum += l;
                    } else {
                        row_invalid += 1;
                    }
                }
            }
            rays.fetch_add(row_rays, Ordering::Relaxed);
            invalid.fetch_add(row_invalid, Ordering::Relaxed);
            let work = counter.totals();
            nodes.fetch_add(work.nodes_visited, Ordering::Relaxed);
            prims.fetch_add(work.primitives_tested, Ordering::Relaxed);
            on_row_done();
        });
    accumulator.samples += count;
    let stats = RenderStats {
        rays: rays.into_inner(),
        invalid_samples: invalid.into_inner(),
        traversal: TraversalStats {
            nodes_visited: nodes.into_inner(),
            primitives_tested: prims.into_inner(),
        },
        elapsed: start.elapsed(),
    };
    accumulator.rays += stats.rays;
    accumulator.invalid_samples += stats.invalid_samples;
    stats
}

/// Radiance arriving along `ray`, following one path of at most `max_depth` segments.
fn trace_path<C: TraversalCounter>(
    scene: &Scene,
    accel: &Accel,
    mut ray: Ray,
    rng: &mut Rng,
    rays: &mut u64,
    counter: &mut C,
) -> Vec3 {
    let mut throughput = Vec3::ONE;
    let mut radiance = Vec3::ZERO;
    for _ in 0..scene.settings.max_depth {
        *rays += 1;
        let Some(hit) = accel.intersect_counted(&scene.primitives, &ray, counter) else {
            radiance += throughput * scene.background.radiance(ray.dir);
            break;
        };
        let primitive = &scene.primitives[hit.prim as usize];
        let material = &scene.materials[primitive.material as usize];
        let surface = primitive.shape.surface(&ray, &hit, &scene.vertex_normals);
        radiance += throughput * material.emitted();
        let Some(scatter) = material.scatter(ray.dir, &surface, rng) else {
            break;
        };
        throughput *= scatter.attenuation;
        if throughput == Vec3::ZERO {
            break;
        }
        ray = spawn_ray(&surface, scatter.direction);
    }
    radiance
}

/// A ray leaving `surface`, its origin pushed off the surface (to the side it leaves
/// towards) by the bound on the hit point's rounding error, so it cannot re-hit the
/// surface it starts on.
#[inline]
fn spawn_ray(surface: &Surface, direction: Vec3) -> Ray {
    let n = surface.geometric_normal;
    let offset = 2.0 * surface.error.max(f32::MIN_POSITIVE);
    let side = if direction.dot(n) >= 0.0 {
        offset
    } else {
        -offset
    };
    Ray::new(surface.p + side * n, direction, 0.0, f32::INFINITY)
}
