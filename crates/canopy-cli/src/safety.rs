//! Checks made before any work starts, so that canopy never writes over a user's file,
//! never fails after hours because an output cannot be written, and never starts what
//! memory cannot hold. The guarantees are listed in `docs/guarantees.md`.

use anyhow::bail;
use canopy_render::checkpoint::Checkpoint;
use canopy_render::files::available_memory;
use std::path::{Path, PathBuf};

pub use canopy_render::files::same_file;

/// The directory a file at `path` lives in (`.` for a bare file name).
fn directory_of(path: &Path) -> &Path {
    canopy_render::files::directory_of(path)
}

/// Refuses to write `what` to `path` when it is one of the scene's input files.
pub fn refuse_inputs(path: &Path, inputs: &[PathBuf], what: &str) -> anyhow::Result<()> {
    canopy_render::files::refuse_inputs(path, inputs, what).map_err(anyhow::Error::msg)
}

/// Refuses a checkpoint path that holds something other than a canopy checkpoint.
pub fn check_checkpoint_slot(path: &Path) -> anyhow::Result<()> {
    Checkpoint::check_slot(path)
        .map_err(|e| anyhow::anyhow!("{e} (choose another --checkpoint path)"))
}

/// Fails unless a file can be created next to `path` (its directory exists and is
/// writable): found at the start, not after the render.
pub fn check_writable_dir(path: &Path, what: &str) -> anyhow::Result<()> {
    // `o.png/` names a directory: no file can ever be renamed to it.
    if path
        .as_os_str()
        .to_string_lossy()
        .ends_with(std::path::is_separator)
    {
        bail!(
            "{}: cannot write the {what}: the path ends with a separator, so it names a directory",
            path.display()
        );
    }
    let dir = directory_of(path);
    if !dir.is_dir() {
        bail!(
            "{}: cannot write the {what}: directory {} does not exist",
            path.display(),
            dir.display()
        );
    }
    if std::fs::metadata(path).is_ok_and(|m| m.is_dir()) {
        bail!(
            "{}: cannot write the {what}: it is a directory",
            path.display()
        );
    }
    // A probe file of a fresh name (never an existing one: create_new does not open
    // what is there), removed at once.
    let mut last_error = None;
    for attempt in 0..16 {
        let probe = dir.join(format!(".canopy-probe-{}-{attempt}", std::process::id()));
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&probe)
        {
            Ok(_) => {
                let _ = std::fs::remove_file(&probe);
                return Ok(());
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => {
                last_error = Some(e);
                break;
            }
        }
    }
    match last_error {
        Some(e) => bail!(
            "{}: cannot write the {what} in {}: {e}",
            path.display(),
            dir.display()
        ),
        None => bail!(
            "{}: cannot write the {what} in {}: no free name for a test file",
            path.display(),
            dir.display()
        ),
    }
}

/// Refuses work that needs more memory than is available (where that is known).
pub fn check_memory(needed: u64, what: &str) -> anyhow::Result<()> {
    canopy_render::files::check_memory(needed, available_memory(), what).map_err(anyhow::Error::msg)
}

/// A scene's name made into a plain file name in the current directory: path
/// separators, `..`, control and other unusual characters become `_`.
pub fn file_stem_from_name(name: &str) -> String {
    let cleaned: String = name
        .chars()
        .map(|c| match c {
            'a'..='z' | 'A'..='Z' | '0'..='9' | '-' | '_' | '.' => c,
            _ => '_',
        })
        .take(100)
        .collect();
    // No hidden files, no `.` or `..`.
    let cleaned = cleaned.trim_start_matches('.');
    if cleaned.chars().all(|c| c == '_') {
        "render".to_owned()
    } else {
        cleaned.to_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_become_plain_file_names() {
        assert_eq!(file_stem_from_name("cornell"), "cornell");
        assert_eq!(file_stem_from_name("../x"), "_x");
        assert_eq!(file_stem_from_name("/etc/passwd"), "_etc_passwd");
        assert_eq!(file_stem_from_name(".."), "render");
        assert_eq!(file_stem_from_name(""), "render");
        assert_eq!(file_stem_from_name("my scene\n"), "my_scene_");
        assert_eq!(file_stem_from_name(&"a".repeat(500)).len(), 100);
    }

    #[test]
    fn same_file_sees_through_relative_paths() {
        let here = std::env::current_dir().unwrap();
        assert!(same_file(Path::new("Cargo.toml"), &here.join("Cargo.toml")));
        assert!(same_file(Path::new("./new.png"), &here.join("new.png")));
        assert!(!same_file(Path::new("a.png"), Path::new("b.png")));
    }
}
