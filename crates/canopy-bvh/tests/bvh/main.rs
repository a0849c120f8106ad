//! canopy-bvh's integration tests: every builder, layout and query against brute force.
//!
//! One binary for all of them (one link instead of one per file); each file is a module.

mod brute_force;
mod common;
mod crossings;
mod instances;
mod proximity;
mod spheres;
mod triangles;
