//! `canopy_rt.render`, `canopy_rt.load_scene` and `canopy_rt.read_image`.

use crate::pools;
use crate::scene::PyScene;
use canopy_job::{CheckpointPolicy, JobError, Observer, RenderJob, RenderOptions, Resumed};
use canopy_render::mesh::{parse_mesh, MeshFormat};
use canopy_render::{load_scene_allowing as load, Accumulator, AovSet, Region, Scene};
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2, PyArray3, PyReadonlyArray2, ToPyArray};
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use std::time::Duration;

pub(crate) fn scene_error(e: canopy_render::SceneError) -> PyErr {
    match e {
        canopy_render::SceneError::Read { .. } => PyOSError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

/// A loaded scene, described (`canopy.load_scene`).
#[pyclass(frozen, module = "canopy_rt._canopy")]
pub struct SceneInfo {
    scene: Scene,
}

impl SceneInfo {
    pub fn new(scene: Scene) -> Self {
        Self { scene }
    }
}

#[pymethods]
impl SceneInfo {
    #[getter]
    fn name(&self) -> &str {
        &self.scene.name
    }

    #[getter]
    fn description(&self) -> &str {
        &self.scene.description
    }

    /// The render settings: width, height, spp, max_depth, seed, integrator,
    /// russian_roulette, sampler.
    #[getter]
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.scene.settings;
        let d = PyDict::new(py);
        d.set_item("width", s.width)?;
        d.set_item("height", s.height)?;
        d.set_item("spp", s.spp)?;
        d.set_item("max_depth", s.max_depth)?;
        d.set_item("seed", s.seed)?;
        d.set_item("integrator", s.integrator.name())?;
        d.set_item("russian_roulette", s.russian_roulette)?;
        d.set_item("sampler", s.sampler.name())?;
        Ok(d)
    }

    /// Counts of primitives by shape, instances, materials (emissive and textured ones
    /// too) and texture images.
    #[getter]
    fn counts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = self.scene.shape_counts();
        let d = PyDict::new(py);
        d.set_item("primitives", self.scene.primitives.len())?;
        d.set_item("instances", self.scene.instances.len())?;
        d.set_item("instanced_triangles", self.scene.instanced_triangles())?;
        d.set_item("spheres", c.spheres)?;
        d.set_item("triangles", c.triangles)?;
        d.set_item("cuboids", c.cuboids)?;
        d.set_item("materials", self.scene.materials.len())?;
        let emissive = self
            .scene
            .materials
            .iter()
            .filter(|m| m.emitted() != glam::Vec3::ZERO)
            .count();
        d.set_item("emissive_materials", emissive)?;
        d.set_item("textured_materials", self.scene.textured_materials())?;
        d.set_item("images", self.scene.images.len())?;
        Ok(d)
    }

    /// Bounds of every primitive: ((min x, y, z), (max x, y, z)).
    #[getter]
    fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let b = self
            .scene
            .primitive_bounds()
            .into_iter()
            .fold(canopy_bvh::Aabb::EMPTY, canopy_bvh::Aabb::union);
        (b.min.to_array(), b.max.to_array())
    }

    /// The files the scene reads (scene file, meshes, models, environment map).
    #[getter]
    fn inputs(&self) -> Vec<std::path::PathBuf> {
        self.scene.inputs.clone()
    }

    /// Everything the scene holds, for handing it to another renderer: `camera`,
    /// `background`, `materials` (tables as `Scene.add_material` takes them, textures
    /// left out), `spheres`, `cuboids` and `triangles` (world space, mesh instances baked)
    /// as numpy arrays with a material index each.
    fn contents<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        crate::contents::contents(py, &self.scene)
    }

    /// What is legal but probably unintended.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.scene.warnings()
    }

    fn __repr__(&self) -> String {
        let s = self.scene.settings;
        format!(
            "SceneInfo(name={:?}, {} primitives, {}x{}, {} spp)",
            self.scene.name,
            self.scene.primitives.len(),
            s.width,
            s.height,
            s.spp
        )
    }
}

#[pyfunction]
#[pyo3(signature = (scene, allow_paths=Vec::new()))]
pub fn load_scene(py: Python<'_>, scene: &str, allow_paths: Vec<PathBuf>) -> PyResult<SceneInfo> {
    let scene = py
        .detach(|| load(scene, &allow_paths))
        .map_err(scene_error)?;
    Ok(SceneInfo { scene })
}

/// Renders a scene to a linear float32 image of shape (height, width, 3), or of the
/// region's shape when one is given (`region=(x, y, width, height)`: exactly those
/// pixels of the whole image). `options` holds canopy's render options
/// (`canopy_job::RenderOptions`: spp, size, seed, max_depth, integrator, ..., by those
/// names; see `RENDER_OPTIONS`). Samples are added one per pixel per pass; between
/// passes `progress(done, total)` is called and Ctrl-C is honoured (KeyboardInterrupt).
/// With `checkpoint=path` the render is saved there every `checkpoint_every` seconds and
/// when interrupted, and `resume=path` continues such a render (its scene and settings
/// come from the file). `samples=(first, count)` renders only samples `first .. first +
/// count` of every pixel and returns their mean. `camera={...}` moves the camera (any
/// of look_from, look_at, up, vfov, aperture, focus_distance) and `instances={k: (3, 4)
/// matrix}` moves mesh instances: a frame of an animation.
#[pyfunction]
#[pyo3(signature = (scene=None, options=None, progress=None, region=None, checkpoint=None,
    checkpoint_every=60.0, resume=None, samples=None, camera=None, instances=None,
    allow_paths=Vec::new(), aovs=None, denoise=false, oidn_paths=Vec::new()))]
#[allow(clippy::too_many_arguments)]
pub fn render<'py>(
    py: Python<'py>,
    scene: Option<SceneArg<'py>>,
    options: Option<Bound<'py, PyAny>>,
    progress: Option<Py<PyAny>>,
    region: Option<(u32, u32, u32, u32)>,
    checkpoint: Option<PathBuf>,
    checkpoint_every: f64,
    resume: Option<PathBuf>,
    samples: Option<(u32, u32)>,
    camera: Option<Bound<'py, PyDict>>,
    instances: Option<std::collections::HashMap<u32, PyReadonlyArray2<'py, f32>>>,
    allow_paths: Vec<PathBuf>,
    aovs: Option<String>,
    denoise: bool,
    oidn_paths: Vec<PathBuf>,
) -> PyResult<Bound<'py, PyAny>> {
    let options = render_options(options.as_ref())?;
    let asked_aovs: Option<AovSet> = aovs
        .as_deref()
        .map(str::parse)
        .transpose()
        .map_err(PyValueError::new_err)?;
    if (asked_aovs.is_some() || denoise) && samples.is_some() {
        return Err(PyValueError::new_err(
            "aovs= and denoise= take a whole render's samples: drop samples=",
        ));
    }
    // Before any work: a denoise that cannot happen is said now.
    let oidn = denoise
        .then(|| crate::denoise::load_oidn(&oidn_paths))
        .transpose()?;
    options.check().map_err(PyValueError::new_err)?;
    if !(checkpoint_every.is_finite() && checkpoint_every >= 0.0) {
        return Err(PyValueError::new_err(format!(
            "checkpoint_every must be a number of seconds >= 0, not {checkpoint_every}"
        )));
    }
    let mut overrides = options.given_scene_settings();
    for (given, name) in [
        (options.fast_triangles.is_some(), "fast_triangles"),
        (region.is_some(), "region"),
        (camera.is_some(), "camera"),
        (instances.is_some(), "instances"),
    ] {
        if given {
            overrides.push(name);
        }
    }
    if resume.is_some() && !overrides.is_empty() {
        return Err(PyValueError::new_err(format!(
            "a resumed render keeps its checkpoint's settings: drop {}",
            overrides.join(", ")
        )));
    }
    if let Some((first, count)) = samples {
        if resume.is_some() || checkpoint.is_some() {
            return Err(PyValueError::new_err(
                "samples= renders a part of a render's samples: drop resume and checkpoint",
            ));
        }
        if options.spp.is_some() {
            return Err(PyValueError::new_err(
                "give spp (all samples) or samples=(first, count), not both",
            ));
        }
        if count == 0 || first.checked_add(count).is_none() {
            return Err(PyValueError::new_err(format!(
                "samples=(first, count) needs count >= 1 and first + count within range, not ({first}, {count})"
            )));
        }
    }
    let given = match scene {
        None => None,
        Some(SceneArg::Named(name)) => {
            let scene = py
                .detach(|| load(&name, &allow_paths))
                .map_err(scene_error)?;
            let source = canopy_render::scene_source(&name).map_err(scene_error)?;
            Some((scene, source))
        }
        Some(SceneArg::Built(built)) => {
            let scene = built.borrow().scene.clone();
            let source = format!("python:{}", scene.name);
            Some((scene, source))
        }
    };
    let (mut scene, source, resumed) = match (given, &resume) {
        (None, None) => return Err(PyValueError::new_err("render() needs a scene (or resume=)")),
        (None, Some(path)) => {
            let r = py
                .detach(|| Resumed::load(path, &allow_paths))
                .map_err(job_error)?;
            (
                r.scene,
                r.source,
                Some((r.accumulator, r.owner, r.triangle_test)),
            )
        }
        (Some((scene, _)), Some(path)) => {
            let r = py
                .detach(|| Resumed::load_for(path, scene))
                .map_err(job_error)?;
            (
                r.scene,
                r.source,
                Some((r.accumulator, r.owner, r.triangle_test)),
            )
        }
        (Some((scene, source)), None) => (scene, source, None),
    };
    if resumed.is_none() {
        let settings_options = RenderOptions {
            spp: samples.map(|(first, count)| first + count).or(options.spp),
            ..options.clone()
        };
        settings_options
            .apply_to_settings(&mut scene.settings)
            .map_err(PyValueError::new_err)?;
        if let Some(changes) = &camera {
            let moved = moved_camera(scene.camera, changes)?;
            scene
                .set_camera(moved)
                .map_err(|e| PyValueError::new_err(format!("camera: {e}")))?;
        }
        let mut moves: Vec<_> = instances.iter().flatten().collect();
        moves.sort_by_key(|(index, _)| **index);
        for (index, transform) in moves {
            let to_world = crate::arrays::affine(transform)?;
            scene
                .set_instance_transform(*index, to_world)
                .map_err(|e| PyValueError::new_err(format!("instances[{index}]: {e}")))?;
        }
    }
    let mut job = RenderJob::new(&scene, source);
    options
        .apply_to_job(&mut job)
        .map_err(PyValueError::new_err)?;
    let resumed = resumed.map(|(accumulator, owner, triangle_test)| {
        // The render goes on in its checkpoint's triangle test.
        job.structure.triangle_test = triangle_test;
        (accumulator, owner)
    });
    if let Some((x, y, width, height)) = region {
        job.region = Region {
            x,
            y,
            width,
            height,
        };
    }
    let written_aovs = asked_aovs.unwrap_or_default();
    job.aovs = match &resumed {
        Some((held, _)) if !held.aovs.set.includes(written_aovs) => {
            return Err(PyValueError::new_err(format!(
                "aovs: the render to resume holds the AOVs [{}], not all of [{written_aovs}]",
                held.aovs.set
            )))
        }
        Some((held, _)) => held.aovs.set,
        None if denoise => written_aovs.union(AovSet::DENOISING),
        None => written_aovs,
    };
    (job.resume, job.resume_owner) = resumed.unzip();
    if let Some((first, _)) = samples {
        // Samples before `first` count as done: the job adds the rest, from `first` on.
        let mut part = Accumulator::for_region(job.region);
        part.samples = first;
        job.resume = Some(part);
    }
    let checkpoint = checkpoint.or(resume);
    job.checkpoint = CheckpointPolicy {
        periodic: checkpoint.clone(),
        every: Duration::from_secs_f64(checkpoint_every),
        on_interrupt: checkpoint,
    };
    let mut observer = PyObserver {
        progress,
        error: None,
    };
    // `None`: the job's own pool where `threads` is set, else all cores (in a forked
    // child, a pool of its own: see `pools`).
    let outcome = py
        .detach(|| pools::install(None, || job.prepare()?.run(&mut observer)))?
        .map_err(job_error)?;
    if let Some(error) = observer.error {
        return Err(error);
    }
    let done = &outcome.accumulator;
    // The mean of the samples rendered here (all of them, or the range asked for).
    let n = samples.map_or(done.samples, |(_, count)| count).max(1) as f32;
    let mut film = canopy_render::Film {
        width: done.region.width,
        height: done.region.height,
        pixels: done.sums.iter().map(|s| *s / n).collect(),
    };
    let aov_images = done.aov_images();
    if let Some(oidn) = &oidn {
        film = py
            .detach(|| {
                let denoise_options = canopy_job::DenoiseOptions {
                    threads: options.threads,
                    prefilter: false,
                };
                canopy_job::denoise_film(oidn, &film, &aov_images, &denoise_options)
            })
            .map_err(crate::denoise::denoise_error)?;
    }
    let pixels: Vec<f32> = film.pixels.iter().flat_map(|p| p.to_array()).collect();
    let image = numpy::ndarray::Array3::from_shape_vec(
        (done.region.height as usize, done.region.width as usize, 3),
        pixels,
    )
    .expect("height x width x 3 values")
    .to_pyarray(py)
    .into_any();
    match asked_aovs {
        None => Ok(image),
        Some(set) => {
            let layers = crate::denoise::aov_arrays(py, &aov_images.only(set), done.region)?;
            Ok((image, layers).into_pyobject(py)?.into_any())
        }
    }
}

/// canopy's render options from a dict of them (`None`: none given), refusing a name
/// that is none of them or a value out of its type.
pub(crate) fn render_options(options: Option<&Bound<'_, PyAny>>) -> PyResult<RenderOptions> {
    match options {
        None => Ok(RenderOptions::default()),
        Some(given) => {
            RenderOptions::deserialize_named(&mut pythonize::Depythonizer::from_object(given))
                .map_err(PyValueError::new_err)
        }
    }
}

/// `camera` with the entries of `changes` (look_from, look_at, up, vfov, aperture,
/// focus_distance, ortho_height) put in.
fn moved_camera(
    mut camera: canopy_render::camera::CameraSpec,
    changes: &Bound<'_, PyDict>,
) -> PyResult<canopy_render::camera::CameraSpec> {
    let bad =
        |key: &str, what: &str| PyValueError::new_err(format!("camera: `{key}` must be {what}"));
    for (key, value) in changes.iter() {
        let key: String = key.extract()?;
        let point = || -> PyResult<glam::Vec3> {
            let v: [f32; 3] = value.extract().map_err(|_| bad(&key, "three numbers"))?;
            Ok(v.into())
        };
        let number = || -> PyResult<f32> { value.extract().map_err(|_| bad(&key, "a number")) };
        match key.as_str() {
            "look_from" => camera.look_from = point()?,
            "look_at" => camera.look_at = point()?,
            "up" => camera.up = point()?,
            "vfov" => camera.vfov = number()?,
            "aperture" => camera.aperture = number()?,
            "focus_distance" => {
                camera.focus_distance = match value.is_none() {
                    true => None,
                    false => Some(number()?),
                }
            }
            "ortho_height" => {
                camera.ortho_height = match value.is_none() {
                    true => None,
                    false => Some(number()?),
                }
            }
            _ => {
                return Err(PyValueError::new_err(format!(
                    "camera: no `{key}` (it takes look_from, look_at, up, vfov, aperture, focus_distance, ortho_height)"
                )))
            }
        }
    }
    Ok(camera)
}

/// A scene to render: a built-in name, a file, or a `Scene` built in Python.
#[derive(FromPyObject)]
pub enum SceneArg<'py> {
    Built(Bound<'py, PyScene>),
    Named(String),
}

fn job_error(e: JobError) -> PyErr {
    use canopy_render::checkpoint::CheckpointError;
    match e {
        JobError::Invalid(_) => PyValueError::new_err(e.to_string()),
        JobError::Scene(e) => scene_error(e),
        JobError::Checkpoint(CheckpointError::Read { .. } | CheckpointError::Write { .. }) => {
            PyOSError::new_err(e.to_string())
        }
        JobError::Checkpoint(_) => PyValueError::new_err(e.to_string()),
        JobError::Threads { .. } | JobError::Gpu(_) => PyRuntimeError::new_err(e.to_string()),
    }
}

/// A render's progress and control from Python: the progress callback after each pass,
/// Ctrl-C (and any exception the callback raises) stopping the render after the pass in
/// flight, warnings through Python's `warnings`.
struct PyObserver {
    progress: Option<Py<PyAny>>,
    /// The exception to raise once the render has stopped (and saved its checkpoint).
    error: Option<PyErr>,
}

impl Observer for PyObserver {
    fn keep_going(&mut self) -> bool {
        if self.error.is_none() {
            self.error = Python::attach(|py| py.check_signals().err());
        }
        self.error.is_none()
    }

    fn pass_done(&mut self, samples: u32, spp: u32) {
        if let (Some(callback), None) = (&self.progress, &self.error) {
            self.error = Python::attach(|py| callback.call1(py, (samples, spp)).err());
        }
    }

    fn warning(&mut self, message: String) {
        Python::attach(|py| {
            let category = py.get_type::<pyo3::exceptions::PyRuntimeWarning>();
            let message = std::ffi::CString::new(message).unwrap_or_default();
            if let Err(e) = PyErr::warn(py, &category, &message, 1) {
                self.error.get_or_insert(e);
            }
        });
    }
}

/// The vertices (V, 3) float32 and triangles (F, 3) int64 of an OBJ or PLY file,
/// polygons fan-triangulated, as canopy's scenes load them.
#[pyfunction]
#[allow(clippy::type_complexity)]
pub fn load_mesh<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
) -> PyResult<(Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<i64>>)> {
    let file = path.display().to_string();
    let format =
        MeshFormat::from_path(&file).map_err(|e| PyValueError::new_err(format!("{file}: {e}")))?;
    let limit = canopy_render::files::available_memory().unwrap_or(u64::MAX) / 8;
    let mesh = py.detach(|| {
        let bytes = canopy_render::files::read_regular_file(&path, limit)
            .map_err(|e| PyOSError::new_err(format!("{file}: {e}")))?;
        parse_mesh(&bytes, format).map_err(|e| PyValueError::new_err(format!("{file}: {e}")))
    })?;
    let vertices: Vec<f32> = mesh.positions.iter().flat_map(|p| p.to_array()).collect();
    let faces: Vec<i64> = mesh
        .triangles
        .iter()
        .flatten()
        .map(|&i| i64::from(i))
        .collect();
    Ok((
        rows_of_three(vertices).into_pyarray(py),
        rows_of_three(faces).into_pyarray(py),
    ))
}

fn rows_of_three<T>(values: Vec<T>) -> Array2<T> {
    Array2::from_shape_vec((values.len() / 3, 3), values).expect("rows of 3")
}

/// Reads a PNG (8-bit values / 255, as stored) or EXR (linear float) image as a float32
/// array of shape (height, width, 3). Only regular files are read, and the size an image
/// declares is checked against the memory available before it is decoded.
#[pyfunction]
pub fn read_image<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let (w, h, rgb) = py
        .detach(|| canopy_render::output::read_image(&path))
        .map_err(PyOSError::new_err)?;
    let array = numpy::ndarray::Array3::from_shape_vec((h as usize, w as usize, 3), rgb)
        .expect("height x width x 3 values");
    Ok(array.into_pyarray(py))
}

/// Writes a linear (height, width, 3) float32 image to `path` as `canopy render` writes
/// its output: `.png` (8-bit sRGB) or `.exr` (linear float), atomically (a failed write
/// leaves no file).
#[pyfunction]
pub fn write_image(
    py: Python<'_>,
    path: std::path::PathBuf,
    image: numpy::PyReadonlyArray3<'_, f32>,
) -> PyResult<()> {
    use numpy::PyUntypedArrayMethods;
    let shape = image.shape();
    if shape[2] != 3 || shape[0] == 0 || shape[1] == 0 {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "image must have shape (height, width, 3), not {shape:?}"
        )));
    }
    let values = image.as_slice().map_err(|_| {
        pyo3::exceptions::PyValueError::new_err("image must be C-contiguous and aligned")
    })?;
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "image value {i} is not finite ({})",
            values[i]
        )));
    }
    let film = canopy_render::film::Film {
        width: shape[1] as u32,
        height: shape[0] as u32,
        pixels: values
            .chunks_exact(3)
            .map(|p| glam::Vec3::new(p[0], p[1], p[2]))
            .collect(),
    };
    py.detach(|| canopy_render::output::write_image(&film, &path))
        .map_err(|e| PyOSError::new_err(e.to_string()))
}
