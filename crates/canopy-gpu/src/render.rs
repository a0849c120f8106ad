//! The path tracers on the GPU — canopy's `path` integrator (light sampling with MIS,
//! Russian roulette) and the report's `bsdf` — one invocation per pixel, samples added
//! to a CPU [`Accumulator`] dispatch by dispatch.

use crate::chunked::ChunkedBuffer;
use crate::instances::Flat;
use crate::scene::{NODE_BINDINGS, PRIM_BINDINGS};
use crate::textures::GpuTextures;
use crate::{Gpu, GpuError};
use bytemuck::{Pod, Zeroable};
use canopy_bvh::Bvh2;
use canopy_render::camera::{Camera, CameraSpec};
use canopy_render::material::Material;
use canopy_render::{Accel, Accumulator, Background, Integrator, RenderSettings, Scene};
use glam::Vec3;
use std::time::{Duration, Instant};

/// A material for the GPU: 48 bytes; WGSL `struct { kind: vec4<u32>, value: vec4<f32>,
/// emission: vec4<f32> }`.
/// `kind.x`: 0 Lambertian (`value.xyz` albedo), 1 metal (albedo, `value.w` fuzz),
/// 2 dielectric (`value.w` index of refraction), 3 emissive (`value.xyz` radiance), 4 glTF
/// metallic-roughness (`value.xyz` base colour, `value.w` roughness, `kind.y` the bits of
/// the metallic factor). `emission.xyz`: the radiance it emits (emissive and
/// metallic-roughness materials).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct GpuMaterial {
    pub kind: [u32; 4],
    pub value: [f32; 4],
    pub emission: [f32; 4],
}

impl GpuMaterial {
    pub fn new(m: &Material) -> Self {
        let (kind, v, w, extra) = match *m {
            Material::Lambertian { albedo } => (0, albedo, 0.0, 0),
            Material::Metal { albedo, fuzz } => (1, albedo, fuzz, 0),
            Material::Dielectric { ior } => (2, Vec3::ZERO, ior, 0),
            Material::Emissive { radiance } => (3, radiance, 0.0, 0),
            Material::Pbr(p) => (4, p.base_color, p.roughness, p.metallic.to_bits()),
        };
        Self {
            kind: [kind, extra, 0, 0],
            value: [v.x, v.y, v.z, w],
            emission: vec4(m.emitted(), 0.0),
        }
    }
}

/// The per-dispatch constants: 272 bytes; WGSL `Frame` in `render.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
struct Frame {
    /// xyz: camera origin, w: lens radius.
    origin: [f32; 4],
    upper_left: [f32; 4],
    horizontal: [f32; 4],
    vertical: [f32; 4],
    u: [f32; 4],
    v: [f32; 4],
    /// width, height, seed key, max depth.
    size: [u32; 4],
    /// first sample, samples, background kind (0 sky, 1 constant, 2 map), first row of
    /// the band being rendered.
    samples: [u32; 4],
    background: [f32; 4],
    /// lights, background is black (1), integrator (0 bsdf, 1 path: informative; the
    /// pipeline's `PATH_ESTIMATOR` decides), roulette (1).
    options: [u32; 4],
    /// An environment map's rotation to the world, by columns.
    env_x: [f32; 4],
    env_y: [f32; 4],
    env_z: [f32; 4],
    /// Its width and height.
    env_size: [u32; 4],
    /// The region of the image rendered: x, y, width, height.
    region: [u32; 4],
    /// Two-level traversal (1) or one tree from node 0 (0), the top tree's root, whether
    /// some surfaces let rays through (1), whether some material has textures (1).
    top: [u32; 4],
    /// xyz: the viewing direction; w: 1 for an orthographic camera (rays start on the
    /// view's rectangle and travel along it).
    forward: [f32; 4],
    /// x: the Sobol dimensions of each sample's stream (0: independent numbers only).
    sampling: [u32; 4],
}

/// An environment map as the GPU reads it: pixels, and per pixel the end of its slice of
/// its row's CDF and its cell density, and per row the end of its slice of the marginal
/// CDF (CDFs normalised to 1; the CPU's are f64 sums).
#[derive(Default)]
struct EnvironmentTables {
    size: [u32; 2],
    to_world: glam::Mat3,
    pixels: Vec<[f32; 4]>,
    cells: Vec<[f32; 2]>,
    rows: Vec<f32>,
}

fn environment_tables(map: &canopy_render::EnvironmentMap) -> EnvironmentTables {
    let (width, height) = map.size();
    let pixels = map.pixels().iter().map(|&p| vec4(p, 0.0)).collect();
    let (mut cells, mut rows) = (vec![[0.0; 2]; width * height], vec![0.0; height]);
    if let Some(d) = map.distribution() {
        let marginal = d.marginal();
        for (row, end) in rows.iter_mut().enumerate() {
            *end = (marginal.cdf()[row + 1] / marginal.total()) as f32;
            let Some(cdf) = d.row(row) else { continue };
            for column in 0..width {
                cells[row * width + column] = [
                    (cdf.cdf()[column + 1] / cdf.total()) as f32,
                    d.pdf_cell(column, row),
                ];
            }
        }
    }
    EnvironmentTables {
        size: [width as u32, height as u32],
        to_world: map.to_world(),
        pixels,
        cells,
        rows,
    }
}

/// `fixed` (what an upload fixed) seen through `camera` with `settings`' image size,
/// seed, depth, estimator flag, roulette and sampler.
fn viewed(fixed: &Frame, camera: &CameraSpec, settings: &RenderSettings) -> Frame {
    let (width, height) = (settings.width, settings.height);
    let camera = Camera::new(camera, width, height).basis();
    let [lights, background_unsampled, ..] = fixed.options;
    Frame {
        origin: vec4(camera.origin, camera.lens_radius),
        upper_left: vec4(camera.upper_left, 0.0),
        horizontal: vec4(camera.horizontal, 0.0),
        vertical: vec4(camera.vertical, 0.0),
        u: vec4(camera.u, 0.0),
        v: vec4(camera.v, 0.0),
        size: [
            width,
            height,
            canopy_render::rng::fold64(settings.seed),
            settings.max_depth,
        ],
        options: [
            lights,
            background_unsampled,
            (settings.integrator == Integrator::Path) as u32,
            settings.russian_roulette as u32,
        ],
        region: [0, 0, width, height],
        forward: vec4(camera.forward, camera.orthographic as u32 as f32),
        sampling: [settings.sampler.sobol_dimensions(), 0, 0, 0],
        ..*fixed
    }
}

fn vec4(v: Vec3, w: f32) -> [f32; 4] {
    [v.x, v.y, v.z, w]
}

/// What a dispatch did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DispatchStats {
    /// Rays traced, shadow rays included.
    pub rays: u64,
    pub shadow_rays: u64,
    pub invalid_samples: u64,
    pub elapsed: Duration,
}

/// A scene uploaded for rendering, with the pipeline that renders it.
pub struct Renderer<'g> {
    gpu: &'g Gpu,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    /// The uploaded scene's frame: its camera and settings, and what the upload fixed.
    frame: Frame,
    /// The estimator compiled into the pipeline.
    integrator: Integrator,
    frame_buffer: wgpu::Buffer,
    accum: wgpu::Buffer,
    ray_count: wgpu::Buffer,
    /// Pixels whose sums one dispatch holds (the whole uploaded image unless its sums
    /// exceed a binding).
    band_pixels: u64,
}

impl<'g> Renderer<'g> {
    /// Uploads `scene`, which has no mesh instances, with the tree `bvh` built over its
    /// primitives.
    pub fn new(gpu: &'g Gpu, scene: &Scene, bvh: &Bvh2) -> Result<Self, GpuError> {
        if !scene.instances.is_empty() {
            return Err(GpuError::Unsupported(
                "mesh instances with one tree (use `Renderer::for_accel`)",
            ));
        }
        Self::upload(gpu, scene, Flat::single(scene, bvh)?)
    }

    /// Uploads `scene` with the structures of `accel` (built over it with width 2):
    /// mesh instances are traced in two levels, the top tree over the instances, then
    /// the instance's mesh in its own space, as on the CPU.
    pub fn for_accel(gpu: &'g Gpu, scene: &Scene, accel: &Accel) -> Result<Self, GpuError> {
        let flat = match (scene.instances.is_empty(), accel.tree()) {
            (true, Some(canopy_bvh::Tree::Binary(bvh))) => Flat::single(scene, bvh)?,
            (true, _) => {
                return Err(GpuError::Unsupported(
                    "a structure that is not a binary tree (build with width 2)",
                ))
            }
            (false, _) => Flat::two_level(scene, accel)?,
        };
        Self::upload(gpu, scene, flat)
    }

    fn upload(gpu: &'g Gpu, scene: &Scene, flat: Flat) -> Result<Self, GpuError> {
        let (background_kind, background, env) = match &scene.background {
            Background::Sky => (0, Vec3::ZERO, EnvironmentTables::default()),
            Background::Constant(c) => (1, *c, EnvironmentTables::default()),
            Background::Environment(map) => (2, Vec3::ZERO, environment_tables(map)),
        };
        let device = &gpu.device;
        let (width, height) = (scene.settings.width, scene.settings.height);
        let storage = |label, bytes: &[u8], extra| gpu.storage(label, bytes, extra);
        let none = wgpu::BufferUsages::empty();
        let nodes = ChunkedBuffer::new(gpu, "NODE", "BVH nodes", &flat.nodes)?;
        // A binding cannot be empty.
        let prim_indices = match flat.prim_indices.is_empty() {
            true => vec![0],
            false => flat.prim_indices,
        };
        let indices = storage(
            "primitive indices",
            bytemuck::cast_slice(&prim_indices),
            none,
        )?;
        let instances = storage("instances", bytemuck::cast_slice(&flat.instances), none)?;
        let primitives = ChunkedBuffer::new(gpu, "PRIM", "primitives", &flat.primitives)?;
        let materials: Vec<GpuMaterial> = scene.materials.iter().map(GpuMaterial::new).collect();
        let materials = storage("materials", bytemuck::cast_slice(&materials), none)?;
        let normals = ChunkedBuffer::new(gpu, "NORMAL", "vertex normals", &flat.normals)?;
        let (light_table, light_of_prim) = (flat.lights, flat.light_of_prim);
        let lights = storage("lights", bytemuck::cast_slice(&light_table), none)?;
        let light_of_prim = storage(
            "light of each primitive",
            bytemuck::cast_slice(&light_of_prim),
            none,
        )?;
        let punctual = storage(
            "punctual lights",
            bytemuck::cast_slice(&flat.punctual),
            none,
        )?;
        let textures = GpuTextures::new(scene);
        let material_maps = storage(
            "material textures",
            bytemuck::cast_slice(&textures.maps),
            none,
        )?;
        let images = storage("images", bytemuck::cast_slice(&textures.images), none)?;
        let texels = storage("texels", bytemuck::cast_slice(&textures.texels), none)?;
        let surface = storage(
            "texture coordinates and tangents",
            bytemuck::cast_slice(&flat.surface),
            none,
        )?;
        let env_pixels = storage("environment map", bytemuck::cast_slice(&env.pixels), none)?;
        let env_cells = storage(
            "environment map distribution",
            bytemuck::cast_slice(&env.cells),
            none,
        )?;
        let env_rows = storage(
            "environment map rows",
            bytemuck::cast_slice(&env.rows),
            none,
        )?;
        // The image is rendered in bands of rows, as many as one binding's sums hold.
        let row_bytes = width as u64 * 16;
        gpu.check_size("one row of the image's sums", row_bytes)?;
        let band_rows = (gpu.max_binding_bytes() / row_bytes).min(height as u64);
        let accum_bytes = band_rows * row_bytes;
        let accum = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("sums"),
            size: accum_bytes,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let ray_count = storage(
            "ray count",
            &[0u8; 16],
            wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        )?;
        // What the upload fixes; the view's part (camera, size, seed, ...) is set below.
        let fixed = Frame {
            samples: [0, 0, background_kind, 0],
            background: vec4(background, 0.0),
            options: [
                light_table.len() as u32,
                // Light sampling of the background: environment maps only, as on the CPU.
                !scene.background.is_sampled() as u32,
                0,
                0,
            ],
            env_x: vec4(env.to_world.x_axis, 0.0),
            env_y: vec4(env.to_world.y_axis, 0.0),
            env_z: vec4(env.to_world.z_axis, 0.0),
            env_size: [env.size[0].max(1), env.size[1].max(1), 0, 0],
            top: [
                flat.top.is_some() as u32,
                flat.top.unwrap_or(0),
                scene.has_see_through() as u32,
                scene.is_textured() as u32,
            ],
            ..Frame::zeroed()
        };
        let frame = viewed(&fixed, &scene.camera, &scene.settings);
        let frame_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame"),
            size: std::mem::size_of::<Frame>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let pipeline = gpu.pipeline(
            "render",
            &[
                include_str!("shaders/rng.wgsl"),
                include_str!("shaders/common.wgsl"),
                include_str!("shaders/render.wgsl"),
                include_str!("shaders/path.wgsl"),
                include_str!("shaders/pbr.wgsl"),
                include_str!("shaders/environment.wgsl"),
                include_str!("shaders/instances.wgsl"),
                include_str!("shaders/textures.wgsl"),
            ],
            &[
                &nodes.constants()[..],
                &primitives.constants(),
                &normals.constants(),
                &[(
                    "PATH_ESTIMATOR".to_string(),
                    (scene.settings.integrator == Integrator::Path) as u32 as f64,
                )],
            ]
            .concat(),
        )?;
        let layout = pipeline.get_bind_group_layout(0);
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("render"),
            layout: &layout,
            entries: &[
                (1, &indices),
                (3, &materials),
                (4, &frame_buffer),
                (5, &accum),
                (7, &ray_count),
                (8, &lights),
                (9, &light_of_prim),
                (10, &env_pixels),
                (11, &env_cells),
                (12, &env_rows),
                (22, &instances),
                (23, &punctual),
                (24, &material_maps),
                (25, &images),
                (26, &texels),
                (27, &surface),
            ]
            .into_iter()
            .chain(nodes.entries(NODE_BINDINGS))
            .chain(primitives.entries(PRIM_BINDINGS))
            .chain(normals.entries([6, 19, 20, 21]))
            .map(|(binding, buffer)| wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            })
            .collect::<Vec<_>>(),
        });
        Ok(Self {
            gpu,
            pipeline,
            bind_group,
            frame,
            integrator: scene.settings.integrator,
            frame_buffer,
            accum,
            ray_count,
            band_pixels: band_rows * width as u64,
        })
    }

    /// The GPU it renders on.
    pub fn gpu(&self) -> &'g Gpu {
        self.gpu
    }

    /// The estimator this upload renders with (compiled into its pipeline).
    pub fn integrator(&self) -> Integrator {
        self.integrator
    }

    /// Renders with seed `seed` from now on, as a scene with that seed would (the scene
    /// stays uploaded and its pipeline built).
    pub fn set_seed(&mut self, seed: u64) {
        self.frame.size[2] = canopy_render::rng::fold64(seed);
    }

    /// Renders `count` more samples of every pixel of the accumulator's region (samples
    /// `accumulator.samples..` of each pixel's streams, as on the CPU) and adds them to
    /// `accumulator`: one dispatch, or one per band of rows for a region whose sums
    /// exceed a storage binding. The region must lie within the scene's image.
    pub fn render_samples(
        &self,
        accumulator: &mut Accumulator,
        count: u32,
    ) -> Result<DispatchStats, GpuError> {
        self.dispatch(&self.frame, accumulator, count)
    }

    /// [`render_samples`](Self::render_samples) of the uploaded scene seen through
    /// `camera`, with the image size, seed, depth, roulette and sampler of `settings`:
    /// what a viewer renders as its camera moves, without uploading the scene again.
    /// Refused for another integrator than the upload's (it is compiled into the
    /// pipeline: upload again) and for an image wider than the uploaded one's sums
    /// hold a row of.
    pub fn render_view_samples(
        &self,
        camera: &CameraSpec,
        settings: &RenderSettings,
        accumulator: &mut Accumulator,
        count: u32,
    ) -> Result<DispatchStats, GpuError> {
        if settings.integrator != self.integrator {
            return Err(GpuError::View(format!(
                "with the `{}` integrator: it was uploaded for `{}`",
                settings.integrator.name(),
                self.integrator.name()
            )));
        }
        if settings.width as u64 > self.band_pixels {
            return Err(GpuError::View(format!(
                "{} pixels wide: its sums hold rows of at most {}",
                settings.width, self.band_pixels
            )));
        }
        self.dispatch(&viewed(&self.frame, camera, settings), accumulator, count)
    }

    /// Adds `count` samples of the image `frame` describes to `accumulator`, band by
    /// band.
    fn dispatch(
        &self,
        view: &Frame,
        accumulator: &mut Accumulator,
        count: u32,
    ) -> Result<DispatchStats, GpuError> {
        let region = accumulator.region;
        if let Err(e) = region.check_within(view.size[0], view.size[1]) {
            panic!("the accumulator does not fit the scene's image: {e}");
        }
        let start = Instant::now();
        let gpu = self.gpu;
        let width = region.width as usize;
        let band_rows = (self.band_pixels / region.width as u64).min(region.height as u64) as u32;
        let mut invalid = 0u64;
        for first_row in (0..region.height).step_by(band_rows as usize) {
            let rows = band_rows.min(region.height - first_row);
            let frame = Frame {
                samples: [accumulator.samples, count, view.samples[2], first_row],
                region: [region.x, region.y, region.width, region.height],
                ..*view
            };
            // Each band is its own submission: the frame it reads is written before it.
            gpu.queue
                .write_buffer(&self.frame_buffer, 0, bytemuck::bytes_of(&frame));
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            encoder.clear_buffer(&self.accum, 0, None);
            if first_row == 0 {
                encoder.clear_buffer(&self.ray_count, 0, None);
            }
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &self.bind_group, &[]);
                pass.dispatch_workgroups(region.width.div_ceil(8), rows.div_ceil(8), 1);
            }
            gpu.queue.submit([encoder.finish()]);
            let sums: Vec<[f32; 4]> = gpu.read_back(&self.accum)?;
            let band = first_row as usize * width..(first_row + rows) as usize * width;
            for (total, s) in accumulator.sums[band].iter_mut().zip(&sums) {
                *total += Vec3::new(s[0], s[1], s[2]);
                invalid += s[3] as u64;
            }
        }
        let rays: Vec<u32> = gpu.read_back(&self.ray_count)?;
        accumulator.samples += count;
        accumulator.rays += rays[0] as u64;
        accumulator.invalid_samples += invalid;
        Ok(DispatchStats {
            rays: rays[0] as u64,
            shadow_rays: rays[1] as u64,
            invalid_samples: invalid,
            elapsed: start.elapsed(),
        })
    }
}
