//! canopy-render's integration tests: loaders, integrators and images.
//!
//! One binary for all of them (one link instead of one per file); each file is a module.

mod accel;
mod aovs;
mod gltf;
mod instances;
mod integrator;
mod light_sampling;
mod loaders_never_panic;
mod mitsuba_ggx;
mod pipeline;
mod punctual;
mod scale_invariance;
mod schedules;
mod tree_quality;
mod watertight;
