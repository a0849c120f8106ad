//! canopy-gpu's integration tests: the GPU kernels against the CPU's.
//!
//! One binary for all of them (one link instead of one per file); each file is a module.

mod render;
mod traversal;
