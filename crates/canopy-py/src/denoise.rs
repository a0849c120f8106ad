//! `canopy_rt.denoise` and the AOVs `canopy_rt.render` returns.

use canopy_job::{DenoiseError, Oidn};
use canopy_render::{Aov, AovBuffers, Region};
use numpy::ndarray::{Array2, Array3};
use numpy::{PyArray3, PyReadonlyArray3, PyUntypedArrayMethods, ToPyArray};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// OIDN, from `CANOPY_OIDN`, the folders `oidn_paths` (the Python side passes an
/// installed pyoidn package's), canopy's data folder or the system: a Python error that
/// says how to install it otherwise.
pub fn load_oidn(oidn_paths: &[PathBuf]) -> PyResult<Oidn> {
    Oidn::load(oidn_paths).map_err(denoise_error)
}

pub fn denoise_error(e: DenoiseError) -> PyErr {
    match e {
        DenoiseError::Input(_) => PyValueError::new_err(e.to_string()),
        _ => PyRuntimeError::new_err(e.to_string()),
    }
}

/// The denoised `color` (float32 (height, width, 3)), guided by `albedo` and `normal` of
/// the same shape where given (a normal needs an albedo).
#[pyfunction]
#[pyo3(signature = (color, albedo=None, normal=None, threads=None, prefilter=false, oidn_paths=Vec::new()))]
pub fn denoise<'py>(
    py: Python<'py>,
    color: PyReadonlyArray3<'py, f32>,
    albedo: Option<PyReadonlyArray3<'py, f32>>,
    normal: Option<PyReadonlyArray3<'py, f32>>,
    threads: Option<usize>,
    prefilter: bool,
    oidn_paths: Vec<PathBuf>,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let shape = color.shape().to_vec();
    let (height, width) = (shape[0], shape[1]);
    if shape[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "color must have shape (height, width, 3), not {shape:?}"
        )));
    }
    let flat = |name: &str, image: &PyReadonlyArray3<'py, f32>| -> PyResult<Vec<f32>> {
        if image.shape() != shape.as_slice() {
            return Err(PyValueError::new_err(format!(
                "{name} has shape {:?}, not the colour's {shape:?}",
                image.shape()
            )));
        }
        Ok(image.as_array().iter().copied().collect())
    };
    let color = flat("color", &color)?;
    let albedo = albedo.as_ref().map(|a| flat("albedo", a)).transpose()?;
    let normal = normal.as_ref().map(|n| flat("normal", n)).transpose()?;
    let oidn = load_oidn(&oidn_paths)?;
    let images = canopy_denoise::Images {
        width,
        height,
        color: &color,
        albedo: albedo.as_deref(),
        normal: normal.as_deref(),
    };
    let options = canopy_denoise::Options { threads, prefilter };
    let clean = py
        .detach(|| oidn.denoise(&images, &options))
        .map_err(denoise_error)?;
    let clean = Array3::from_shape_vec((height, width, 3), clean).expect("the input's shape");
    Ok(clean.to_pyarray(py))
}

/// The AOV images of a render over `region` as arrays by name: `albedo`, `normal`,
/// `position` (height, width, 3), `depth` (height, width), and for `id` the uint32
/// `instance` and `primitive` (height, width).
pub fn aov_arrays<'py>(
    py: Python<'py>,
    aovs: &AovBuffers,
    region: Region,
) -> PyResult<Bound<'py, PyDict>> {
    let (h, w) = (region.height as usize, region.width as usize);
    let vec3 = |v: &[glam::Vec3]| {
        let flat: Vec<f32> = v.iter().flat_map(|p| p.to_array()).collect();
        Array3::from_shape_vec((h, w, 3), flat).expect("a value a pixel")
    };
    let dict = PyDict::new(py);
    for aov in aovs.set.iter() {
        match aov {
            Aov::Albedo => dict.set_item("albedo", vec3(&aovs.albedo).to_pyarray(py))?,
            Aov::Normal => dict.set_item("normal", vec3(&aovs.normal).to_pyarray(py))?,
            Aov::Position => dict.set_item("position", vec3(&aovs.position).to_pyarray(py))?,
            Aov::Depth => {
                let depth = Array2::from_shape_vec((h, w), aovs.depth.clone());
                dict.set_item("depth", depth.expect("a value a pixel").to_pyarray(py))?
            }
            Aov::Id => {
                for (name, ids) in [("instance", &aovs.instance), ("primitive", &aovs.primitive)] {
                    let ids = Array2::from_shape_vec((h, w), ids.clone());
                    dict.set_item(name, ids.expect("a value a pixel").to_pyarray(py))?;
                }
            }
        }
    }
    Ok(dict)
}
