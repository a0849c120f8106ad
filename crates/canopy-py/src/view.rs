//! `canopy_rt.view`: the interactive viewer (canopy-view) for a scene from Python.

use crate::render::{scene_error, SceneArg};
use canopy_render::load_scene_allowing;
use canopy_view::{Reload, ViewOptions, ViewServer};
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Mutex;

/// A running viewer: its address, and a way to stop it (it also stops when collected).
#[pyclass(frozen, module = "canopy_rt._canopy", name = "Viewer")]
pub struct PyViewer {
    url: String,
    server: Mutex<Option<ViewServer>>,
}

#[pymethods]
impl PyViewer {
    /// The page's address, token included.
    #[getter]
    fn url(&self) -> String {
        self.url.clone()
    }

    /// Pages connected now.
    #[getter]
    fn clients(&self) -> usize {
        let server = self.server.lock().unwrap_or_else(|e| e.into_inner());
        server.as_ref().map_or(0, |s| s.clients())
    }

    /// Whether it still serves.
    #[getter]
    fn running(&self) -> bool {
        self.server
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .is_some()
    }

    /// Stops serving and rendering (after the pass in flight); nothing happens if it
    /// has stopped already.
    fn stop(&self, py: Python<'_>) {
        let server = self.server.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(server) = server {
            py.detach(|| server.shutdown());
        }
    }
}

/// Serves `scene` (a name, a file, or a `Scene` built in Python) in the browser, starting
/// with the render `options` (a dict, as `render` takes them); see `canopy_rt.view`.
#[pyfunction]
#[pyo3(signature = (scene, options=None, *, bind, output_dir, allow_paths, reload))]
pub fn view(
    py: Python<'_>,
    scene: SceneArg<'_>,
    options: Option<Bound<'_, PyAny>>,
    bind: &str,
    output_dir: PathBuf,
    allow_paths: Vec<PathBuf>,
    reload: bool,
) -> PyResult<PyViewer> {
    let render = crate::render::render_options(options.as_ref())?;
    let bind: SocketAddr = bind
        .parse()
        .map_err(|e| PyValueError::new_err(format!("bind: {bind:?} is no address ({e})")))?;
    if !output_dir.is_dir() {
        return Err(PyValueError::new_err(format!(
            "output_dir: {} is not an existing folder",
            output_dir.display()
        )));
    }
    let (scene, reload) = match scene {
        SceneArg::Named(name) => {
            let scene = py
                .detach(|| load_scene_allowing(&name, &allow_paths))
                .map_err(scene_error)?;
            let reload = reload.then(|| {
                Reload::new(move || {
                    load_scene_allowing(&name, &allow_paths).map_err(|e| e.to_string())
                })
            });
            (scene, reload)
        }
        // Built in code: no file to follow.
        SceneArg::Built(built) => (built.borrow().scene.clone(), None),
    };
    let options = ViewOptions {
        bind,
        render,
        save_dir: output_dir,
        reload,
    };
    let server = py
        .detach(|| ViewServer::start(scene, options))
        .map_err(|e| match e {
            canopy_view::ViewError::Bind { .. } => PyOSError::new_err(e.to_string()),
            canopy_view::ViewError::Threads(_) | canopy_view::ViewError::Gpu(_) => {
                PyRuntimeError::new_err(e.to_string())
            }
            _ => PyValueError::new_err(e.to_string()),
        })?;
    Ok(PyViewer {
        url: server.url(),
        server: Mutex::new(Some(server)),
    })
}
