//! The device: adapter choice, limits, and the errors of GPU work.

use std::sync::{Arc, Mutex};
use thiserror::Error;

/// What can go wrong on the GPU side; never a panic.
#[derive(Debug, Error)]
pub enum GpuError {
    #[error("no GPU adapter found ({0}); install a Vulkan driver (on Debian: mesa-vulkan-drivers and libvulkan1 for the software one)")]
    NoAdapter(String),
    #[error("the GPU adapter `{adapter}` refused a device: {reason}")]
    Device { adapter: String, reason: String },
    #[error("the GPU reported an error: {0}")]
    Reported(String),
    #[error("{what} needs {bytes} bytes in one buffer, more than this adapter's limit of {limit} bytes ({limit_name})")]
    TooLarge {
        what: &'static str,
        bytes: u64,
        limit: u64,
        limit_name: &'static str,
    },
    #[error("{what} needs {bytes} bytes, more than {chunks} storage bindings hold on this adapter ({binding} bytes each, its max_storage_buffer_binding_size)")]
    TooLargeToSplit {
        what: &'static str,
        bytes: u64,
        chunks: usize,
        binding: u64,
    },
    #[error("the BVH is {depth} levels deep; the GPU traversal stack holds {max}")]
    TooDeep { depth: usize, max: usize },
    #[error("reading results back from the GPU failed: {0}")]
    Readback(String),
    #[error("the GPU renderer does not take {0}")]
    Unsupported(&'static str),
    #[error("the scene as uploaded to the GPU cannot be rendered {0}")]
    View(String),
}

/// A GPU device and its queue.
pub struct Gpu {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    limits: wgpu::Limits,
    /// The largest storage binding canopy uses: the adapter's, or less (see
    /// [`Gpu::cap_binding_bytes`]).
    max_binding: u64,
    /// The first error wgpu reported since the last check (it would panic otherwise).
    reported: Arc<Mutex<Option<String>>>,
}

impl Gpu {
    /// The first adapter wgpu finds (a high-performance one preferred).
    pub fn new() -> Result<Self, GpuError> {
        pollster::block_on(Self::open())
    }

    async fn open() -> Result<Self, GpuError> {
        let instance = new_instance();
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
        let reported = Arc::new(Mutex::new(None));
        let slot = reported.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let mut first = slot.lock().unwrap_or_else(|p| p.into_inner());
            first.get_or_insert_with(|| e.to_string());
        }));
        Ok(Self {
            device,
            queue,
            info,
            max_binding: limits
                .max_storage_buffer_binding_size
                .min(limits.max_buffer_size),
            limits,
            reported,
        })
    }

    /// Whether the adapter is a CPU in disguise (a software driver such as lavapipe).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// The adapter's name, backend and kind, in one line.
    pub fn describe(&self) -> String {
        describe(&self.info)
    }

    /// A storage buffer holding `bytes` (checked against the binding limits; an empty one
    /// gets 256 zero bytes, at least one element of any buffer canopy binds, as bindings
    /// cannot be empty), usable also as `extra`.
    pub(crate) fn storage(
        &self,
        label: &'static str,
        bytes: &[u8],
        extra: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer, GpuError> {
        use wgpu::util::DeviceExt;
        self.check_size(label, bytes.len() as u64)?;
        let padding = [0u8; 256];
        let contents = if bytes.is_empty() {
            &padding[..]
        } else {
            bytes
        };
        Ok(self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE | extra,
            }))
    }

    /// The error wgpu reported since the last check, if any (and clears it).
    pub(crate) fn check(&self) -> Result<(), GpuError> {
        let mut reported = self.reported.lock().unwrap_or_else(|p| p.into_inner());
        match reported.take() {
            Some(message) => Err(GpuError::Reported(message)),
            None => Ok(()),
        }
    }

    /// A compute pipeline from WGSL sources joined in order, entry point `entry`, with
    /// values for the shader's overridable `constants`.
    pub(crate) fn pipeline(
        &self,
        entry: &str,
        sources: &[&str],
        constants: &[(String, f64)],
    ) -> Result<wgpu::ComputePipeline, GpuError> {
        let constants: Vec<(&str, f64)> = constants.iter().map(|(k, v)| (k.as_str(), *v)).collect();
        let module = self
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(entry),
                source: wgpu::ShaderSource::Wgsl(sources.join("\n").into()),
            });
        let pipeline = self
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants: &constants,
                    ..Default::default()
                },
                cache: None,
            });
        self.check()?;
        Ok(pipeline)
    }

    /// Copies a storage buffer (made with `COPY_SRC`) back to the CPU, after the work
    /// submitted so far.
    pub(crate) fn read_back<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
    ) -> Result<Vec<T>, GpuError> {
        let size = buffer.size();
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
        self.queue.submit([encoder.finish()]);
        let slice = staging.slice(..);
        let (sender, receiver) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = sender.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        receiver
            .recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        self.check()?;
        let data = slice
            .get_mapped_range()
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        Ok(bytemuck::cast_slice(&data).to_vec())
    }

    pub(crate) fn limits(&self) -> &wgpu::Limits {
        &self.limits
    }

    /// Bytes one storage binding may hold.
    pub(crate) fn max_binding_bytes(&self) -> u64 {
        self.max_binding
    }

    /// Treats storage bindings as holding at most `bytes` (never more than the adapter
    /// allows), so that small scenes take the paths of large ones: arrays split over
    /// several bindings, and the errors of scenes that do not fit. For tests and for
    /// trying a smaller GPU's limits.
    pub fn cap_binding_bytes(&mut self, bytes: u64) {
        self.max_binding = self.max_binding.min(bytes);
    }

    /// Refuses a buffer larger than one storage binding may be.
    pub(crate) fn check_size(&self, what: &'static str, bytes: u64) -> Result<(), GpuError> {
        let checks = [
            (self.max_binding, "max_storage_buffer_binding_size"),
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

/// A wgpu instance for compute, which needs no display.
fn new_instance() -> wgpu::Instance {
    quiet_headless_device_selection();
    wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env())
}

/// Mesa's implicit Vulkan layer `VK_LAYER_MESA_device_select` picks the GPU that drives
/// the display, and on a machine without one (no `WAYLAND_DISPLAY`, no `DISPLAY`: a
/// server, CI, a Ray worker) it prints "error: XDG_RUNTIME_DIR is invalid or not set"
/// to stderr when it tries to connect, once per instance. A library must not print, and
/// there is no display to select by: the layer is switched off (`NODEVICE_SELECT=1`,
/// its own switch) before the first instance, unless the user set it either way.
fn quiet_headless_device_selection() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let set = |name: &str| std::env::var_os(name).is_some_and(|v| !v.is_empty());
        let headless = !set("WAYLAND_DISPLAY") && !set("DISPLAY");
        if headless && std::env::var_os("NODEVICE_SELECT").is_none() {
            // Before wgpu starts the Vulkan loader (which reads it); canopy reads no
            // environment from other threads meanwhile.
            std::env::set_var("NODEVICE_SELECT", "1");
        }
    });
}

fn describe(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
}

/// Every adapter wgpu finds, described in one line each (`canopy devices`).
pub fn adapters() -> Vec<String> {
    let instance = new_instance();
    pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()))
        .iter()
        .map(|a| describe(&a.get_info()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shader_that_does_not_compile_is_an_error_not_a_panic() {
        let gpu = match Gpu::new() {
            Ok(gpu) => gpu,
            Err(e) => return eprintln!("SKIPPED: no GPU adapter: {e}"),
        };
        let Err(err) = gpu.pipeline("broken", &["@compute @workgroup_size(1) fn broken( {"], &[])
        else {
            panic!("a broken shader compiled");
        };
        assert!(matches!(err, GpuError::Reported(_)), "{err}");
        // The error was taken: the device goes on working.
        assert!(gpu.check().is_ok());
        gpu.pipeline("fine", &["@compute @workgroup_size(1) fn fine() {}"], &[])
            .unwrap();
    }
}
