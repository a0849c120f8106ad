//! The ray-tracing kernel: closest hits of a batch of rays.

use crate::chunked::ChunkedBuffer;
use crate::scene::{GpuRay, GpuScene, NODE_BINDINGS, PRIM_BINDINGS};
use crate::{Gpu, GpuError};
use canopy_bvh::{Hit, Ray};
use wgpu::util::DeviceExt;

/// Rays per dispatch: 16384 workgroups of 64, well inside every adapter's limits.
const RAYS_PER_DISPATCH: usize = 1 << 20;

/// One result as the shader writes it: `t` (INF-like when missed), `prim`, `u`, `v`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct GpuHit {
    t: f32,
    prim: u32,
    u: f32,
    v: f32,
}

/// A scene uploaded to the GPU with the pipeline that traces it.
pub struct Tracer<'g> {
    gpu: &'g Gpu,
    pipeline: wgpu::ComputePipeline,
    nodes: ChunkedBuffer,
    prim_indices: wgpu::Buffer,
    primitives: ChunkedBuffer,
}

impl<'g> Tracer<'g> {
    pub fn new(gpu: &'g Gpu, scene: &GpuScene) -> Result<Self, GpuError> {
        let nodes = ChunkedBuffer::new(gpu, "NODE", "BVH nodes", &scene.upload_nodes())?;
        let prim_indices = gpu.storage(
            "primitive indices",
            bytemuck::cast_slice(scene.bvh.prim_indices()),
            wgpu::BufferUsages::empty(),
        )?;
        let primitives = ChunkedBuffer::new(gpu, "PRIM", "primitives", &scene.primitives)?;
        let pipeline = gpu.pipeline(
            "trace",
            &[
                include_str!("shaders/common.wgsl"),
                include_str!("shaders/trace.wgsl"),
            ],
            &[nodes.constants(), primitives.constants()].concat(),
        )?;
        Ok(Self {
            gpu,
            pipeline,
            nodes,
            prim_indices,
            primitives,
        })
    }

    /// The closest hit of each ray (ties to the lower primitive index), in dispatches
    /// of at most a million rays, fewer where the adapter's bindings cannot hold their
    /// rays.
    pub fn closest(&self, rays: &[Ray]) -> Result<Vec<Option<Hit>>, GpuError> {
        let binding = self.gpu.max_binding_bytes() as usize;
        let per_dispatch = RAYS_PER_DISPATCH
            .min(self.gpu.limits().max_compute_workgroups_per_dimension as usize * 64)
            .min(binding / std::mem::size_of::<GpuRay>())
            .max(1);
        let mut hits = Vec::with_capacity(rays.len());
        for chunk in rays.chunks(per_dispatch) {
            hits.extend(self.closest_chunk(chunk)?);
        }
        Ok(hits)
    }

    fn closest_chunk(&self, rays: &[Ray]) -> Result<Vec<Option<Hit>>, GpuError> {
        let device = &self.gpu.device;
        let gpu_rays: Vec<GpuRay> = rays.iter().map(GpuRay::from).collect();
        let ray_bytes: &[u8] = bytemuck::cast_slice(&gpu_rays);
        let hit_bytes = (rays.len() * std::mem::size_of::<GpuHit>()) as u64;
        self.gpu.check_size("rays", ray_bytes.len() as u64)?;
        self.gpu.check_size("hits", hit_bytes)?;
        if rays.is_empty() {
            return Ok(Vec::new());
        }
        let ray_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("rays"),
            contents: ray_bytes,
            usage: wgpu::BufferUsages::STORAGE,
        });
        let hit_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("hits"),
            size: hit_bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("params"),
            contents: bytemuck::cast_slice(&[rays.len() as u32, 0, 0, 0]),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let layout = self.pipeline.get_bind_group_layout(0);
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("trace"),
            layout: &layout,
            entries: &[
                (1, &self.prim_indices),
                (3, &ray_buffer),
                (4, &hit_buffer),
                (5, &params),
            ]
            .into_iter()
            .chain(self.nodes.entries(NODE_BINDINGS))
            .chain(self.primitives.entries(PRIM_BINDINGS))
            .map(|(binding, buffer)| wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            })
            .collect::<Vec<_>>(),
        });
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(rays.len().div_ceil(64) as u32, 1, 1);
        }
        self.gpu.queue.submit([encoder.finish()]);
        let hits: Vec<GpuHit> = self.gpu.read_back(&hit_buffer)?;
        Ok(hits
            .iter()
            .map(|h| {
                (h.prim != canopy_bvh::NO_PRIM).then_some(Hit {
                    t: h.t,
                    inst: 0,
                    prim: h.prim,
                    u: h.u,
                    v: h.v,
                })
            })
            .collect())
    }
}
