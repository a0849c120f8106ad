//! Unidirectional path tracing over image rows, in parallel with rayon. The estimators
//! of one sample are in [`path`].

mod aov;
mod camera_rays;
mod path;
mod scatter;
mod wavefront;

pub use wavefront::STREAM_PATHS;

use crate::accel::Accel;
use crate::aov::{AovBuffers, AovRow, AovSet};
use crate::camera::Camera;
use crate::film::Film;
use crate::lights::Lights;
use crate::region::Region;
use crate::scene::Scene;
use aov::AovTrack;
use camera_rays::{camera_sample, Streams};
use canopy_bvh::{TraversalCounter, TraversalStats};
use glam::Vec3;
use path::{Tracer, Work};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// The order in which a worker traces its paths. Both give the same image, bit for bit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Schedule {
    /// One path at a time, each segment and its shadow rays in turn (the reference).
    Depth,
    /// Many paths at a time, stage by stage ([`wavefront`]).
    #[default]
    Wavefront,
}

impl Schedule {
    pub const ALL: [Schedule; 2] = [Schedule::Depth, Schedule::Wavefront];

    pub fn name(self) -> &'static str {
        match self {
            Schedule::Depth => "depth",
            Schedule::Wavefront => "wavefront",
        }
    }
}

impl std::fmt::Display for Schedule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Schedule {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Schedule::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| format!("unknown schedule `{s}`, expected one of: depth, wavefront"))
    }
}

/// What a render did, for the closing summary.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderStats {
    /// Rays traced: camera, scattered and shadow rays.
    pub rays: u64,
    /// The shadow rays among them (light sampling's occlusion queries).
    pub shadow_rays: u64,
    /// Node visits and primitive tests of the closest-hit queries; zero unless counted
    /// ([`render_counted`]).
    pub traversal: TraversalStats,
    /// Time the workers spent in shadow-ray queries, summed over threads; zero unless
    /// counted ([`render_counted`]).
    pub shadow_time: Duration,
    /// Time the workers spent rendering, summed over threads (for shares of it).
    pub thread_time: Duration,
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

/// [`render`], also counting the BVH work of every closest-hit query into
/// [`RenderStats::traversal`] and timing the shadow rays into [`RenderStats::shadow_time`]
/// (slightly slower; the image is the same).
pub fn render_counted(
    scene: &Scene,
    accel: &Accel,
    on_row_done: &(dyn Fn() + Sync),
) -> (Film, RenderStats) {
    render_with::<Profile>(scene, accel, on_row_done)
}

/// What a render measures besides the image: nothing, or traversal work and shadow-ray
/// time.
pub(crate) trait Probe: TraversalCounter + Default {
    /// Whether it counts or times anything (then queries go ray by ray).
    const MEASURES: bool;
    fn totals(&self) -> TraversalStats;
    /// Runs a shadow-ray query, timing it if this probe times.
    fn time_shadow(&mut self, query: impl FnOnce() -> bool) -> bool;
    fn shadow_time(&self) -> Duration;
}

impl Probe for () {
    const MEASURES: bool = false;
    fn totals(&self) -> TraversalStats {
        TraversalStats::default()
    }
    #[inline(always)]
    fn time_shadow(&mut self, query: impl FnOnce() -> bool) -> bool {
        query()
    }
    fn shadow_time(&self) -> Duration {
        Duration::ZERO
    }
}

/// Counts closest-hit traversal work and times shadow rays.
#[derive(Default)]
pub(crate) struct Profile {
    work: TraversalStats,
    shadow: Duration,
}

impl TraversalCounter for Profile {
    #[inline(always)]
    fn visit_node(&mut self) {
        self.work.visit_node();
    }
    #[inline(always)]
    fn test_primitive(&mut self) {
        self.work.test_primitive();
    }
}

impl Probe for Profile {
    const MEASURES: bool = true;
    fn totals(&self) -> TraversalStats {
        self.work
    }
    fn time_shadow(&mut self, query: impl FnOnce() -> bool) -> bool {
        let start = Instant::now();
        let blocked = query();
        self.shadow += start.elapsed();
        blocked
    }
    fn shadow_time(&self) -> Duration {
        self.shadow
    }
}

fn render_with<P: Probe>(
    scene: &Scene,
    accel: &Accel,
    on_row_done: &(dyn Fn() + Sync),
) -> (Film, RenderStats) {
    let mut accumulator = Accumulator::new(scene.settings.width, scene.settings.height);
    let stats = accumulate::<P>(
        scene,
        accel,
        &mut accumulator,
        scene.settings.spp,
        Schedule::default(),
        on_row_done,
        &|| true,
    )
    .expect("a pass told to keep going is never abandoned");
    (accumulator.film(), stats)
}

/// A render in progress: every pixel's sum of samples (in sample order) and how many
/// samples each pixel has, over the whole image or a region of it. Adding the rest
/// later gives exactly the image of an uninterrupted render.
#[derive(Clone, Debug, PartialEq)]
pub struct Accumulator {
    /// The pixels accumulated, in the scene's image.
    pub region: Region,
    /// Sum of the radiance samples of each pixel of the region, row by row from the top.
    pub sums: Vec<Vec3>,
    /// Samples every pixel has received.
    pub samples: u32,
    /// Ray segments traced and samples dropped as NaN/inf, over all passes.
    pub rays: u64,
    pub invalid_samples: u64,
    /// The AOV layers accumulated with the samples (none unless asked for).
    pub aovs: AovBuffers,
}

impl Accumulator {
    /// An empty accumulator for the whole of a `width` x `height` image.
    pub fn new(width: u32, height: u32) -> Self {
        Self::for_region(Region::full(width, height))
    }

    /// An empty accumulator for `region` of the image.
    pub fn for_region(region: Region) -> Self {
        Self {
            region,
            sums: vec![Vec3::ZERO; region.pixels()],
            samples: 0,
            rays: 0,
            invalid_samples: 0,
            aovs: AovBuffers::default(),
        }
    }

    /// This accumulator, also accumulating the AOVs of `set` (from its next sample on:
    /// call it on an empty one).
    pub fn with_aovs(mut self, set: AovSet) -> Self {
        self.aovs = AovBuffers::new(set, self.region.pixels());
        self
    }

    /// The AOV layers as images of the samples so far.
    pub fn aov_images(&self) -> AovBuffers {
        self.aovs.resolved(self.samples)
    }

    /// The mean of the samples so far: an image of the region's size.
    pub fn film(&self) -> Film {
        let n = self.samples.max(1) as f32;
        Film {
            width: self.region.width,
            height: self.region.height,
            pixels: self.sums.iter().map(|s| *s / n).collect(),
        }
    }
}

/// Adds the next `count` samples (indices `samples .. samples + count`) to every pixel
/// of `accumulator`. Its region must lie within the scene's image (see
/// [`Region::check_within`]); a pixel gets the same samples in any region.
pub fn render_samples(
    scene: &Scene,
    accel: &Accel,
    accumulator: &mut Accumulator,
    count: u32,
    on_row_done: &(dyn Fn() + Sync),
) -> RenderStats {
    render_samples_with(
        scene,
        accel,
        accumulator,
        count,
        Schedule::default(),
        on_row_done,
    )
}

/// [`render_samples`] in the given schedule (the image is the same in every one).
pub fn render_samples_with(
    scene: &Scene,
    accel: &Accel,
    accumulator: &mut Accumulator,
    count: u32,
    schedule: Schedule,
    on_row_done: &(dyn Fn() + Sync),
) -> RenderStats {
    render_samples_abandonable(
        scene,
        accel,
        accumulator,
        count,
        schedule,
        on_row_done,
        &|| true,
    )
    .expect("a pass told to keep going is never abandoned")
}

/// [`render_samples_with`] that a caller may abandon: `keep_going` is asked before each
/// row, and once it says no the remaining rows are skipped and `None` returned. The
/// accumulator is then torn — some rows have the new samples, others not, and its
/// sample count is unchanged — so the caller puts back a copy taken before, or drops it.
pub fn render_samples_abandonable(
    scene: &Scene,
    accel: &Accel,
    accumulator: &mut Accumulator,
    count: u32,
    schedule: Schedule,
    on_row_done: &(dyn Fn() + Sync),
    keep_going: &(dyn Fn() -> bool + Sync),
) -> Option<RenderStats> {
    accumulate::<()>(
        scene,
        accel,
        accumulator,
        count,
        schedule,
        on_row_done,
        keep_going,
    )
}

fn accumulate<P: Probe>(
    scene: &Scene,
    accel: &Accel,
    accumulator: &mut Accumulator,
    count: u32,
    schedule: Schedule,
    on_row_done: &(dyn Fn() + Sync),
    keep_going: &(dyn Fn() -> bool + Sync),
) -> Option<RenderStats> {
    let settings = scene.settings;
    let region = accumulator.region;
    if let Err(e) = region.check_within(settings.width, settings.height) {
        panic!("the accumulator does not fit the scene's image: {e}");
    }
    let camera = Camera::new(&scene.camera, settings.width, settings.height);
    let lights = Lights::new(scene);
    let tracer = Tracer::new(scene, accel, &lights);
    let first_sample = accumulator.samples;
    let totals = Totals::default();
    let start = Instant::now();
    let size = (settings.width, settings.height);
    let streams = Streams {
        sampler: settings.sampler,
        seed: settings.seed,
    };
    let width = region.width as usize;
    let abandoned = AtomicBool::new(false);
    // The AOV layers row by row beside the sums (none when not asked for).
    let mut aov_rows: Vec<Option<AovRow>> = match accumulator.aovs.set.is_empty() {
        true => (0..region.height).map(|_| None).collect(),
        false => accumulator
            .aovs
            .rows_mut(width)
            .into_iter()
            .map(Some)
            .collect(),
    };
    accumulator
        .sums
        .par_chunks_mut(width)
        .zip(aov_rows.par_iter_mut())
        .enumerate()
        .for_each(|(row_in_region, (row, aovs))| {
            if abandoned.load(Ordering::Relaxed) || !keep_going() {
                abandoned.store(true, Ordering::Relaxed);
                return;
            }
            let row_start = Instant::now();
            let mut work = Work::<P>::default();
            let y = region.y as usize + row_in_region;
            let invalid = match schedule {
                Schedule::Depth => {
                    let mut invalid = 0;
                    for (x_in_region, sum) in row.iter_mut().enumerate() {
                        let pixel = (region.x + x_in_region as u32, y as u32);
                        for sample in first_sample..first_sample + count {
                            let (ray, mut rng) =
                                camera_sample(&camera, size, streams, pixel, sample);
                            let mut track = aovs.is_some().then(AovTrack::default);
                            let l = tracer.radiance(ray, &mut rng, &mut work, track.as_mut());
                            if l.is_finite() {
                                *sum += l;
                            } else {
                                invalid += 1;
                            }
                            if let (Some(aovs), Some(track)) = (aovs.as_mut(), track) {
                                aovs.add(x_in_region, &track.sample, sample == 0);
                            }
                        }
                    }
                    invalid
                }
                Schedule::Wavefront => {
                    let block = wavefront::Block {
                        x: region.x,
                        y: y as u32,
                        sums: row,
                    };
                    let samples = first_sample..first_sample + count;
                    wavefront::render_block(
                        &tracer,
                        &camera,
                        block,
                        aovs.as_mut(),
                        samples,
                        STREAM_PATHS,
                        &mut work,
                    )
                }
            };
            totals.add(&work, invalid, row_start.elapsed());
            on_row_done();
        });
    if abandoned.into_inner() {
        return None;
    }
    accumulator.samples += count;
    let stats = totals.stats(start.elapsed());
    accumulator.rays += stats.rays;
    accumulator.invalid_samples += stats.invalid_samples;
    Some(stats)
}

/// Adds the AOVs of the next `count` samples (indices `samples .. samples + count`) to
/// `accumulator`, and nothing else: for a device that renders the radiance itself (the
/// GPU), whose AOVs the CPU traces through `accel`. Call it before the device adds its
/// samples. Returns the rays traced.
pub fn render_aov_samples(
    scene: &Scene,
    accel: &Accel,
    accumulator: &mut Accumulator,
    count: u32,
) -> u64 {
    let settings = scene.settings;
    let camera = Camera::new(&scene.camera, settings.width, settings.height);
    let lights = Lights::new(scene);
    let tracer = Tracer::new(scene, accel, &lights);
    let streams = Streams {
        sampler: settings.sampler,
        seed: settings.seed,
    };
    let totals = Totals::default();
    let samples = accumulator.samples..accumulator.samples + count;
    add_aovs(&tracer, &camera, streams, accumulator, samples, &totals);
    totals.rays.into_inner()
}

/// Adds the AOVs of samples `samples` of every pixel of `accumulator`'s region, traced
/// alone ([`Tracer::aov_sample`]), row by row in parallel, each pixel's in sample order.
fn add_aovs(
    tracer: &Tracer,
    camera: &Camera,
    streams: Streams,
    accumulator: &mut Accumulator,
    samples: std::ops::Range<u32>,
    totals: &Totals,
) {
    let region = accumulator.region;
    let settings = tracer.scene.settings;
    let size = (settings.width, settings.height);
    let mut rows = accumulator.aovs.rows_mut(region.width as usize);
    rows.par_iter_mut().enumerate().for_each(|(row, aovs)| {
        let row_start = Instant::now();
        let mut work = Work::<()>::default();
        let y = region.y + row as u32;
        for (x_in_region, x) in (region.x..region.x + region.width).enumerate() {
            for sample in samples.clone() {
                let (ray, mut rng) = camera_sample(camera, size, streams, (x, y), sample);
                let seen = tracer.aov_sample(ray, &mut rng, &mut work);
                aovs.add(x_in_region, &seen, sample == 0);
            }
        }
        totals.add(&work, 0, row_start.elapsed());
    });
}

/// Sums of the workers' counts, added once per row.
#[derive(Default)]
struct Totals {
    rays: AtomicU64,
    shadow_rays: AtomicU64,
    invalid: AtomicU64,
    nodes: AtomicU64,
    prims: AtomicU64,
    shadow_nanos: AtomicU64,
    thread_nanos: AtomicU64,
}

impl Totals {
    fn add<P: Probe>(&self, work: &Work<P>, invalid: u64, busy: Duration) {
        let traversal = work.probe.totals();
        for (total, value) in [
            (&self.rays, work.rays),
            (&self.shadow_rays, work.shadow_rays),
            (&self.invalid, invalid),
            (&self.nodes, traversal.nodes_visited),
            (&self.prims, traversal.primitives_tested),
            (
                &self.shadow_nanos,
                work.probe.shadow_time().as_nanos() as u64,
            ),
            (&self.thread_nanos, busy.as_nanos() as u64),
        ] {
            total.fetch_add(value, Ordering::Relaxed);
        }
    }

    fn stats(self, elapsed: Duration) -> RenderStats {
        RenderStats {
            rays: self.rays.into_inner(),
            shadow_rays: self.shadow_rays.into_inner(),
            invalid_samples: self.invalid.into_inner(),
            traversal: TraversalStats {
                nodes_visited: self.nodes.into_inner(),
                primitives_tested: self.prims.into_inner(),
            },
            shadow_time: Duration::from_nanos(self.shadow_nanos.into_inner()),
            thread_time: Duration::from_nanos(self.thread_nanos.into_inner()),
            elapsed,
        }
    }
}
