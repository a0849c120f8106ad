//! The device: adapter choice, limits, and the errors of GPU work.

use thiserror::Error;

/// What can go wrong on the GPU side; never a panic.
#[derive(Debug, Error)]
pub enum GpuError {
    #[error("no GPU adapter found ({0}); install a Vulkan driver (on Debian: mesa-vulkan-drivers and libvulkan1 for the software one)")]
    NoAdapter(String),
    #[error("the GPU adapter `{adapter}` refused a device: {reason}")]
    Device { adapter: String, reason: String },
    #[error("{what} needs {bytes} bytes in one buffer, more than this adapter's limit of {limit} bytes ({limit_name})")]
    TooLarge {
        what: &'static str,
        bytes: u64,
        limit: u64,
        limit_name: &'static str,
    },
    #[error("the BVH is {depth} levels deep; the GPU traversal stack holds {max}")]
    TooDeep { depth: usize, max: usize },
    #[error("reading results back from the GPU failed: {0}")]
    Readback(String),
}

/// A GPU device and its queue.
pub struct Gpu {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    limits: wgpu::Limits,
}

impl Gpu {
    /// The first adapter wgpu finds (a high-performance one preferred).
    pub fn new() -> Result<Self, GpuError> {
        pollster::block_on(Self::open())
    }

    async fn open() -> Result<Self, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                ..Default::default()
            })
            .await
            .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let limits = adapter.limits();
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("canopy"),
                required_limits: limits.clone(),
                ..Default::default()
            })
            .await
            .map_err(|e| GpuError::Device {
                adapter: info.name.clone(),
                reason: e.to_string(),
            })?;
        Ok(Self {
            device,
            queue,
            info,
            limits,
        })
    }

    /// The adapter's name, backend and kind, in one line.
    pub fn describe(&self) -> String {
        describe(&self.info)
    }

    pub(crate) fn limits(&self) -> &wgpu::Limits {
        &self.limits
    }

    /// Refuses a buffer larger than one storage binding may be.
    pub(crate) fn check_size(&self, what: &'static str, bytes: u64) -> Result<(), GpuError> {
        let checks = [
            (
                self.limits.max_storage_buffer_binding_size,
                "max_storage_buffer_binding_size",
            ),
            (self.limits.max_buffer_size, "max_buffer_size"),
        ];
        for (limit, limit_name) in checks {
            if bytes > limit {
                return Err(GpuError::TooLarge {
                    what,
                    bytes,
                    limit,
                    limit_name,
                });
            }
        }
        Ok(())
    }
}

fn describe(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
}

/// Every adapter wgpu finds, described in one line each (`canopy devices`).
pub fn adapters() -> Vec<String> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()))
        .iter()
        .map(|a| describe(&a.get_info()))
        .collect()
}
