//! Where OIDN's library is looked for, in order.

use std::path::PathBuf;

/// The library's file name, which the system's loader also finds it by.
#[cfg(target_os = "linux")]
pub const LIBRARY_NAME: &str = "libOpenImageDenoise.so.2";
#[cfg(target_os = "macos")]
pub const LIBRARY_NAME: &str = "libOpenImageDenoise.2.dylib";
#[cfg(windows)]
pub const LIBRARY_NAME: &str = "OpenImageDenoise.dll";
#[cfg(not(any(target_os = "linux", target_os = "macos", windows)))]
pub const LIBRARY_NAME: &str = "libOpenImageDenoise.so.2";

/// The environment variable that names the library, or a folder holding it (or holding
/// a `lib` folder that does: OIDN's own release layout).
pub const CANOPY_OIDN_VARIABLE: &str = "CANOPY_OIDN";

/// The places [`crate::Oidn::load`] tries, in order: `CANOPY_OIDN`, the folders
/// `extra`, canopy's data folder (`$XDG_DATA_HOME/canopy/oidn/lib`, by default
/// `~/.local/share/canopy/oidn/lib`: where `scripts/oidn.sh` installs it), and last the
/// bare library name for the system's loader.
pub fn library_candidates(extra: &[PathBuf]) -> Vec<PathBuf> {
    let mut candidates = Vec::new();
    if let Some(named) = std::env::var_os(CANOPY_OIDN_VARIABLE).map(PathBuf::from) {
        if named.is_dir() {
            candidates.push(named.join(LIBRARY_NAME));
            candidates.push(named.join("lib").join(LIBRARY_NAME));
        } else {
            candidates.push(named);
        }
    }
    candidates.extend(extra.iter().map(|dir| dir.join(LIBRARY_NAME)));
    if let Some(data) = data_folder() {
        candidates.push(data.join("canopy/oidn/lib").join(LIBRARY_NAME));
    }
    candidates.push(PathBuf::from(LIBRARY_NAME));
    candidates
}

/// The user's data folder: `$XDG_DATA_HOME`, else `~/.local/share`.
fn data_folder() -> Option<PathBuf> {
    let absolute = |p: PathBuf| p.is_absolute().then_some(p);
    std::env::var_os("XDG_DATA_HOME")
        .map(PathBuf::from)
        .and_then(absolute)
        .or_else(|| {
            let home = std::env::var_os("HOME").map(PathBuf::from)?;
            absolute(home.join(".local/share"))
        })
}
