//! canopy-job's integration tests: passes, regions, progress and checkpoints.
//!
//! One binary for all of them (one link instead of one per file); each file is a module.

mod job;
