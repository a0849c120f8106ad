//! The BSDF samples of a wavefront stage, grouped by material and drawn over SIMD lanes.
//!
//! Each vertex that scatters off a Lambertian, metal or glass surface is queued in its
//! material's group, with the numbers its path drew for it; then each group's samples are
//! drawn [`LANES`] at a time by [`crate::material::lanes`]' functions, in loops that
//! compile to vector code (AVX-512 or AVX2 where the CPU has it). The functions are the
//! ones [`Material::sample`] calls, so each vertex gets the sample it would get alone,
//! bit for bit. Other materials are sampled by the caller, one at a time.

use crate::geometry::Surface;
use crate::material::lanes::{LaneParams, LaneSample, Lobe};
use crate::material::{BsdfDraw, BsdfSample, Facing, Material};
use glam::{Vec2, Vec3};

/// Vertices sampled together: a multiple of the widest vectors' 16 floats.
const LANES: usize = 16;

/// What [`LANES`] vertices' samples are drawn from, one array per coordinate.
#[derive(Clone, Copy)]
struct Inputs {
    /// The arriving rays' directions and the normals facing them.
    dir: [[f32; LANES]; 3],
    shading: [[f32; LANES]; 3],
    geometric: [[f32; LANES]; 3],
    /// [`LaneParams`]' numbers and parameter.
    u: [[f32; LANES]; 2],
    param: [f32; LANES],
}

/// The samples drawn from [`Inputs`].
#[derive(Clone, Copy)]
struct Outputs {
    direction: [[f32; LANES]; 3],
    pdf: [f32; LANES],
    scatters: [bool; LANES],
}

const EMPTY_INPUTS: Inputs = Inputs {
    dir: [[0.0; LANES]; 3],
    shading: [[0.0; LANES]; 3],
    geometric: [[0.0; LANES]; 3],
    u: [[0.0; LANES]; 2],
    param: [0.0; LANES],
};

const EMPTY_OUTPUTS: Outputs = Outputs {
    direction: [[0.0; LANES]; 3],
    pdf: [0.0; LANES],
    scatters: [false; LANES],
};

/// A vertex waiting for its sample: its path, where it scatters and off what.
pub(super) struct Queued {
    pub path: u32,
    pub surface: Surface,
    pub material: Material,
}

/// One material's queued vertices, lane by lane.
#[derive(Default)]
struct Group {
    vertices: Vec<Queued>,
    inputs: Vec<Inputs>,
    outputs: Vec<Outputs>,
}

/// A stage's queued BSDF samples, by material; kept from stage to stage for its buffers.
#[derive(Default)]
pub(super) struct Scatters {
    groups: [Group; 3],
}

impl Scatters {
    pub fn clear(&mut self) {
        for group in &mut self.groups {
            group.vertices.clear();
            group.inputs.clear();
        }
    }

    /// Queues the sample of `material` at `surface` for the ray along `dir` of path
    /// `path`, from the numbers `draw`; hands it back where the material is not sampled
    /// in lanes.
    pub fn push(
        &mut self,
        path: u32,
        dir: Vec3,
        surface: Surface,
        material: Material,
        draw: BsdfDraw,
    ) -> Result<(), (Surface, Material)> {
        let facing = Facing::new(dir, &surface);
        let Some(LaneParams { lobe, param, u }) = material.lane_params(&facing, draw) else {
            return Err((surface, material));
        };
        let group = &mut self.groups[lobe as usize];
        let lane = group.vertices.len() % LANES;
        if lane == 0 {
            group.inputs.push(EMPTY_INPUTS);
        }
        let inputs = group.inputs.last_mut().expect("a lane block was pushed");
        for axis in 0..3 {
            inputs.dir[axis][lane] = dir[axis];
            inputs.shading[axis][lane] = facing.shading[axis];
            inputs.geometric[axis][lane] = facing.geometric[axis];
        }
        inputs.u[0][lane] = u.x;
        inputs.u[1][lane] = u.y;
        inputs.param[lane] = param;
        group.vertices.push(Queued {
            path,
            surface,
            material,
        });
        Ok(())
    }

    /// Draws every queued sample.
    pub fn sample(&mut self) {
        self.sample_with(sample_lanes);
    }

    /// Draws every queued sample with the lane kernel `kernel`.
    fn sample_with(&mut self, kernel: Kernel) {
        for (group, lobe) in self.groups.iter_mut().zip(Lobe::ALL) {
            group.outputs.clear();
            group.outputs.resize(group.inputs.len(), EMPTY_OUTPUTS);
            kernel(lobe, &group.inputs, &mut group.outputs);
        }
    }

    /// Every queued vertex with its sample (`None` where it does not scatter), group by
    /// group, after [`Scatters::sample`].
    pub fn samples(&self) -> impl Iterator<Item = (&Queued, Option<BsdfSample>)> {
        self.groups.iter().flat_map(|group| {
            group.vertices.iter().enumerate().map(|(i, queued)| {
                let out = &group.outputs[i / LANES];
                let lane = i % LANES;
                let drawn = LaneSample {
                    direction: Vec3::new(
                        out.direction[0][lane],
                        out.direction[1][lane],
                        out.direction[2][lane],
                    ),
                    pdf: out.pdf[lane],
                    scatters: out.scatters[lane],
                };
                (queued, queued.material.with_weight(drawn))
            })
        })
    }
}

/// Draws the samples of a lobe from every block of its inputs into its outputs.
type Kernel = fn(Lobe, &[Inputs], &mut [Outputs]);

/// The kernels this CPU can run: plain code, and each SIMD twin it has.
#[cfg(test)]
fn kernels() -> Vec<(&'static str, Kernel)> {
    let mut kernels: Vec<(&'static str, Kernel)> = vec![("scalar", sample_blocks)];
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is available, checked just above.
            kernels.push(("avx2", |l, i, o| unsafe { sample_lanes_avx2(l, i, o) }));
        }
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: AVX-512F is available, checked just above.
            kernels.push(("avx512", |l, i, o| unsafe { sample_lanes_avx512(l, i, o) }));
        }
    }
    kernels
}

/// Draws the samples of `lobe` from every block of `inputs` into `outputs`, in the
/// widest vectors the CPU has.
fn sample_lanes(lobe: Lobe, inputs: &[Inputs], outputs: &mut [Outputs]) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: AVX-512F is available, checked just above.
            return unsafe { sample_lanes_avx512(lobe, inputs, outputs) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is available, checked just above.
            return unsafe { sample_lanes_avx2(lobe, inputs, outputs) };
        }
    }
    sample_blocks(lobe, inputs, outputs);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2")]
unsafe fn sample_lanes_avx512(lobe: Lobe, inputs: &[Inputs], outputs: &mut [Outputs]) {
    sample_blocks(lobe, inputs, outputs);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn sample_lanes_avx2(lobe: Lobe, inputs: &[Inputs], outputs: &mut [Outputs]) {
    sample_blocks(lobe, inputs, outputs);
}

/// One loop over the lanes of each block, which the compiler vectorises: the lobe is a
/// constant in each loop, so its `match` folds away (a lobe function passed as a closure
/// was not always inlined).
#[inline(always)]
fn sample_blocks(lobe: Lobe, inputs: &[Inputs], outputs: &mut [Outputs]) {
    for (x, out) in inputs.iter().zip(outputs) {
        match lobe {
            Lobe::Lambertian => {
                for lane in 0..LANES {
                    out.set(lane, x.sample(Lobe::Lambertian, lane));
                }
            }
            Lobe::Metal => {
                for lane in 0..LANES {
                    out.set(lane, x.sample(Lobe::Metal, lane));
                }
            }
            Lobe::Dielectric => {
                for lane in 0..LANES {
                    out.set(lane, x.sample(Lobe::Dielectric, lane));
                }
            }
        }
    }
}

impl Outputs {
    #[inline(always)]
    fn set(&mut self, lane: usize, s: LaneSample) {
        for axis in 0..3 {
            self.direction[axis][lane] = s.direction[axis];
        }
        self.pdf[lane] = s.pdf;
        self.scatters[lane] = s.scatters;
    }
}

impl Inputs {
    /// The sample of lane `lane`, drawn as a `lobe`.
    #[inline(always)]
    fn sample(&self, lobe: Lobe, lane: usize) -> LaneSample {
        let params = LaneParams {
            lobe,
            param: self.param[lane],
            u: Vec2::new(self.u[0][lane], self.u[1][lane]),
        };
        params.sample(
            Self::vec3(&self.dir, lane),
            Self::vec3(&self.shading, lane),
            Self::vec3(&self.geometric, lane),
        )
    }

    #[inline(always)]
    fn vec3(v: &[[f32; LANES]; 3], lane: usize) -> Vec3 {
        Vec3::new(v[0][lane], v[1][lane], v[2][lane])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Every sample drawn in lanes is the one [`Material::sample_drawn`] draws alone, bit
    /// for bit, with every kernel the CPU runs: for each material, surfaces facing either
    /// way, smooth-shading normals, and groups that do and do not fill their last block.
    #[test]
    fn samples_in_lanes_are_those_drawn_one_at_a_time() {
        for (name, kernel) in kernels() {
            lanes_match_one_at_a_time(name, kernel);
        }
    }

    fn lanes_match_one_at_a_time(name: &str, kernel: Kernel) {
        let materials = [
            Material::Lambertian {
                albedo: Vec3::new(0.2, 0.5, 0.9),
            },
            Material::Metal {
                albedo: Vec3::new(0.9, 0.6, 0.3),
                fuzz: 0.3,
            },
            Material::Metal {
                albedo: Vec3::ONE,
                fuzz: 0.0,
            },
            Material::Metal {
                albedo: Vec3::ONE,
                fuzz: 1.7,
            },
            Material::Dielectric { ior: 1.5 },
            Material::Dielectric { ior: 0.8 },
        ];
        let mut rng = Rng::for_sample(11, 12, 13);
        let mut scatters = Scatters::default();
        let mut expected = Vec::new();
        let mut scattered = [0usize; 2];
        for count in [1, 16, 37, 300] {
            scatters.clear();
            expected.clear();
            for path in 0..count {
                let material = materials[path as usize % materials.len()];
                let geometric = rng.unit_vector();
                let shading = (geometric + 0.3 * rng.unit_vector()).normalize();
                let surface = Surface {
                    p: Vec3::new(1.0, 2.0, 3.0),
                    geometric_normal: geometric,
                    shading_normal: shading,
                    error: 1e-6,
                };
                let dir = rng.unit_vector();
                let draw = BsdfDraw {
                    choice: rng.next_f32(),
                    u: rng.next_2d(),
                };
                let alone = material.sample_drawn(dir, &surface, draw);
                scattered[alone.is_some() as usize] += 1;
                expected.push((path, alone));
                assert!(scatters.push(path, dir, surface, material, draw).is_ok());
            }
            scatters.sample_with(kernel);
            let mut drawn: Vec<_> = scatters.samples().map(|(q, s)| (q.path, s)).collect();
            drawn.sort_by_key(|(path, _)| *path);
            let bits = |s: &Option<BsdfSample>| {
                s.map(|s| {
                    let v = [s.direction, s.weight].map(|v| v.to_array().map(f32::to_bits));
                    (v, s.pdf.to_bits(), s.delta)
                })
            };
            assert_eq!(drawn.len(), expected.len());
            for ((path, made), (_, alone)) in drawn.iter().zip(&expected) {
                let material = materials[*path as usize % materials.len()];
                assert_eq!(bits(made), bits(alone), "{name}, path {path}: {material:?}");
            }
        }
        // Both outcomes were exercised.
        assert!(scattered.iter().all(|&n| n > 20), "{scattered:?}");
    }

    #[test]
    fn other_materials_are_handed_back() {
        let mut scatters = Scatters::default();
        let surface = Surface {
            p: Vec3::ZERO,
            geometric_normal: Vec3::Y,
            shading_normal: Vec3::Y,
            error: 0.0,
        };
        let emitter = Material::Emissive {
            radiance: Vec3::ONE,
        };
        let back = scatters.push(0, -Vec3::Y, surface, emitter, BsdfDraw::default());
        assert_eq!(back.map_err(|(_, m)| m), Err(emitter));
        scatters.sample();
        assert_eq!(scatters.samples().count(), 0);
    }
}
