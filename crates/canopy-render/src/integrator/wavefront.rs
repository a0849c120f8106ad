//! The wavefront (breadth-first) schedule: a worker takes a block of pixels and keeps
//! all their paths of a pass of samples in one stream, advancing the whole stream a
//! stage at a time: closest hits of every path, then every path's vertex (shading,
//! light samples, BSDF sample, roulette), then every shadow ray as one occlusion batch,
//! then the paths that ended leave the stream (the last path taking each one's place).
//! Each stage runs one kernel over many rays, so its code and the tree's top levels
//! stay in the cache.
//!
//! The arithmetic is the depth-first schedule's ([`super::path`]) and each path draws
//! from its own random stream in the same order, so the image is the same bit for bit.

use super::aov::AovTrack;
use super::camera_rays::{camera_rays, PassSamples, Streams};
use super::path::{DirectLight, PathState, Scattering, Tracer, Work};
use super::scatter::Scatters;
use super::Probe;
use crate::aov::AovRow;
use crate::camera::Camera;
use crate::rng::Rng;
use canopy_bvh::{Coherence, Hit, Ray, RayQuery, ALL_MASKS};
use glam::Vec3;
use std::cell::RefCell;
use std::ops::Range;

/// Paths a stream holds at most: a pass takes as many samples of its block's pixels as
/// fit (at least one). A few thousand paths of state stay within a core's L2 cache.
pub const STREAM_PATHS: usize = 4096;

/// How many hits ahead the vertex stage asks for the primitive record it will shade.
const SHADE_AHEAD: usize = 8;

/// A path in the stream: its state, its random stream and where its sample goes.
struct StreamPath {
    path: PathState,
    rng: Rng,
    /// Index of its sample in the pass (pixel-major).
    slot: u32,
}

// A path that ends is replaced by the stream's last: at 128 bytes that copy is inline,
// above it a call to `memmove` (3.5% of paper-3's render at 144 bytes).
const _: () = assert!(std::mem::size_of::<StreamPath>() <= 128);

/// A pixel block of the image: `pixels` consecutive pixels of one image row from
/// (`x`, `y`), the first of `sums`.
pub(super) struct Block<'a> {
    pub x: u32,
    pub y: u32,
    pub sums: &'a mut [Vec3],
}

/// Adds `samples` to every pixel of `block`, in sample order, tracing at most
/// `stream_paths` paths at a time (at least one sample of each pixel); returns how many samples were
/// dropped as NaN or infinite.
pub(super) fn render_block<P: Probe>(
    tracer: &Tracer,
    camera: &Camera,
    block: Block,
    aovs: Option<&mut AovRow>,
    samples: Range<u32>,
    stream_paths: usize,
    work: &mut Work<P>,
) -> u64 {
    let pixels = block.sums.len();
    let per_pass = (stream_paths / pixels.max(1)).clamp(1, samples.len().max(1)) as u32;
    // Each worker keeps its stream's buffers from block to block: a block is often one
    // row of one sample, and allocating them anew cost as much as tracing short paths.
    STREAM.with_borrow_mut(|stream| {
        render_passes(tracer, camera, block, aovs, samples, per_pass, stream, work)
    })
}

thread_local! {
    static STREAM: RefCell<Stream> = RefCell::new(Stream::default());
}

#[allow(clippy::too_many_arguments)]
fn render_passes<P: Probe>(
    tracer: &Tracer,
    camera: &Camera,
    block: Block,
    mut aovs: Option<&mut AovRow>,
    samples: Range<u32>,
    per_pass: u32,
    stream: &mut Stream,
    work: &mut Work<P>,
) -> u64 {
    let settings = tracer.scene.settings;
    let pixels = block.sums.len();
    let mut invalid = 0;
    let mut start = samples.start;
    while start < samples.end {
        let samples = per_pass.min(samples.end - start);
        stream.clear_results(pixels * samples as usize, aovs.is_some());
        let pass = PassSamples {
            width: settings.width,
            height: settings.height,
            streams: Streams {
                sampler: settings.sampler,
                seed: settings.seed,
            },
            first_x: block.x,
            y: block.y,
            pixels,
            samples: start..start + samples,
        };
        // Slots are pixel-major, as the rays come.
        let mut slot = 0;
        camera_rays(camera, &pass, |ray, rng| {
            stream.paths.push(StreamPath {
                path: PathState::new(ray),
                rng,
                slot,
            });
            slot += 1;
        });
        stream.trace(tracer, work);
        for (i, sum) in block.sums.iter_mut().enumerate() {
            for l in &stream.results[i * samples as usize..(i + 1) * samples as usize] {
                if l.is_finite() {
                    *sum += *l;
                } else {
                    invalid += 1;
                }
            }
        }
        if let Some(row) = aovs.as_deref_mut() {
            let per_pixel = stream.tracks.chunks(samples as usize);
            for (i, tracks) in per_pixel.enumerate() {
                for (k, track) in tracks.iter().enumerate() {
                    row.add(i, &track.sample, start + k as u32 == 0);
                }
            }
        }
        start += samples;
    }
    invalid
}

/// The stream's paths and the scratch space of its stages, kept between passes.
#[derive(Default)]
struct Stream {
    paths: Vec<StreamPath>,
    /// The stage's path segments, gathered for one closest-hit batch, and their hits.
    segments: Vec<Ray>,
    hits: Vec<Option<Hit>>,
    /// Whether each path goes on after the stage's vertex.
    goes_on: Vec<bool>,
    /// The stage's BSDF samples drawn in lanes.
    scatters: Scatters,
    /// The light sampling of the stage's vertices that sampled light: path and tests.
    directs: Vec<(u32, DirectLight)>,
    /// Shadow rays of the stage, in path order, and whether each is blocked.
    shadows: Vec<Ray>,
    blocked: Vec<bool>,
    /// Each finished path's radiance, by slot.
    results: Vec<Vec3>,
    /// What each path saw for the AOVs, by slot (empty when they are not asked for).
    tracks: Vec<AovTrack>,
}

impl Stream {
    fn clear_results(&mut self, slots: usize, track_aovs: bool) {
        self.results.clear();
        self.results.resize(slots, Vec3::ZERO);
        self.tracks.clear();
        if track_aovs {
            self.tracks.resize(slots, AovTrack::default());
        }
    }

    /// Traces every path of the stream to its end.
    fn trace<P: Probe>(&mut self, tracer: &Tracer, work: &mut Work<P>) {
        // The first segments are camera rays, a pixel's samples side by side, and the
        // first shadow rays start from where they hit: coherent.
        let mut coherent = true;
        while !self.paths.is_empty() {
            self.closest_hits(tracer, coherent, work);
            self.goes_on.clear();
            self.directs.clear();
            self.vertices(tracer);
            self.shadow_rays(tracer, coherent, work);
            coherent = false;
            // Light that arrives, in path order, then the paths that ended leave.
            let mut answers = self.blocked.iter();
            for (i, direct) in &self.directs {
                let arriving = direct.arriving(|_| *answers.next().expect("answered"));
                self.paths[*i as usize].path.radiance += arriving;
            }
            for (p, goes_on) in self.paths.iter().zip(&self.goes_on) {
                if !goes_on {
                    self.results[p.slot as usize] = p.path.radiance;
                }
            }
            // Backwards, so that each path swapped in has been looked at already.
            for (i, goes_on) in self.goes_on.iter().enumerate().rev() {
                if !goes_on {
                    self.paths.swap_remove(i);
                }
            }
        }
    }

    /// Every path's vertex at the hit of its segment: emission and light sampling path
    /// by path, then the BSDF samples grouped by material and drawn over SIMD lanes
    /// ([`Scatters`]), then each path's roulette. Each path draws its numbers in the
    /// order [`Tracer::vertex`] does.
    fn vertices(&mut self, tracer: &Tracer) {
        self.scatters.clear();
        for (i, (p, hit)) in self.paths.iter_mut().zip(&self.hits).enumerate() {
            if let Some(Some(ahead)) = self.hits.get(i + SHADE_AHEAD) {
                tracer.scene.prefetch_primitive(ahead);
            }
            let track = self.tracks.get_mut(p.slot as usize);
            let goes_on = match tracer.vertex_head(&mut p.path, *hit, &mut p.rng, track) {
                None => false,
                Some(Scattering {
                    surface,
                    material,
                    direct,
                }) => {
                    if let Some(direct) = direct {
                        self.directs.push((i as u32, direct));
                    }
                    let dir = p.path.ray.dir;
                    let draw = material.draw(&mut p.rng);
                    match self.scatters.push(i as u32, dir, surface, material, draw) {
                        // Decided once the sample is drawn, below.
                        Ok(()) => false,
                        Err((surface, material)) => {
                            let sample = material.sample_drawn(dir, &surface, draw);
                            tracer.vertex_tail(&mut p.path, &surface, sample, &mut p.rng)
                        }
                    }
                }
            };
            self.goes_on.push(goes_on);
        }
        self.scatters.sample();
        for (queued, sample) in self.scatters.samples() {
            let i = queued.path as usize;
            let p = &mut self.paths[i];
            self.goes_on[i] = tracer.vertex_tail(&mut p.path, &queued.surface, sample, &mut p.rng);
        }
    }

    /// The closest hit of every path's next segment: one batch through the structure
    /// (in packets where the rays are `coherent`), or ray by ray where see-through
    /// surfaces draw random numbers or work is counted.
    fn closest_hits<P: Probe>(&mut self, tracer: &Tracer, coherent: bool, work: &mut Work<P>) {
        let n = self.paths.len();
        work.rays += n as u64;
        self.hits.clear();
        if tracer.see_through || P::MEASURES {
            for p in &mut self.paths {
                let hit = tracer.intersect(&p.path.ray, &mut p.rng, work);
                self.hits.push(hit);
            }
            return;
        }
        self.hits.resize(n, None);
        self.segments.clear();
        self.segments.extend(self.paths.iter().map(|p| p.path.ray));
        let coherence = Coherence::hint(coherent);
        tracer.accel.closest_hits_into(
            &self.segments,
            &mut self.hits,
            ALL_MASKS,
            coherence,
            &mut (),
        )
    }

    /// Answers the shadow rays of every vertex of the stage, in path order (in packets
    /// where they are `coherent`).
    fn shadow_rays<P: Probe>(&mut self, tracer: &Tracer, coherent: bool, work: &mut Work<P>) {
        self.blocked.clear();
        if tracer.see_through || P::MEASURES {
            for (i, direct) in &self.directs {
                let p = &mut self.paths[*i as usize];
                for test in direct.tests.iter().flatten() {
                    let blocked = tracer.occluded(&test.ray, &mut p.rng, work);
                    self.blocked.push(blocked);
                }
            }
            return;
        }
        self.shadows.clear();
        for (_, direct) in &self.directs {
            self.shadows
                .extend(direct.tests.iter().flatten().map(|t| t.ray));
        }
        let n = self.shadows.len();
        work.rays += n as u64;
        work.shadow_rays += n as u64;
        self.blocked.resize(n, false);
        // The first vertices' shadow rays, a pixel's samples side by side towards one
        // light, are coherent: packets pay over trees that stay in the cache (1.9x on
        // spheres), not over larger ones, whose rays part ways between the leaves
        // (0.6-0.7x on the 202k-triangle dragon, `examples/packet_speed.rs --shadows`).
        let coherence = Coherence::hint(coherent && !tracer.accel.orders_batches());
        let (shadows, blocked) = (&self.shadows, &mut self.blocked);
        tracer
            .accel
            .any_hits_into(shadows, blocked, ALL_MASKS, coherence)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::{Accel, AccelKind};
    use crate::builtin::BuiltinScene;
    use crate::lights::Lights;
    use canopy_bvh::{BuildParams, BvhWidth};

    /// A pass may hold one path or thousands: every sample of a row sums the same.
    #[test]
    fn any_stream_size_gives_the_same_sums() {
        let mut scene = BuiltinScene::find("paper-3").unwrap().load().unwrap();
        (scene.settings.width, scene.settings.height) = (24, 16);
        let accel = Accel::for_scene(
            &scene,
            AccelKind::default(),
            BvhWidth::Four,
            &BuildParams::default(),
            None,
        );
        let lights = Lights::new(&scene);
        let tracer = Tracer::new(&scene, &accel, &lights);
        let camera = Camera::new(&scene.camera, 24, 16);
        let row = |stream_paths: usize| {
            let mut sums = vec![Vec3::ZERO; 20];
            let block = Block {
                x: 2,
                y: 9,
                sums: &mut sums,
            };
            let mut work = Work::<()>::default();
            render_block(
                &tracer,
                &camera,
                block,
                None,
                3..10,
                stream_paths,
                &mut work,
            );
            (sums, work.rays)
        };
        let reference = row(STREAM_PATHS);
        assert!(reference.0.iter().all(|s| *s != Vec3::ZERO));
        for stream_paths in [1, 7, 20, 45, 1 << 20] {
            assert_eq!(
                row(stream_paths),
                reference,
                "{stream_paths} paths a stream"
            );
        }
    }
}
