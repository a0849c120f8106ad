//! The `canopy` binary's integration tests: its commands, its promises and its limits.
//!
//! One binary for all of them (one link instead of one per file); each file is a module.

mod cli;
mod common;
mod denoise;
mod limits;
mod safety;
mod view;
