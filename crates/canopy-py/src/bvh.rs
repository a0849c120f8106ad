//! `canopy.Bvh`: a BVH over a triangle mesh or over boxes, and batched ray queries.

use crate::arrays;
use crate::pools;
use canopy_bvh::{Aabb, BuildParams, BvhWidth, SahCosts, TriangleTest};
use canopy_bvh::{Coherence, Hit, Ray, RayBatch, RayOrder, RayQuery, ALL_MASKS};
use canopy_render::geometry::{Cuboid, Shape, Triangle};
use canopy_render::scene::Primitive;
use canopy_render::{Accel, AccelKind};
use glam::Vec3;
use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;
use std::time::Instant;

/// Rays per parallel task: enough to amortise scheduling, few enough to balance.
const CHUNK: usize = 1024;

/// A BVH over triangles (a mesh) or boxes, built once, queried with batches of rays.
#[pyclass(frozen, module = "canopy_rt._canopy")]
pub struct Bvh {
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
    optimize: Option<canopy_bvh::OptimizeBudget>,
    width: BvhWidth,
    params: BuildParams,
    threads: Option<usize>,
    triangle_test: TriangleTest,
}

#[allow(clippy::too_many_arguments)]
fn options(
    builder: &str,
    width: u32,
    max_leaf_size: Option<u32>,
    sah_traversal: Option<f32>,
    sah_intersection: Option<f32>,
    ploc_radius: Option<u32>,
    max_duplication: Option<f32>,
    optimize: Option<f64>,
    threads: Option<usize>,
    triangles: &str,
) -> PyResult<Options> {
    let triangle_test = match triangles {
        "watertight" => TriangleTest::Watertight,
        "fast" => TriangleTest::Fast,
        other => {
            return Err(PyValueError::new_err(format!(
                "triangles must be 'watertight' or 'fast', not {other:?}"
            )))
        }
    };
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
        max_duplication: max_duplication.unwrap_or(d.max_duplication),
        ..d
    };
    params
        .check()
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let optimize = match optimize {
        None => None,
        Some(s) if s > 0.0 && s <= 3600.0 => Some(canopy_bvh::OptimizeBudget::Time(
            std::time::Duration::from_secs_f64(s),
        )),
        Some(s) => {
            return Err(PyValueError::new_err(format!(
                "optimize must be a time in seconds in (0, 3600], not {s}"
            )))
        }
    };
    Ok(Options {
        kind,
        optimize,
        width,
        params,
        threads,
        triangle_test,
    })
}

impl Bvh {
    fn build(py: Python<'_>, primitives: Vec<Primitive>, o: Options) -> PyResult<Self> {
        if primitives.is_empty() {
            return Err(PyValueError::new_err(
                "a BVH needs at least one primitive (the input is empty)",
            ));
        }
        let (kind, width, params, optimize) = (o.kind, o.width, o.params, o.optimize);
        let triangle_test = o.triangle_test;
        py.detach(|| {
            pools::install(o.threads, || {
                let start = Instant::now();
                let accel =
                    Accel::build_optimized(kind, width, &primitives.into(), &params, optimize)
                        .with_triangle_test(triangle_test);
                let build_ms = start.elapsed().as_secs_f64() * 1e3;
                Bvh {
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

    /// The order to trace `batch` in, if not the caller's ([`Accel::orders_batches`]).
    fn batch_order(&self, batch: &Batch<'_>) -> Option<RayOrder> {
        self.accel
            .orders_batches()
            .then(|| RayOrder::by_origin(batch.len(), |i| Vec3::from(batch.origins[i])))
            .flatten()
    }
}

/// `tnear` or `tfar`: one value for every ray, or one each.
#[derive(Clone, Copy)]
pub(crate) enum PerRay<'a> {
    All(f32),
    Each(&'a [f32]),
}

impl PerRay<'_> {
    #[inline]
    fn get(self, i: usize) -> f32 {
        match self {
            PerRay::All(v) => v,
            PerRay::Each(values) => values[i],
        }
    }
}

/// Writes ray `i`'s closest hit into the output arrays (t = inf, prim = -1, uv = 0 on a
/// miss).
#[inline]
fn write_hit(t: &mut [f32], prim: &mut [i64], uv: &mut [f32], i: usize, hit: Option<Hit>) {
    match hit {
        Some(hit) => {
            t[i] = hit.t;
            prim[i] = hit.prim as i64;
            uv[2 * i] = hit.u;
            uv[2 * i + 1] = hit.v;
        }
        None => {
            t[i] = f32::INFINITY;
            prim[i] = -1;
            uv[2 * i] = 0.0;
            uv[2 * i + 1] = 0.0;
        }
    }
}

/// A batch of rays as the caller's arrays, checked; rays are made from them on the fly,
/// in parallel.
#[derive(Clone, Copy)]
pub(crate) struct Batch<'a> {
    origins: &'a [[f32; 3]],
    directions: &'a [[f32; 3]],
    tnear: PerRay<'a>,
    tfar: PerRay<'a>,
}

impl Batch<'_> {
    pub(crate) fn len(&self) -> usize {
        self.origins.len()
    }

    #[inline]
    pub(crate) fn ray(&self, i: usize) -> Ray {
        Ray::new(
            Vec3::from(self.origins[i]),
            Vec3::from(self.directions[i]),
            self.tnear.get(i),
            self.tfar.get(i),
        )
    }
}

fn per_ray<'a, 'py>(
    name: &str,
    value: &'a Bound<'py, PyAny>,
    array: &'a mut Option<PyReadonlyArray1<'py, f32>>,
    n: usize,
) -> PyResult<PerRay<'a>> {
    if let Ok(v) = value.extract::<f32>() {
        if v.is_nan() || v < 0.0 {
            return Err(PyValueError::new_err(format!(
                "{name} = {v} must be >= 0 and not NaN"
            )));
        }
        return Ok(PerRay::All(v));
    }
    *array = Some(value.extract()?);
    let values = arrays::per_ray(name, array.as_ref().expect("just set"), n)?;
    Ok(PerRay::Each(values))
}

/// The checked batch of a query's arguments (`near` and `far` hold per-ray arrays).
pub(crate) fn batch<'a, 'py>(
    origins: &'a PyReadonlyArray2<'py, f32>,
    directions: &'a PyReadonlyArray2<'py, f32>,
    tnear: &'a Bound<'py, PyAny>,
    near: &'a mut Option<PyReadonlyArray1<'py, f32>>,
    tfar: &'a Bound<'py, PyAny>,
    far: &'a mut Option<PyReadonlyArray1<'py, f32>>,
) -> PyResult<Batch<'a>> {
    let o = arrays::points("origins", origins)?;
    let d = arrays::points("directions", directions)?;
    if o.len() != d.len() {
        return Err(PyValueError::new_err(format!(
            "origins and directions must have the same number of rows, not {} and {}",
            o.len(),
            d.len()
        )));
    }
    Ok(Batch {
        origins: o,
        directions: d,
        tnear: per_ray("tnear", tnear, near, o.len())?,
        tfar: per_ray("tfar", tfar, far, o.len())?,
    })
}

#[pymethods]
impl Bvh {
    /// See `canopy.Bvh` in the Python package for the documentation.
    #[new]
    #[pyo3(signature = (vertices, faces, builder="binned-sah", width=8, max_leaf_size=None,
        sah_traversal=None, sah_intersection=None, ploc_radius=None, max_duplication=None,
        optimize=None, threads=None, triangles="watertight"))]
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
        max_duplication: Option<f32>,
        optimize: Option<f64>,
        threads: Option<usize>,
        triangles: &str,
    ) -> PyResult<Self> {
        let o = options(
            builder,
            width,
            max_leaf_size,
            sah_traversal,
            sah_intersection,
            ploc_radius,
            max_duplication,
            optimize,
            threads,
            triangles,
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
        sah_traversal=None, sah_intersection=None, ploc_radius=None, max_duplication=None,
        optimize=None, threads=None, triangles="watertight"))]
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
        max_duplication: Option<f32>,
        optimize: Option<f64>,
        threads: Option<usize>,
        triangles: &str,
    ) -> PyResult<Self> {
        let o = options(
            builder,
            width,
            max_leaf_size,
            sah_traversal,
            sah_intersection,
            ploc_radius,
            max_duplication,
            optimize,
            threads,
            triangles,
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

    /// The primitives, for pickling: ("triangles", (F, 3, 3) vertices of each) or
    /// ("boxes", (N, 2, 3) min and max corners), exactly as built.
    fn primitives<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(&'static str, Bound<'py, PyArray3<f32>>)> {
        let primitives = self.accel.primitives();
        let (kind, corners) = match primitives.first().map(|p| &p.shape) {
            Some(Shape::Cuboid(_)) => ("boxes", 2),
            _ => ("triangles", 3),
        };
        let mut flat = Vec::with_capacity(primitives.len() * corners * 3);
        for p in primitives {
            match &p.shape {
                Shape::Triangle(t) => flat.extend(t.v.iter().flat_map(|v| v.to_array())),
                Shape::Cuboid(c) => {
                    flat.extend([c.local.min, c.local.max].iter().flat_map(|v| v.to_array()))
                }
                Shape::Sphere(_) => {
                    return Err(PyValueError::new_err("a Bvh holds triangles or boxes only"))
                }
            }
        }
        let array = PyArray1::from_vec(py, flat).reshape([primitives.len(), corners, 3])?;
        Ok((kind, array))
    }

    #[getter]
    fn primitive_count(&self) -> usize {
        self.accel.primitives().len()
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
        d.set_item("primitives", self.accel.primitives().len())?;
        d.set_item("build_ms", self.build_ms)?;
        let triangles = match self.accel.triangle_test() {
            TriangleTest::Watertight => "watertight",
            TriangleTest::Fast => "fast",
        };
        d.set_item("triangles", triangles)?;
        let Some(tree) = self.accel.tree() else {
            return Ok(d);
        };
        let s = tree.stats(&self.params.sah);
        d.set_item("width", self.width.children())?;
        // Wide trees test their nodes with the best SIMD kernel the CPU has.
        let isa = match self.width {
            BvhWidth::Two => "scalar",
            _ => canopy_bvh::Isa::best().name(),
        };
        d.set_item("isa", isa)?;
        d.set_item("sah_cost", s.sah_cost)?;
        d.set_item("nodes", s.nodes)?;
        d.set_item("leaves", s.leaves)?;
        d.set_item("max_depth", s.max_depth)?;
        d.set_item("max_leaf_size", s.max_leaf_size)?;
        d.set_item("mean_leaf_size", s.mean_leaf_size())?;
        d.set_item("references", s.references)?;
        d.set_item("memory_bytes", s.memory_bytes)?;
        Ok(d)
    }

    /// EPO (effective parallel overlap) of the tree, with the scene's area normalised to
    /// 1; 0 for brute force.
    fn epo(&self, py: Python<'_>) -> f32 {
        let Some(tree) = self.accel.tree() else {
            return 0.0;
        };
        py.detach(|| {
            canopy_bvh::epo(tree.view(), &self.params.sah, |prim, region| {
                self.accel.primitives()[prim as usize]
                    .shape
                    .area_in_box(region)
                    .unwrap_or(0.0)
            })
        })
    }

    fn validate(&self) -> PyResult<()> {
        match self.accel.tree() {
            Some(tree) => tree
                .validate(
                    &self
                        .accel
                        .primitives()
                        .iter()
                        .map(|p| p.shape.bounds())
                        .collect::<Vec<Aabb>>(),
                )
                .map_err(|e| PyValueError::new_err(format!("invalid BVH: {e}"))),
            None => Ok(()),
        }
    }

    /// Closest hits: (t, prim, uv) with t = inf, prim = -1, uv = 0 on a miss. `coherent`
    /// rays (neighbours start near each other and run alike) are traced in packets.
    #[pyo3(signature = (origins, directions, tnear, tfar, threads=None, coherent=false))]
    #[allow(clippy::type_complexity, clippy::too_many_arguments)]
    fn intersect<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'py, f32>,
        directions: PyReadonlyArray2<'py, f32>,
        tnear: Bound<'py, PyAny>,
        tfar: Bound<'py, PyAny>,
        threads: Option<usize>,
        coherent: bool,
    ) -> PyResult<(
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray2<f32>>,
    )> {
        let (mut near, mut far) = (None, None);
        let batch = batch(&origins, &directions, &tnear, &mut near, &tfar, &mut far)?;
        let n = batch.len();
        // Left uninitialised (zeroing 20 bytes a ray cost more than a tenth of a primary
        // ray's trace): `write_hit` writes every element of every ray below.
        // SAFETY: the elements are plain numbers, written before the arrays are returned
        // and never read before.
        let (t_out, prim_out, uv_out) = unsafe {
            (
                PyArray1::<f32>::new(py, n, false),
                PyArray1::<i64>::new(py, n, false),
                PyArray2::<f32>::new(py, [n, 2], false),
            )
        };
        // SAFETY: the arrays were just made here and nothing else refers to them yet.
        let (t, prim, uv) = unsafe {
            (
                t_out.as_slice_mut().expect("contiguous"),
                prim_out.as_slice_mut().expect("contiguous"),
                uv_out.as_slice_mut().expect("contiguous"),
            )
        };
        py.detach(|| {
            pools::install(threads, || {
                // Scattered rays (from surfaces, in any order) are traced by where they
                // start; coherent ones in their own order, in packets.
                let Some(order) = self.batch_order(&batch).filter(|_| !coherent) else {
                    return t
                        .par_chunks_mut(CHUNK)
                        .zip(prim.par_chunks_mut(CHUNK))
                        .zip(uv.par_chunks_mut(2 * CHUNK))
                        .enumerate()
                        .for_each(|(chunk, ((t, prim), uv))| {
                            let (first, count) = (chunk * CHUNK, t.len());
                            let answer =
                                |i: usize, hit: Option<Hit>| write_hit(t, prim, uv, i, hit);
                            let rays = |i: usize| batch.ray(first + i);
                            let batch = RayBatch::new(count).with(Coherence::hint(coherent));
                            self.accel.closest_hits(batch, rays, answer, &mut ())
                        });
                };
                let traced = order.trace(
                    CHUNK,
                    |i| batch.ray(i),
                    |rays, out| {
                        let answer = |i: usize, hit: Option<Hit>| out[i] = hit;
                        self.accel
                            .intersect_each(rays.len(), ALL_MASKS, |i| rays[i], answer)
                    },
                );
                let ranks = order.ranks();
                t.par_chunks_mut(CHUNK)
                    .zip(prim.par_chunks_mut(CHUNK))
                    .zip(uv.par_chunks_mut(2 * CHUNK))
                    .enumerate()
                    .for_each(|(chunk, ((t, prim), uv))| {
                        for i in 0..t.len() {
                            let hit = traced[ranks[chunk * CHUNK + i] as usize];
                            write_hit(t, prim, uv, i, hit);
                        }
                    })
            })
        })?;
        Ok((t_out, prim_out, uv_out))
    }

    /// Whether anything lies on each ray within [tnear, tfar]; `coherent` as for
    /// `intersect`.
    #[pyo3(signature = (origins, directions, tnear, tfar, threads=None, coherent=false))]
    #[allow(clippy::too_many_arguments)]
    fn occluded<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'py, f32>,
        directions: PyReadonlyArray2<'py, f32>,
        tnear: Bound<'py, PyAny>,
        tfar: Bound<'py, PyAny>,
        threads: Option<usize>,
        coherent: bool,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let (mut near, mut far) = (None, None);
        let batch = batch(&origins, &directions, &tnear, &mut near, &tfar, &mut far)?;
        let out = PyArray1::<bool>::zeros(py, batch.len(), false);
        // SAFETY: the array was just made here and nothing else refers to it yet.
        let blocked = unsafe { out.as_slice_mut().expect("contiguous") };
        py.detach(|| {
            pools::install(threads, || {
                let Some(order) = self.batch_order(&batch).filter(|_| !coherent) else {
                    return blocked
                        .par_chunks_mut(CHUNK)
                        .enumerate()
                        .for_each(|(chunk, out)| {
                            let count = out.len();
                            let rays = |i: usize| batch.ray(chunk * CHUNK + i);
                            let answer = |i: usize, blocked: bool| out[i] = blocked;
                            let batch = RayBatch::new(count).with(Coherence::hint(coherent));
                            self.accel.any_hits(batch, rays, answer)
                        });
                };
                let traced = order.trace(
                    CHUNK,
                    |i| batch.ray(i),
                    |rays, out| {
                        let answer = |i: usize, blocked: bool| out[i] = blocked;
                        self.accel
                            .occluded_each(rays.len(), ALL_MASKS, |i| rays[i], answer)
                    },
                );
                order.unsort_into(&traced, blocked);
            })
        })?;
        Ok(out)
    }

    fn __repr__(&self) -> String {
        format!(
            "Bvh({} primitives, builder={:?}, width={})",
            self.accel.primitives().len(),
            self.name(),
            self.width.children()
        )
    }
}
