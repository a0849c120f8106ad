//! `canopy_rt._canopy`, the native half of the Python package `canopy_rt` (the Python
//! half, in `python/canopy_rt`, converts arguments and documents them). Every call that does real
//! work releases the GIL and runs on a rayon pool of the requested size.

mod arrays;
mod bvh;
mod contents;
mod denoise;
mod outputs;
mod pools;
mod ray_scene;
mod render;
mod scene;
mod view;

use pyo3::prelude::*;

/// The names of the BVH builders, in the order `canopy bvh` lists them.
#[pyfunction]
fn builders() -> Vec<&'static str> {
    canopy_bvh::Builder::ALL.iter().map(|b| b.name()).collect()
}

/// The names of the built-in scenes, in the order `canopy scenes` lists them.
#[pyfunction]
fn scenes() -> Vec<&'static str> {
    canopy_render::builtin::BUILTIN_SCENES
        .iter()
        .map(|s| s.name)
        .collect()
}

/// The GPU adapters wgpu finds, described (empty when there is none).
#[pyfunction]
fn devices(py: Python<'_>) -> Vec<String> {
    py.detach(canopy_gpu::adapters)
}

#[pymodule]
fn _canopy(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<bvh::Bvh>()?;
    m.add_class::<render::SceneInfo>()?;
    m.add_class::<scene::PyScene>()?;
    m.add_class::<ray_scene::RayScene>()?;
    m.add_class::<view::PyViewer>()?;
    m.add_function(wrap_pyfunction!(builders, m)?)?;
    m.add_function(wrap_pyfunction!(scenes, m)?)?;
    m.add_function(wrap_pyfunction!(devices, m)?)?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    m.add_function(wrap_pyfunction!(denoise::denoise, m)?)?;
    m.add_function(wrap_pyfunction!(render::load_scene, m)?)?;
    m.add_function(wrap_pyfunction!(render::read_image, m)?)?;
    m.add_function(wrap_pyfunction!(render::write_image, m)?)?;
    m.add_function(wrap_pyfunction!(outputs::check_output, m)?)?;
    m.add_function(wrap_pyfunction!(outputs::write_file, m)?)?;
    m.add_function(wrap_pyfunction!(render::load_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(view::view, m)?)?;
    m.add_function(wrap_pyfunction!(scene::eval_material, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // The names of canopy's render options (one type, `canopy_job::RenderOptions`):
    // `render()`, `view()` and the Ray driver take them as keywords by these names.
    m.add(
        "RENDER_OPTIONS",
        canopy_job::RenderOptions::names().to_vec(),
    )?;
    Ok(())
}
