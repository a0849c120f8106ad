//! The library's output policy for Python's writers (the Ray driver, its CLI, resume
//! folders, frames, benchmark records): `check_output` before any work, `write_file`
//! through the atomic writer.

use canopy_render::output_policy::{self, OutputKind};
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use std::path::PathBuf;

/// Why `what` may not be written to `path` ("image", "checkpoint" or "data" for `kind`),
/// raised as ValueError before any work: a format its writer does not know, a folder
/// that is missing or not writable, one of `inputs` (by identity: links count), or a
/// canopy checkpoint (a render's unfinished work).
#[pyfunction]
#[pyo3(signature = (path, what, kind, inputs=Vec::new()))]
pub fn check_output(path: PathBuf, what: &str, kind: &str, inputs: Vec<PathBuf>) -> PyResult<()> {
    let kind = match kind {
        "image" => OutputKind::Image,
        "checkpoint" => OutputKind::Checkpoint,
        "data" => OutputKind::Data,
        other => {
            return Err(PyValueError::new_err(format!(
                "kind must be \"image\", \"checkpoint\" or \"data\", not {other:?}"
            )))
        }
    };
    output_policy::check_output(&path, what, kind, &inputs).map_err(PyValueError::new_err)
}

/// Writes `data` to `path` atomically: through a new temporary file of an unpredictable
/// name beside it (created exclusively, so a planted link is never followed), synced,
/// then renamed over `path`. A failed write leaves no file.
#[pyfunction]
pub fn write_file(py: Python<'_>, path: PathBuf, data: Vec<u8>) -> PyResult<()> {
    use std::io::Write;
    py.detach(|| canopy_render::output::write_atomically(&path, |w| w.write_all(&data)))
        .map_err(|e| PyOSError::new_err(format!("{}: cannot write: {e}", path.display())))
}
