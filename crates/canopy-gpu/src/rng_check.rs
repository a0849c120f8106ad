//! The GPU's random streams, read back: what the test that CPU and GPU draw the same
//! numbers compares.

use crate::{Gpu, GpuError};
use canopy_render::Sampler;
use wgpu::util::DeviceExt;

/// The first `count` words of the streams of `(seed, pixel, sample)` keys under
/// `sampler`, as the GPU draws them (pixel and sample below 2^32).
pub fn first_words(
    gpu: &Gpu,
    sampler: Sampler,
    keys: &[(u64, u32, u32)],
    count: u32,
) -> Result<Vec<Vec<u32>>, GpuError> {
    if keys.is_empty() || count == 0 {
        return Ok(vec![Vec::new(); keys.len()]);
    }
    let device = &gpu.device;
    let streams: Vec<[u32; 4]> = keys
        .iter()
        .map(|&(seed, pixel, sample)| {
            let seed = canopy_render::rng::fold64(seed);
            [seed, pixel, sample, sampler.sobol_dimensions()]
        })
        .collect();
    let buffer = |label, contents: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage,
        })
    };
    let streams = buffer(
        "streams",
        bytemuck::cast_slice(&streams),
        wgpu::BufferUsages::STORAGE,
    );
    let words = buffer(
        "words",
        &vec![0u8; keys.len() * count as usize * 4],
        wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    );
    let params = buffer(
        "params",
        bytemuck::cast_slice(&[count, 0, 0, 0]),
        wgpu::BufferUsages::UNIFORM,
    );
    let pipeline = gpu.pipeline(
        "first_words",
        &[
            include_str!("shaders/rng.wgsl"),
            include_str!("shaders/rng_test.wgsl"),
        ],
        &[],
    )?;
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("first_words"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[(0, &streams), (1, &words), (2, &params)].map(|(binding, buffer)| {
            wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            }
        }),
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups((keys.len() as u32).div_ceil(64), 1, 1);
    }
    gpu.queue.submit([encoder.finish()]);
    let all: Vec<u32> = gpu.read_back(&words)?;
    Ok(all.chunks(count as usize).map(<[u32]>::to_vec).collect())
}
