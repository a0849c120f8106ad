//! `canopy.Bvh`: a BVH over a triangle mesh or over boxes, and batched ray queries.

use crate::arrays;
use crate::pools;
use canopy_bvh::Ray;
use canopy_bvh::{Aabb, BuildParams, BvhWidth, SahCosts};
use canopy_render::geometry::{Cuboid, Shape, Triangle};
use canopy_render::scene::Primitive;
use canopy_render::{Accel, AccelKind};
use glam::Vec3;
use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;
use std::time::Instant;

/// Rays per parallel task: enough to amortise scheduling, few enough to balance.
const CHUNK: usize = 1024;

/// A BVH over triangles (a mesh) or boxes, built once, queried with batches of rays.
#[pyclass(frozen, module = "canopy._canopy")]
pub struct Bvh {
    primitives: Vec<Primitive>,
    boxes: Vec<Aabb>,
    accel: Accel,
    /// A builder, or `none` (brute force: the plain loop every tree is checked against).
    kind: AccelKind,
    width: BvhWidth,
    params: BuildParams,
    build_ms: f64,
}

/// The build options every constructor takes.
struct Options {
    kind: AccelKind,
    width: BvhWidth,
    params: BuildParams,
    threads: Option<usize>,
}

#[allow(clippy::too_many_arguments)]
fn options(
    builder: &str,
    width: u32,
    max_leaf_size: Option<u32>,
    sah_traversal: Option<f32>,
    sah_intersection: Option<f32>,
    ploc_radius: Option<u32>,
    threads: Option<usize>,
) -> PyResult<Options> {
    let kind: AccelKind = builder
        .parse()
        .map_err(|e: canopy_bvh::UnknownBuilder| PyValueError::new_err(e.to_string()))?;
    let width: BvhWidth = width.to_string().parse().map_err(PyValueError::new_err)?;
    let d = BuildParams::default();
    let params = BuildParams {
        max_leaf_size: max_leaf_size.unwrap_or(d.max_leaf_size),
        sah: SahCosts {
            traversal: sah_traversal.unwrap_or(d.sah.traversal),
            intersection: sah_intersection.unwrap_or(d.sah.intersection),
        },
        ploc_radius: ploc_radius.unwrap_or(d.ploc_radius),
        ..d
    };
    params
        .check()
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(Options {
        kind,
        width,
        params,
        threads,
    })
}

impl Bvh {
    fn build(py: Python<'_>, primitives: Vec<Primitive>, o: Options) -> PyResult<Self> {
        if primitives.is_empty() {
            return Err(PyValueError::new_err(
                "a BVH needs at least one primitive (the input is empty)",
            ));
        }
        let (kind, width, params) = (o.kind, o.width, o.params);
        py.detach(|| {
            pools::install(o.threads, || {
                let start = Instant::now();
                let accel = Accel::build(kind, width, &primitives, &params);
                let build_ms = start.elapsed().as_secs_f64() * 1e3;
                let boxes = primitives.iter().map(|p| p.shape.bounds()).collect();
                Bvh {
                    primitives,
                    boxes,
                    accel,
                    kind,
                    width,
                    params,
                    build_ms,
                }
            })
        })
    }

    fn name(&self) -> String {
        self.kind.to_string()
    }
}

/// The rays of a batch, checked.
fn rays(
    origins: &PyReadonlyArray2<'_, f32>,
    directions: &PyReadonlyArray2<'_, f32>,
    tnear: &PyReadonlyArray1<'_, f32>,
    tfar: &PyReadonlyArray1<'_, f32>,
) -> PyResult<Vec<Ray>> {
    let o = arrays::points("origins", origins)?;
    let d = arrays::points("directions", directions)?;
    if o.len() != d.len() {
        return Err(PyValueError::new_err(format!(
            "origins and directions must have the same number of rows, not {} and {}",
            o.len(),
            d.len()
        )));
    }
    let near = arrays::per_ray("tnear", tnear, o.len())?;
    let far = arrays::per_ray("tfar", tfar, o.len())?;
    Ok((0..o.len())
        .map(|i| Ray::new(Vec3::from(o[i]), Vec3::from(d[i]), near[i], far[i]))
        .collect())
}

#[pymethods]
impl Bvh {
    /// See `canopy.Bvh` in the Python package for the documentation.
    #[new]
    #[pyo3(signature = (vertices, faces, builder="binned-sah", width=8, max_leaf_size=None,
        sah_traversal=None, sah_intersection=None, ploc_radius=None, threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        vertices: PyReadonlyArray2<'_, f32>,
        faces: PyReadonlyArray2<'_, i64>,
        builder: &str,
        width: u32,
        max_leaf_size: Option<u32>,
        sah_traversal: Option<f32>,
        sah_intersection: Option<f32>,
        ploc_radius: Option<u32>,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        let o = options(
            builder,
            width,
            max_leaf_size,
            sah_traversal,
            sah_intersection,
            ploc_radius,
            threads,
        )?;
        let v = arrays::points("vertices", &vertices)?;
        let f = arrays::faces(&faces, v.len())?;
        let primitives = f
            .iter()
            .map(|&[a, b, c]| Primitive {
                shape: Shape::Triangle(Triangle::new(
                    Vec3::from(v[a as usize]),
                    Vec3::from(v[b as usize]),
                    Vec3::from(v[c as usize]),
                )),
                material: 0,
            })
            .collect();
        Self::build(py, primitives, o)
    }

    /// See `canopy.Bvh.from_boxes` in the Python package.
    #[staticmethod]
    #[pyo3(signature = (boxes, builder="binned-sah", width=8, max_leaf_size=None,
        sah_traversal=None, sah_intersection=None, ploc_radius=None, threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn from_boxes(
        py: Python<'_>,
        boxes: PyReadonlyArray3<'_, f32>,
        builder: &str,
        width: u32,
        max_leaf_size: Option<u32>,
        sah_traversal: Option<f32>,
        sah_intersection: Option<f32>,
        ploc_radius: Option<u32>,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        let o = options(
            builder,
            width,
            max_leaf_size,
            sah_traversal,
            sah_intersection,
            ploc_radius,
            threads,
        )?;
        let primitives = arrays::boxes(&boxes)?
            .iter()
            .map(|b| Primitive {
                shape: Shape::Cuboid(Cuboid::axis_aligned(
                    Vec3::new(b[0], b[1], b[2]),
                    Vec3::new(b[3], b[4], b[5]),
                )),
                material: 0,
            })
            .collect();
        Self::build(py, primitives, o)
    }

    #[getter]
    fn primitive_count(&self) -> usize {
        self.primitives.len()
    }

    #[getter]
    fn builder(&self) -> String {
        self.name()
    }

    #[getter]
    fn width(&self) -> u32 {
        self.width.children()
    }

    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("builder", self.name())?;
        d.set_item("primitives", self.primitives.len())?;
        d.set_item("build_ms", self.build_ms)?;
        let Some(tree) = self.accel.tree() else {
            return Ok(d);
        };
        let s = tree.stats(&self.params.sah);
        d.set_item("width", self.width.children())?;
        d.set_item("sah_cost", s.sah_cost)?;
        d.set_item("nodes", s.nodes)?;
        d.set_item("leaves", s.leaves)?;
        d.set_item("max_depth", s.max_depth)?;
        d.set_item("max_leaf_size", s.max_leaf_size)?;
        d.set_item("mean_leaf_size", s.mean_leaf_size(self.primitives.len()))?;
        d.set_item("memory_bytes", s.memory_bytes)?;
        Ok(d)
    }

    fn validate(&self) -> PyResult<()> {
        match self.accel.tree() {
            Some(tree) => tree
                .validate(&self.boxes)
                .map_err(|e| PyValueError::new_err(format!("invalid BVH: {e}"))),
            None => Ok(()),
        }
    }

    /// Closest hits: (t, prim, uv) with t = inf, prim = -1, uv = 0 on a miss.
    #[pyo3(signature = (origins, directions, tnear, tfar, threads=None))]
    #[allow(clippy::type_complexity)]
    fn intersect<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'py, f32>,
        directions: PyReadonlyArray2<'py, f32>,
        tnear: PyReadonlyArray1<'py, f32>,
        tfar: PyReadonlyArray1<'py, f32>,
        threads: Option<usize>,
    ) -> PyResult<(
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray2<f32>>,
    )> {
        let rays = rays(&origins, &directions, &tnear, &tfar)?;
        let n = rays.len();
        let mut t = vec![f32::INFINITY; n];
        let mut prim = vec![-1i64; n];
        let mut uv = vec![[0.0f32; 2]; n];
        py.detach(|| {
            pools::install(threads, || {
                t.par_chunks_mut(CHUNK)
                    .zip(prim.par_chunks_mut(CHUNK))
                    .zip(uv.par_chunks_mut(CHUNK))
                    .zip(rays.par_chunks(CHUNK))
                    .for_each(|(((t, prim), uv), rays)| {
                        for (i, ray) in rays.iter().enumerate() {
                            if let Some(hit) = self.accel.intersect(&self.primitives, ray) {
                                t[i] = hit.t;
                                prim[i] = hit.prim as i64;
                                uv[i] = [hit.u, hit.v];
                            }
                        }
                    })
            })
        })?;
        let uv = numpy::ndarray::Array2::from_shape_vec((n, 2), uv.into_flattened())
            .expect("n rows of 2");
        Ok((
            PyArray1::from_vec(py, t),
            PyArray1::from_vec(py, prim),
            PyArray2::from_owned_array(py, uv),
        ))
    }

    /// Whether anything lies on each ray within [tnear, tfar].
    #[pyo3(signature = (origins, directions, tnear, tfar, threads=None))]
    fn occluded<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'py, f32>,
        directions: PyReadonlyArray2<'py, f32>,
        tnear: PyReadonlyArray1<'py, f32>,
        tfar: PyReadonlyArray1<'py, f32>,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let rays = rays(&origins, &directions, &tnear, &tfar)?;
        let mut blocked = vec![false; rays.len()];
        py.detach(|| {
            pools::install(threads, || {
                blocked
                    .par_chunks_mut(CHUNK)
                    .zip(rays.par_chunks(CHUNK))
                    .for_each(|(out, rays)| {
                        for (o, ray) in out.iter_mut().zip(rays) {
                            *o = self.accel.occluded(&self.primitives, ray);
                        }
                    })
            })
        })?;
        Ok(PyArray1::from_vec(py, blocked))
    }

    fn __repr__(&self) -> String {
        format!(
            "Bvh({} primitives, builder={:?}, width={})",
            self.primitives.len(),
            self.name(),
            self.width.children()
        )
    }
}
