//! canopy-gpu: canopy's scenes and BVHs on the GPU, through wgpu compute shaders (WGSL),
//! so any Vulkan, Metal or DX12 GPU runs them, and Mesa's software Vulkan driver
//! (lavapipe) runs them on machines with none.
//!
//! This first part traces rays: [`GpuScene`] flattens primitives and a BVH
//! ([`canopy_bvh::GpuBvh`], child boxes in the parent) into `#[repr(C)]` buffers, and
//! [`Tracer::closest`] finds the closest hit of each ray of a batch, the same hits as the
//! CPU's within rounding (same primitive; distance within 1e-5 relative, ties aside).
//!
//! ```no_run
//! # fn main() -> Result<(), canopy_gpu::GpuError> {
//! let scene = canopy_render::load_scene("paper-3").unwrap();
//! let gpu = canopy_gpu::Gpu::new()?;
//! let flat = canopy_gpu::GpuScene::new(&scene.primitives, &canopy_bvh::BuildParams::default())?;
//! let tracer = canopy_gpu::Tracer::new(&gpu, &flat)?;
//! let ray = canopy_bvh::Ray::new(glam::Vec3::ZERO, glam::Vec3::Z, 0.0, f32::INFINITY);
//! let hits = tracer.closest(&[ray])?;
//! # Ok(()) }
//! ```

mod chunked;
mod context;
mod instances;
mod lights;
mod render;
mod rng_check;
mod scene;
mod textures;
mod trace;

pub use chunked::CHUNKS;
pub use context::{adapters, Gpu, GpuError};
pub use render::{DispatchStats, GpuMaterial, Renderer};
pub use rng_check::first_words;
pub use scene::{GpuPrimitive, GpuRay, GpuScene, FLAT, MAX_TREE_DEPTH};
pub use trace::Tracer;
