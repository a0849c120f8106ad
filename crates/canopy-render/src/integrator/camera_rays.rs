//! The camera rays of a wavefront pass, made many at a time: each sample's random stream
//! is hashed and its ray computed lane by lane (loops over [`LANES`] samples, compiled
//! for AVX2 where the CPU has it), with the operations [`Camera::ray`] and
//! [`Rng::for_sample_with`] perform (its first Sobol pair or its first independent
//! words), in the same order, so every ray and every generator is
//! the one a sample made alone would have, bit for bit. Cameras with a lens (whose disk
//! sample needs `sin_cos`) make theirs one at a time.

use crate::camera::{Camera, CameraBasis};
use crate::rng::{first_sobol_pairs, fold64, pcg4d_lanes, unit_f32, Rng, Sampler};
use canopy_bvh::Ray;
use glam::Vec3;
use std::ops::Range;

/// Samples whose rays are made together.
const LANES: usize = 16;

/// What keys the samples' random streams: the seed and how numbers are drawn.
#[derive(Clone, Copy, Debug)]
pub(super) struct Streams {
    pub sampler: Sampler,
    pub seed: u64,
}

/// Where a pass's samples are: pixels `first_x..first_x + pixels` of row `y` of an image
/// `width` x `height`, samples `samples` of each, drawing from `streams`.
pub(super) struct PassSamples {
    pub width: u32,
    pub height: u32,
    pub streams: Streams,
    pub first_x: u32,
    pub y: u32,
    pub pixels: usize,
    pub samples: Range<u32>,
}

/// The camera ray of sample `sample` of pixel (`x`, `y`) of an image `width` x `height`
/// drawing from `streams`, one sample alone, and its generator after the ray's draws:
/// what every schedule traces.
pub(super) fn camera_sample(
    camera: &Camera,
    (width, height): (u32, u32),
    streams: Streams,
    (x, y): (u32, u32),
    sample: u32,
) -> (Ray, Rng) {
    let index = y as u64 * width as u64 + x as u64;
    let mut rng = Rng::for_sample_with(streams.sampler, streams.seed, index, sample as u64);
    let jitter = rng.next_2d();
    let s = (x as f32 + jitter.x) / width as f32;
    let t = (y as f32 + jitter.y) / height as f32;
    (camera.ray(s, t, &mut rng), rng)
}

/// Calls `emit` with the camera ray of every sample of `pass`, pixel by pixel and each
/// pixel's samples in order, and the sample's generator after the ray's draws.
pub(super) fn camera_rays(camera: &Camera, pass: &PassSamples, mut emit: impl FnMut(Ray, Rng)) {
    let basis = camera.basis();
    if basis.lens_radius > 0.0 || basis.orthographic {
        let size = (pass.width, pass.height);
        for i in 0..pass.pixels {
            let pixel = (pass.first_x + i as u32, pass.y);
            for sample in pass.samples.clone() {
                let (ray, rng) = camera_sample(camera, size, pass.streams, pixel, sample);
                emit(ray, rng);
            }
        }
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 is available, checked just above.
        unsafe { pinhole_rays_avx2(&basis, pass, &mut emit) };
        return;
    }
    pinhole_rays(&basis, pass, &mut emit);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn pinhole_rays_avx2(basis: &CameraBasis, pass: &PassSamples, emit: impl FnMut(Ray, Rng)) {
    pinhole_rays(basis, pass, emit);
}

/// [`camera_rays`] for a pinhole camera, [`LANES`] samples at a time.
#[inline(always)]
fn pinhole_rays(basis: &CameraBasis, pass: &PassSamples, mut emit: impl FnMut(Ray, Rng)) {
    let per_pixel = pass.samples.len();
    let total = pass.pixels * per_pixel;
    let seed_key = fold64(pass.streams.seed);
    let sobol = pass.streams.sampler == Sampler::Sobol;
    let (width, height) = (pass.width as f32, pass.height as f32);
    let row = pass.y as f32;
    // Copied once here: read through `basis` in the loop below, the origin was copied
    // field by field onto the stack for every ray and read back 16 bytes at once, a
    // store forward that fails (a third of this function's samples waited on it).
    let origin = basis.origin;
    let [ox, oy, oz] = origin.to_array();
    let [ux, uy, uz] = basis.upper_left.to_array();
    let [hx, hy, hz] = basis.horizontal.to_array();
    let [vx, vy, vz] = basis.vertical.to_array();
    // The (pixel, sample) after `at`, pixel-major.
    let after = |(pixel, sample): (usize, usize)| match sample + 1 == per_pixel {
        true => (pixel + 1, 0),
        false => (pixel, sample + 1),
    };
    // Where the next group of lanes starts.
    let mut next = (0, 0);
    for start in (0..total).step_by(LANES) {
        let count = LANES.min(total - start);
        // Each lane's key (lanes past the end repeat the last sample's) and pixel column.
        let mut words = [[0u32; LANES]; 4];
        let mut column = [0f32; LANES];
        let mut at = next;
        for lane in 0..LANES {
            let (pixel, sample) = at;
            let x = pass.first_x + pixel as u32;
            let index = pass.y as u64 * pass.width as u64 + x as u64;
            words[0][lane] = fold64(index);
            words[1][lane] = fold64((pass.samples.start as usize + sample) as u64);
            words[2][lane] = seed_key;
            column[lane] = x as f32;
            if lane + 1 < count {
                at = after(at);
            }
        }
        next = after(at);
        let keys = [words[0], words[1], words[2]];
        // The pixel jitter: the first Sobol pair, or the first two independent words.
        let jitter = match sobol {
            true => first_sobol_pairs(&keys),
            false => {
                pcg4d_lanes(&mut words);
                [words[0], words[1]]
            }
        };
        let mut dir = [[0f32; LANES]; 3];
        let mut inv = [[0f32; LANES]; 3];
        for lane in 0..LANES {
            let s = (column[lane] + unit_f32(jitter[0][lane])) / width;
            let t = (row + unit_f32(jitter[1][lane])) / height;
            // target - origin, then normalised: glam's `Vec3` arithmetic, componentwise.
            let dx = ((ux + s * hx) - t * vx) - ox;
            let dy = ((uy + s * hy) - t * vy) - oy;
            let dz = ((uz + s * hz) - t * vz) - oz;
            let recip_length = 1.0 / (dx * dx + dy * dy + dz * dz).sqrt();
            let d = [dx * recip_length, dy * recip_length, dz * recip_length];
            for axis in 0..3 {
                dir[axis][lane] = d[axis];
                inv[axis][lane] = 1.0 / d[axis];
            }
        }
        for lane in 0..count {
            let ray = Ray {
                origin,
                dir: Vec3::new(dir[0][lane], dir[1][lane], dir[2][lane]),
                inv_dir: Vec3::new(inv[0][lane], inv[1][lane], inv[2][lane]),
                t_min: 0.0,
                t_max: f32::MAX,
            };
            let key = [keys[0][lane], keys[1][lane], keys[2][lane]];
            let rng = match sobol {
                true => Rng::after_first_sobol_pair(key),
                false => Rng::after_first_words(key, [0, 1, 2, 3].map(|w| words[w][lane]), 2),
            };
            emit(ray, rng);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::CameraSpec;
    use crate::rng::SOBOL_DIMENSIONS;

    /// Every ray and generator is the one a sample made alone has, bit for bit, for pixel
    /// runs and sample ranges that do and do not fill the lanes, with either sampler (the
    /// generators are compared past their Sobol dimensions).
    #[test]
    fn rays_in_lanes_are_those_made_one_at_a_time() {
        let spec = CameraSpec {
            look_from: Vec3::new(13.0, 2.0, 3.0),
            vfov: 30.0,
            ..CameraSpec::default()
        };
        let mut lens = spec;
        lens.aperture = 0.2;
        let cameras = [spec, lens].into_iter();
        for (spec, sampler) in cameras.flat_map(|c| Sampler::ALL.map(|s| (c, s))) {
            let streams = Streams {
                sampler,
                seed: 0x1234_5678_9abc,
            };
            let camera = Camera::new(&spec, 37, 23);
            for (pixels, samples) in [(1, 0..1), (5, 3..6), (16, 0..1), (7, 2..18), (37, 9..10)] {
                let pass = PassSamples {
                    width: 37,
                    height: 23,
                    streams,
                    first_x: 37 - pixels as u32,
                    y: 11,
                    pixels,
                    samples: samples.clone(),
                };
                let mut made = Vec::new();
                camera_rays(&camera, &pass, |ray, rng| made.push((ray, rng)));
                assert_eq!(made.len(), pixels * samples.len());
                let mut made = made.into_iter();
                for i in 0..pixels {
                    let x = pass.first_x + i as u32;
                    for sample in samples.clone() {
                        let (ray, mut rng) =
                            camera_sample(&camera, (37, 23), streams, (x, pass.y), sample);
                        let (made_ray, mut made_rng) = made.next().unwrap();
                        let bits = |r: &Ray| {
                            [r.origin, r.dir, r.inv_dir]
                                .map(|v| v.to_array().map(f32::to_bits))
                                .concat()
                        };
                        assert_eq!(bits(&made_ray), bits(&ray), "pixel {x}, sample {sample}");
                        assert_eq!((made_ray.t_min, made_ray.t_max), (ray.t_min, ray.t_max));
                        for _ in 0..SOBOL_DIMENSIONS + 9 {
                            assert_eq!(made_rng.next_u32(), rng.next_u32(), "pixel {x}");
                        }
                    }
                }
            }
        }
    }
}
