//! Checks made before any work starts, so that canopy never writes over a user's file,
//! never fails after hours because an output cannot be written, and never starts what
//! memory cannot hold. The guarantees are listed in `docs/guarantees.md`.

use canopy_render::files::available_memory;
use std::path::{Path, PathBuf};

pub use canopy_render::files::same_file;

/// Refuses to write `what` to `path` when it is one of the scene's input files.
pub fn refuse_inputs(path: &Path, inputs: &[PathBuf], what: &str) -> anyhow::Result<()> {
    canopy_render::output_policy::check_not_an_input(path, what, inputs).map_err(anyhow::Error::msg)
}

/// The library's output policy ([`canopy_render::output_policy`]): format, folder,
/// inputs and checkpoints, checked before any work.
pub fn check_output(
    path: &Path,
    what: &str,
    kind: OutputKind,
    inputs: &[PathBuf],
) -> anyhow::Result<()> {
    canopy_render::output_policy::check_output(path, what, kind, inputs).map_err(anyhow::Error::msg)
}

pub use canopy_render::output_policy::{file_stem_from_name, OutputKind};

/// Refuses work that needs more memory than is available (where that is known).
pub fn check_memory(needed: u64, what: &str) -> anyhow::Result<()> {
    canopy_render::files::check_memory(needed, available_memory(), what).map_err(anyhow::Error::msg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_file_sees_through_relative_paths() {
        let here = std::env::current_dir().unwrap();
        assert!(same_file(Path::new("Cargo.toml"), &here.join("Cargo.toml")));
        assert!(same_file(Path::new("./new.png"), &here.join("new.png")));
        assert!(!same_file(Path::new("a.png"), Path::new("b.png")));
    }
}
