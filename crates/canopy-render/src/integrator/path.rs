//! The radiance along one camera ray: the report's estimator (follow the BSDF until light
//! is found by chance) and the path tracer with next-event estimation, which also samples
//! the lights (and an environment map) at every vertex and weights both strategies by
//! multiple importance sampling (Veach 1997, power heuristic).

use super::aov::AovTrack;
use super::Probe;
use crate::accel::Accel;
use crate::geometry::Surface;
use crate::lights::Lights;
use crate::material::{BsdfSample, Material};
use crate::rng::Rng;
use crate::sampling::power_heuristic;
use crate::scene::{Integrator, Scene};
use canopy_bvh::{Hit, Ray, RayQuery, ALL_MASKS};
use glam::Vec3;

/// Segments a path has before Russian roulette may end it.
const ROULETTE_AFTER: u32 = 3;

/// Most survival probability of Russian roulette: even bright paths end now and then.
const ROULETTE_MAX_SURVIVAL: f32 = 0.95;

/// Shadow rays stop this fraction short of the light's point, so the light itself (or a
/// rounding error on it) never counts as an occluder.
const SHADOW_SHORTENING: f32 = 1e-4;

/// Most see-through layers a ray passes before the next surface counts as opaque.
const MAX_SEE_THROUGH_LAYERS: u32 = 256;

/// What a path can see of the render: scene, structures and the lights.
pub(super) struct Tracer<'a> {
    pub scene: &'a Scene,
    pub accel: &'a Accel,
    pub lights: &'a Lights,
    /// Whether some surfaces let rays through (alpha modes), so that hits must be tested.
    pub see_through: bool,
    /// Whether light sampling has anything to sample: emitters, or a background that is
    /// sampled. Without, vertices make no shadow tests (and draw no random numbers for them).
    pub samples_light: bool,
}

impl<'a> Tracer<'a> {
    pub fn new(scene: &'a Scene, accel: &'a Accel, lights: &'a Lights) -> Self {
        Self {
            scene,
            accel,
            lights,
            see_through: scene.has_see_through(),
            samples_light: !lights.is_empty() || scene.background.is_sampled(),
        }
    }
}

/// Rays traced by one worker, and its probe.
#[derive(Default)]
pub(super) struct Work<P> {
    /// Every ray: camera, scattered and shadow rays.
    pub rays: u64,
    pub shadow_rays: u64,
    pub probe: P,
}

/// The previous vertex of a path that arrived by sampling a non-delta BSDF: an emitter or
/// the background found next shares its light with light sampling from there.
#[derive(Clone, Copy)]
struct BsdfVertex {
    p: Vec3,
    pdf: f32,
}

impl BsdfVertex {
    /// No such vertex (the camera ray, or after a delta bounce), told by a pdf no sample
    /// has rather than by an `Option`'s tag: without those 4 bytes a path and its random
    /// stream fit the 128 bytes the renderer's stream copies inline.
    const NONE: Self = Self {
        p: Vec3::ZERO,
        pdf: f32::NEG_INFINITY,
    };

    #[inline(always)]
    fn found(self) -> Option<Self> {
        (self.pdf != f32::NEG_INFINITY).then_some(self)
    }
}

/// A path being traced: where it goes next and what it has gathered.
#[derive(Clone, Copy)]
pub(super) struct PathState {
    /// The segment to trace next.
    pub ray: Ray,
    /// Segments traced so far, this one included once traced (1 for the camera ray).
    pub segments: u32,
    pub throughput: Vec3,
    pub radiance: Vec3,
    /// None for the camera ray and after delta bounces: nothing else could find the light.
    previous: BsdfVertex,
}

impl PathState {
    pub fn new(camera_ray: Ray) -> Self {
        Self {
            ray: camera_ray,
            segments: 1,
            throughput: Vec3::ONE,
            radiance: Vec3::ZERO,
            previous: BsdfVertex::NONE,
        }
    }
}

/// A shadow ray of light sampling and the light it brings where nothing blocks it.
#[derive(Clone, Copy)]
pub(super) struct ShadowTest {
    pub ray: Ray,
    pub light: Vec3,
}

/// Light sampling at one vertex: the shadow tests of an emitter sample and of a
/// background sample (either may be absent), and the path's throughput there.
#[derive(Clone, Copy)]
pub(super) struct DirectLight {
    pub tests: [Option<ShadowTest>; 2],
    pub throughput: Vec3,
}

impl DirectLight {
    /// The light that arrives, given which shadow rays are blocked (asked in order).
    #[inline]
    pub fn arriving(&self, mut blocked: impl FnMut(&Ray) -> bool) -> Vec3 {
        let mut direct = Vec3::ZERO;
        for test in self.tests.iter().flatten() {
            if !blocked(&test.ray) {
                direct += test.light;
            }
        }
        self.throughput * direct
    }
}

/// What one vertex of a path leaves to do.
pub(super) struct Vertex {
    /// Light sampling to finish once its shadow rays are answered.
    pub direct: Option<DirectLight>,
    /// Whether the path goes on (along its new `ray`).
    pub goes_on: bool,
}

/// A vertex that scatters, up to its BSDF sample: the path goes on from `surface` by a
/// sample of `material` unless the sample or roulette ends it, and `direct` is its light
/// sampling.
pub(super) struct Scattering {
    pub surface: Surface,
    pub material: Material,
    pub direct: Option<DirectLight>,
}

impl Tracer<'_> {
    /// One sample of the radiance arriving along the camera ray `ray`, traced depth
    /// first: each segment and its shadow rays in turn; what it sees for the AOVs goes
    /// into `track` where given.
    pub fn radiance<P: Probe>(
        &self,
        ray: Ray,
        rng: &mut Rng,
        work: &mut Work<P>,
        mut track: Option<&mut AovTrack>,
    ) -> Vec3 {
        let mut path = PathState::new(ray);
        loop {
            work.rays += 1;
            let hit = self.intersect(&path.ray, rng, work);
            let vertex = self.vertex(&mut path, hit, rng, track.as_deref_mut());
            if let Some(direct) = vertex.direct {
                path.radiance += direct.arriving(|shadow| self.occluded(shadow, rng, work));
            }
            if !vertex.goes_on {
                return path.radiance;
            }
        }
    }

    /// Advances `path` by the segment it has just traced (`hit` is where it ends).
    /// Randomness is drawn in one order for both schedules: light samples, then the
    /// BSDF sample and roulette, then (for see-through surfaces) the shadow rays.
    #[inline(always)]
    pub fn vertex(
        &self,
        path: &mut PathState,
        hit: Option<Hit>,
        rng: &mut Rng,
        track: Option<&mut AovTrack>,
    ) -> Vertex {
        let Some(Scattering {
            surface,
            material,
            direct,
        }) = self.vertex_head(path, hit, rng, track)
        else {
            return Vertex {
                direct: None,
                goes_on: false,
            };
        };
        let sample = material.sample(path.ray.dir, &surface, rng);
        Vertex {
            direct,
            goes_on: self.vertex_tail(path, &surface, sample, rng),
        }
    }

    /// The vertex up to its BSDF sample: the emission found is added and the lights
    /// sampled (and the AOVs' `track` told what the segment found); `None` where the
    /// path ends here.
    #[inline(always)]
    pub fn vertex_head(
        &self,
        path: &mut PathState,
        hit: Option<Hit>,
        rng: &mut Rng,
        track: Option<&mut AovTrack>,
    ) -> Option<Scattering> {
        match self.scene.settings.integrator {
            Integrator::Path => self.path_head(path, hit, rng, track),
            Integrator::Bsdf => self.bsdf_head(path, hit, track),
        }
    }

    /// The vertex from its BSDF sample on (`None`: drawn where it cannot scatter):
    /// whether the path goes on, along its new `ray`.
    #[inline(always)]
    pub fn vertex_tail(
        &self,
        path: &mut PathState,
        surface: &Surface,
        sample: Option<BsdfSample>,
        rng: &mut Rng,
    ) -> bool {
        let settings = self.scene.settings;
        let Some(sample) = sample else {
            return false;
        };
        path.throughput *= sample.weight;
        if settings.integrator == Integrator::Path {
            path.previous = if sample.delta {
                BsdfVertex::NONE
            } else {
                BsdfVertex {
                    p: surface.p,
                    pdf: sample.pdf,
                }
            };
            if !self.survives_roulette(&mut path.throughput, path.segments, rng) {
                return false;
            }
        }
        if path.throughput == Vec3::ZERO {
            return false;
        }
        path.ray = spawn_ray(surface, sample.direction);
        path.segments += 1;
        true
    }

    /// Whether a path of `segments` segments and `throughput` goes on past Russian
    /// roulette (path integrator), its throughput scaled up if so to keep it unbiased.
    #[inline(always)]
    pub fn survives_roulette(&self, throughput: &mut Vec3, segments: u32, rng: &mut Rng) -> bool {
        let settings = self.scene.settings;
        let plays = settings.integrator == Integrator::Path && settings.russian_roulette;
        if !plays || segments < ROULETTE_AFTER {
            return true;
        }
        let survival = throughput.max_element().min(ROULETTE_MAX_SURVIVAL);
        if rng.next_f32() >= survival {
            return false;
        }
        *throughput /= survival;
        true
    }

    /// The report's estimator: at most `max_depth` segments, light only where a path
    /// happens to end on an emitter or in the background.
    #[inline(always)]
    fn bsdf_head(
        &self,
        path: &mut PathState,
        hit: Option<Hit>,
        track: Option<&mut AovTrack>,
    ) -> Option<Scattering> {
        let scene = self.scene;
        let Some(hit) = hit else {
            let background = scene.background.radiance(path.ray.dir);
            if let Some(track) = track {
                track.escaped(background);
            }
            path.radiance += path.throughput * background;
            return None;
        };
        let (surface, material) = scene.shade(&path.ray, &hit);
        if let Some(track) = track {
            track.hit(&path.ray, &hit, &surface, &material, path.segments == 1);
        }
        path.radiance += path.throughput * material.emitted();
        if path.segments == scene.settings.max_depth {
            return None;
        }
        Some(Scattering {
            surface,
            material,
            direct: None,
        })
    }

    /// Path tracing with next-event estimation and MIS: every non-delta vertex sends one
    /// shadow ray to a point on a light and one towards the background (where it is an
    /// environment map: [`crate::Background::is_sampled`]), and the emitter or background
    /// the BSDF-sampled ray finds next is weighted against those. Paths have at most
    /// `max_depth` segments, shadow rays counted, so both estimators sum the same paths.
    #[inline(always)]
    fn path_head(
        &self,
        path: &mut PathState,
        hit: Option<Hit>,
        rng: &mut Rng,
        track: Option<&mut AovTrack>,
    ) -> Option<Scattering> {
        let scene = self.scene;
        let settings = scene.settings;
        let Some(hit) = hit else {
            if let Some(track) = track {
                track.escaped(scene.background.radiance(path.ray.dir));
            }
            let weight = match path.previous.found() {
                Some(v) if scene.background.is_sampled() => {
                    power_heuristic(v.pdf, scene.background.pdf(path.ray.dir))
                }
                _ => 1.0,
            };
            path.radiance += path.throughput * weight * scene.background.radiance(path.ray.dir);
            return None;
        };
        let (surface, material) = scene.shade(&path.ray, &hit);
        if let Some(track) = track {
            track.hit(&path.ray, &hit, &surface, &material, path.segments == 1);
        }
        let emitted = material.emitted();
        if emitted != Vec3::ZERO {
            let weight = match path.previous.found() {
                Some(v) => {
                    let light_pdf =
                        self.lights
                            .pdf(scene, &hit, v.p, surface.p, surface.geometric_normal);
                    power_heuristic(v.pdf, light_pdf)
                }
                None => 1.0,
            };
            path.radiance += path.throughput * weight * emitted;
        }
        if !material.scatters() || path.segments == settings.max_depth {
            return None;
        }
        let direct = (!material.is_delta() && self.samples_light).then(|| DirectLight {
            tests: self.light_tests(&material, &path.ray, &surface, rng),
            throughput: path.throughput,
        });
        Some(Scattering {
            surface,
            material,
            direct,
        })
    }

    /// Light reaching `surface` directly, towards the viewer of `ray`, as shadow tests:
    /// one sample of the emitters and one of the background where it is sampled, each
    /// MIS-weighted against BSDF sampling.
    fn light_tests(
        &self,
        material: &Material,
        ray: &Ray,
        surface: &Surface,
        rng: &mut Rng,
    ) -> [Option<ShadowTest>; 2] {
        let scene = self.scene;
        let mut tests = [None; 2];
        if let Some(light) = self.lights.sample(scene, surface.p, rng) {
            let to_light = light.point.p - surface.p;
            let wi = to_light.normalize_or_zero();
            let f = material.eval(ray.dir, surface, wi);
            if f != Vec3::ZERO {
                // Aim at the light's point pushed off its surface towards us.
                let lift = 2.0 * light.point.error * light.point.normal;
                let target = if light.point.normal.dot(to_light) < 0.0 {
                    light.point.p + lift
                } else {
                    light.point.p - lift
                };
                let origin = offset_origin(surface, wi);
                let weight = match light.delta {
                    true => 1.0,
                    false => power_heuristic(light.pdf, material.pdf(ray.dir, surface, wi)),
                };
                tests[0] = Some(ShadowTest {
                    ray: Ray::new(origin, target - origin, 0.0, 1.0 - SHADOW_SHORTENING),
                    light: f * light.radiance * (weight / light.pdf),
                });
            }
        }
        if !scene.background.is_sampled() {
            return tests;
        }
        if let Some(sky) = scene.background.sample(rng) {
            let f = material.eval(ray.dir, surface, sky.direction);
            if f != Vec3::ZERO {
                let origin = offset_origin(surface, sky.direction);
                let bsdf_pdf = material.pdf(ray.dir, surface, sky.direction);
                let weight = power_heuristic(sky.pdf, bsdf_pdf);
                tests[1] = Some(ShadowTest {
                    ray: Ray::new(origin, sky.direction, 0.0, f32::INFINITY),
                    light: f * sky.radiance * (weight / sky.pdf),
                });
            }
        }
        tests
    }

    /// The first surface along `ray` that stops it: the closest hit, or, where
    /// surfaces are see-through, the closest one whose coverage stops the ray (the
    /// search goes on past each one that does not).
    pub fn intersect<P: Probe>(&self, ray: &Ray, rng: &mut Rng, work: &mut Work<P>) -> Option<Hit> {
        let mut hit = self
            .accel
            .intersect_counted(ray, ALL_MASKS, &mut work.probe)?;
        if !self.see_through {
            return Some(hit);
        }
        for _ in 0..MAX_SEE_THROUGH_LAYERS {
            if self.scene.stops_ray(&hit, || rng.next_f32()) {
                return Some(hit);
            }
            let beyond = Ray::new(ray.origin, ray.dir, hit.t.next_up(), ray.t_max);
            hit = self
                .accel
                .intersect_counted(&beyond, ALL_MASKS, &mut work.probe)?;
        }
        Some(hit)
    }

    pub fn occluded<P: Probe>(&self, shadow: &Ray, rng: &mut Rng, work: &mut Work<P>) -> bool {
        work.rays += 1;
        work.shadow_rays += 1;
        if self.see_through {
            // Any hit will not do: a see-through surface does not block.
            return self.intersect(shadow, rng, work).is_some();
        }
        work.probe.time_shadow(|| self.accel.occluded(shadow))
    }
}

/// The start of a ray leaving `surface` in `direction`: the hit point pushed off the
/// surface (to the side the ray leaves towards) by the bound on its rounding error, so
/// the ray cannot re-hit the surface it starts on.
#[inline]
fn offset_origin(surface: &Surface, direction: Vec3) -> Vec3 {
    let n = surface.geometric_normal;
    let offset = 2.0 * surface.error.max(f32::MIN_POSITIVE);
    if direction.dot(n) >= 0.0 {
        surface.p + offset * n
    } else {
        surface.p - offset * n
    }
}

#[inline]
pub(super) fn spawn_ray(surface: &Surface, direction: Vec3) -> Ray {
    Ray::new(
        offset_origin(surface, direction),
        direction,
        0.0,
        f32::INFINITY,
    )
}
