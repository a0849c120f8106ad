//! Reading input files safely (only regular files, never more bytes than a limit), and
//! telling whether an output path names one of them.
//!
//! A path may name a device (`/dev/zero`, `/dev/urandom`), a FIFO or a directory. Reading
//! such a thing either never ends or never stops growing, so every reader in canopy goes
//! through [`read_regular_file`], which refuses them before opening (opening a FIFO for
//! reading blocks until a writer appears) and bounds the read by the size the file had
//! when it was checked.

use std::fs::File;
use std::io::{self, Read};
use std::path::Path;

/// Why an input file was not read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{0}")]
    Io(#[from] io::Error),
    #[error("not a regular file (a {0}); canopy reads only regular files")]
    NotRegular(&'static str),
    #[error("the file is {size} bytes, more than the {limit} bytes allowed here")]
    TooLarge { size: u64, limit: u64 },
}

/// For errors that carry an `io::Error` cause: I/O errors as they are, refusals as
/// errors of their own kind with the same message.
impl From<ReadError> for io::Error {
    fn from(e: ReadError) -> Self {
        match e {
            ReadError::Io(e) => e,
            other => io::Error::other(other.to_string()),
        }
    }
}

/// What kind of non-regular thing a path names, for the message.
fn kind_of(meta: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    if t.is_dir() {
        "directory"
    } else if t.is_fifo() {
        "FIFO"
    } else if t.is_char_device() || t.is_block_device() {
        "device"
    } else if t.is_socket() {
        "socket"
    } else {
        "special file"
    }
}

/// Fails unless `path` (after following symbolic links) is a regular file; returns its
/// size in bytes.
pub fn regular_file_size(path: &Path) -> Result<u64, ReadError> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(ReadError::NotRegular(kind_of(&meta)));
    }
    Ok(meta.len())
}

/// The bytes of a regular file of at most `limit` bytes. A file that grows while it is
/// read is cut at the size it had when checked, so the read always ends.
pub fn read_regular_file(path: &Path, limit: u64) -> Result<Vec<u8>, ReadError> {
    let size = regular_file_size(path)?;
    if size > limit {
        return Err(ReadError::TooLarge { size, limit });
    }
    let file = File::open(path)?;
    // The path may have been swapped for something else between the check and the open.
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(ReadError::NotRegular(kind_of(&meta)));
    }
    let mut bytes = Vec::with_capacity(size as usize);
    file.take(size).read_to_end(&mut bytes)?;
    Ok(bytes)
}

/// The first `n` bytes of a regular file (fewer if it is shorter); `None` when the path
/// does not name a readable regular file.
pub fn read_prefix(path: &Path, n: usize) -> Option<Vec<u8>> {
    regular_file_size(path).ok()?;
    let mut bytes = Vec::with_capacity(n);
    File::open(path)
        .ok()?
        .take(n as u64)
        .read_to_end(&mut bytes)
        .ok()?;
    Some(bytes)
}

/// A random non-zero number nobody can predict: std's per-process random hasher keys,
/// mixed with the process id, the time and a counter.
pub fn random_u64() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    use std::sync::atomic::{AtomicU64, Ordering};
    static CALLS: AtomicU64 = AtomicU64::new(0);
    let mut hasher = std::collections::hash_map::RandomState::new().build_hasher();
    hasher.write_u32(std::process::id());
    hasher.write_u64(CALLS.fetch_add(1, Ordering::Relaxed));
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    hasher.write_u128(now.as_nanos());
    hasher.finish().max(1)
}

/// Why `what` cannot be done: it needs `needed` bytes, more than the `available` ones
/// (when known). The one memory check of every input that decodes to something large.
pub fn check_memory(needed: u64, available: Option<u64>, what: &str) -> Result<(), String> {
    match available {
        Some(free) if needed > free => Err(format!(
            "{what} needs about {} MiB of memory, more than the {} MiB available",
            needed >> 20,
            free >> 20
        )),
        _ => Ok(()),
    }
}

/// `MemAvailable` from /proc/meminfo, where there is one.
pub fn available_memory() -> Option<u64> {
    // A /proc file reports a size of 0, so it is read as it is; it is a kernel table.
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// The directory a file at `path` lives in (`.` for a bare file name).
pub fn directory_of(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// The absolute form of a path that may not exist yet: its directory resolved (links
/// followed), its file name kept. `None` when the directory does not exist.
fn resolved(path: &Path) -> Option<std::path::PathBuf> {
    if let Ok(full) = std::fs::canonicalize(path) {
        return Some(full);
    }
    Some(
        std::fs::canonicalize(directory_of(path))
            .ok()?
            .join(path.file_name()?),
    )
}

/// Whether two paths name the same file (or would, once created): the same file on
/// disk (device and inode: symbolic and hard links and every other spelling count), or
/// for a file not there yet, the same place. The one test every writer makes of its
/// outputs against the inputs it read.
pub fn same_file(a: &Path, b: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    if let (Ok(a), Ok(b)) = (std::fs::metadata(a), std::fs::metadata(b)) {
        return (a.dev(), a.ino()) == (b.dev(), b.ino());
    }
    match (resolved(a), resolved(b)) {
        (Some(a), Some(b)) => a == b,
        _ => a == b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_and_directories_are_refused_without_reading() {
        for path in ["/dev/zero", "/dev/urandom", "/dev/null"] {
            if Path::new(path).exists() {
                let e = read_regular_file(Path::new(path), u64::MAX).unwrap_err();
                assert!(
                    e.to_string().contains("not a regular file (a device)"),
                    "{e}"
                );
            }
        }
        let e = read_regular_file(&std::env::temp_dir(), u64::MAX).unwrap_err();
        assert!(e.to_string().contains("directory"), "{e}");
    }

    #[test]
    fn a_fifo_is_refused_instead_of_blocking() {
        let path = std::env::temp_dir().join(format!("canopy-fifo-{}", std::process::id()));
        let made = std::process::Command::new("mkfifo").arg(&path).status();
        if !made.is_ok_and(|s| s.success()) {
            return; // no mkfifo on this system
        }
        let e = read_regular_file(&path, u64::MAX).unwrap_err();
        std::fs::remove_file(&path).unwrap();
        assert!(e.to_string().contains("FIFO"), "{e}");
    }

    #[test]
    fn a_file_over_the_limit_is_refused() {
        let path = std::env::temp_dir().join(format!("canopy-big-{}", std::process::id()));
        std::fs::write(&path, [0u8; 100]).unwrap();
        assert!(matches!(
            read_regular_file(&path, 99),
            Err(ReadError::TooLarge {
                size: 100,
                limit: 99
            })
        ));
        assert_eq!(read_regular_file(&path, 100).unwrap().len(), 100);
        assert_eq!(read_prefix(&path, 8).unwrap().len(), 8);
        std::fs::remove_file(&path).unwrap();
    }
}
