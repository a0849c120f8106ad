//! `canopy.Bvh`: a BVH over a triangle mesh or over boxes, and batched ray queries.

use crate::arrays;
use crate::pools;
use canopy_bvh::ALL_MASKS;
use canopy_bvh::{Aabb, BuildParams, BvhWidth, SahCosts, TriangleTest};
use canopy_bvh::{AnswerSlots, Coherence, Hit, Ray, RayBatch, RayOrder, RayQuery, SliceSlots};
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
use std::marker::PhantomData;
use std::sync::{PoisonError, RwLock, RwLockReadGuard};
use std::time::Instant;

/// Rays per parallel task: enough to amortise scheduling, few enough to balance.
const CHUNK: usize = 1024;

/// A BVH over triangles (a mesh) or boxes, built once, queried with batches of rays; a
/// mesh's vertices may move ([`Bvh::set_vertices`]: the tree is refitted).
///
/// The structure sits behind a lock that queries share and a refit takes alone. Queries
/// and refits take it with the GIL released, and a refit never waits for the GIL while
/// it holds the lock; so the short reads that take it holding the GIL (statistics,
/// pickling) wait at most for a refit to end, and no thread waits for a lock while
/// holding the GIL that the lock's holder needs.
#[pyclass(frozen, module = "canopy_rt._canopy")]
pub struct Bvh {
    shared: RwLock<Shared>,
    /// The mesh's triangles as indices into [`Shared::vertices`] (`None`: boxes).
    faces: Option<Vec<[u32; 3]>>,
    /// A builder, or `none` (brute force: the plain loop every tree is checked against).
    kind: AccelKind,
    width: BvhWidth,
    params: BuildParams,
    build_ms: f64,
}

/// What a refit changes: the structure, and the mesh's vertices (empty for boxes).
struct Shared {
    accel: Accel,
    vertices: Vec<[f32; 3]>,
}

/// A mesh as a `Bvh` is given it: vertices, and faces as indices into them.
type MeshParts = (Vec<[f32; 3]>, Vec<[u32; 3]>);

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
    let triangle_test = triangle_test(triangles)?;
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
    /// The structure over `primitives`, made from `mesh` (vertices and faces) or boxes.
    fn build(
        py: Python<'_>,
        primitives: Vec<Primitive>,
        mesh: Option<MeshParts>,
        o: Options,
    ) -> PyResult<Self> {
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
                let (vertices, faces) = match mesh {
                    Some((vertices, faces)) => (vertices, Some(faces)),
                    None => (Vec::new(), None),
                };
                Bvh {
                    shared: RwLock::new(Shared { accel, vertices }),
                    faces,
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

    /// The structure and vertices, shared with other queries. Called with the GIL held,
    /// it may wait for a refit, which never waits for the GIL (see [`Bvh`]).
    fn read(&self) -> RwLockReadGuard<'_, Shared> {
        self.shared.read().unwrap_or_else(PoisonError::into_inner)
    }
}

/// The order to answer `n` queries of `structure` in, if not the caller's: by `place(i)`
/// (a ray's origin, a query point), where the structure is larger than the cache
/// ([`RayQuery::orders_batches`], [`RayOrder::by_origin`]).
pub(crate) fn query_order(
    structure: &impl RayQuery,
    n: usize,
    place: impl Fn(usize) -> Vec3 + Sync,
) -> Option<RayOrder> {
    structure
        .orders_batches()
        .then(|| RayOrder::by_origin(n, place))
        .flatten()
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

/// The three output arrays of closest hits as [`AnswerSlots`]: rays traced out of the
/// caller's order write their hits straight to their rows.
struct HitColumns<'a> {
    t: *mut f32,
    prim: *mut i64,
    uv: *mut f32,
    len: usize,
    _borrow: PhantomData<&'a mut [f32]>,
}

impl<'a> HitColumns<'a> {
    /// # Panics
    /// If the arrays do not all hold one row per ray (`uv` two values a row).
    fn new(t: &'a mut [f32], prim: &'a mut [i64], uv: &'a mut [f32]) -> Self {
        assert!(
            prim.len() == t.len() && uv.len() == 2 * t.len(),
            "one row per ray"
        );
        Self {
            t: t.as_mut_ptr(),
            prim: prim.as_mut_ptr(),
            uv: uv.as_mut_ptr(),
            len: t.len(),
            _borrow: PhantomData,
        }
    }
}

// SAFETY: the columns stand for three `&mut` slices of plain numbers; `put`'s contract
// keeps threads to disjoint rows.
unsafe impl Sync for HitColumns<'_> {}

impl AnswerSlots<Option<Hit>> for HitColumns<'_> {
    fn len(&self) -> usize {
        self.len
    }

    #[inline]
    unsafe fn put(&self, i: usize, hit: Option<Hit>) {
        debug_assert!(i < self.len);
        // SAFETY: row `i` is in bounds of all three arrays (checked in `new`) and no
        // other thread touches it, by the caller's contract; the arrays are borrowed
        // mutably for the columns' life.
        let (t, prim, uv) = unsafe {
            (
                std::slice::from_raw_parts_mut(self.t.add(i), 1),
                std::slice::from_raw_parts_mut(self.prim.add(i), 1),
                std::slice::from_raw_parts_mut(self.uv.add(2 * i), 2),
            )
        };
        write_hit(t, prim, uv, 0, hit);
    }
}

/// A batch of rays as the caller's arrays, checked; rays are made from them on the fly,
/// in parallel.
#[derive(Clone, Copy)]
pub(crate) struct Batch<'a> {
    rows: RayRows<'a>,
    tnear: PerRay<'a>,
    tfar: PerRay<'a>,
}

/// The rays' origins and directions as the caller gave them.
#[derive(Clone, Copy)]
enum RayRows<'a> {
    /// Two `(n, 3)` arrays.
    Apart(&'a [[f32; 3]], &'a [[f32; 3]]),
    /// One `(n, 6)` array, origin then direction (Open3D's rays).
    Joined(&'a [[f32; 6]]),
}

impl RayRows<'_> {
    fn len(&self) -> usize {
        match self {
            RayRows::Apart(origins, _) => origins.len(),
            RayRows::Joined(rays) => rays.len(),
        }
    }
}

impl Batch<'_> {
    pub(crate) fn len(&self) -> usize {
        self.rows.len()
    }

    #[inline]
    pub(crate) fn origin(&self, i: usize) -> Vec3 {
        match self.rows {
            RayRows::Apart(origins, _) => Vec3::from(origins[i]),
            RayRows::Joined(rays) => Vec3::from_slice(&rays[i][..3]),
        }
    }

    #[inline]
    pub(crate) fn ray(&self, i: usize) -> Ray {
        let (origin, direction) = match self.rows {
            RayRows::Apart(origins, directions) => {
                (Vec3::from(origins[i]), Vec3::from(directions[i]))
            }
            RayRows::Joined(rays) => {
                let [ox, oy, oz, dx, dy, dz] = rays[i];
                (Vec3::new(ox, oy, oz), Vec3::new(dx, dy, dz))
            }
        };
        Ray::new(origin, direction, self.tnear.get(i), self.tfar.get(i))
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

/// The checked batch of a query's arguments (`near` and `far` hold per-ray arrays):
/// `origins` and `directions` `(n, 3)`, or, without `directions`, `origins` `(n, 6)` rays.
pub(crate) fn batch<'a, 'py>(
    origins: &'a PyReadonlyArray2<'py, f32>,
    directions: &'a Option<PyReadonlyArray2<'py, f32>>,
    tnear: &'a Bound<'py, PyAny>,
    near: &'a mut Option<PyReadonlyArray1<'py, f32>>,
    tfar: &'a Bound<'py, PyAny>,
    far: &'a mut Option<PyReadonlyArray1<'py, f32>>,
) -> PyResult<Batch<'a>> {
    let rows = match directions {
        None => RayRows::Joined(arrays::rays("rays", origins)?),
        Some(directions) => {
            let o = arrays::points("origins", origins)?;
            let d = arrays::points("directions", directions)?;
            if o.len() != d.len() {
                return Err(PyValueError::new_err(format!(
                    "origins and directions must have the same number of rows, not {} and {}",
                    o.len(),
                    d.len()
                )));
            }
            RayRows::Apart(o, d)
        }
    };
    Ok(Batch {
        rows,
        tnear: per_ray("tnear", tnear, near, rows.len())?,
        tfar: per_ray("tfar", tfar, far, rows.len())?,
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
        // In range: `arrays::faces` checked every index against the vertex count.
        let f: Vec<[u32; 3]> = arrays::faces(&faces, v.len())?
            .iter()
            .map(|face| face.map(|i| i as u32))
            .collect();
        let primitives = f
            .iter()
            .map(|&face| Primitive {
                shape: Shape::Triangle(triangle(v, face)),
                material: 0,
            })
            .collect();
        Self::build(py, primitives, Some((v.to_vec(), f)), o)
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
        Self::build(py, primitives, None, o)
    }

    /// Moves the mesh's vertices to `vertices` (as many as it has; the triangles stay)
    /// and refits the tree: every box recomputed, the topology kept. Refused for boxes,
    /// for another vertex count, and for a tree with spatial splits (`sbvh`), which
    /// cannot be refitted; refused, the structure is unchanged.
    #[pyo3(signature = (vertices, threads=None))]
    fn set_vertices(
        &self,
        py: Python<'_>,
        vertices: PyReadonlyArray2<'_, f32>,
        threads: Option<usize>,
    ) -> PyResult<()> {
        let Some(faces) = &self.faces else {
            return Err(PyValueError::new_err(
                "set_vertices: this Bvh is over boxes, which have no vertices",
            ));
        };
        let v = arrays::points("vertices", &vertices)?;
        let count = self.read().vertices.len();
        if v.len() != count {
            return Err(PyValueError::new_err(format!(
                "set_vertices: the mesh has {count} vertices, not {}; a mesh with other \
                 vertices or triangles is a new Bvh",
                v.len()
            )));
        }
        let refit = py.detach(|| {
            pools::install(threads, || {
                let mut shared = self.shared.write().unwrap_or_else(PoisonError::into_inner);
                shared.accel.update_primitives(|primitives| {
                    primitives
                        .par_iter_mut()
                        .zip(faces.par_iter())
                        .for_each(|(p, &face)| p.shape = Shape::Triangle(triangle(v, face)));
                })?;
                shared.vertices = v.to_vec();
                Ok(())
            })
        })?;
        refit.map_err(|e: canopy_bvh::RefitError| {
            PyValueError::new_err(format!(
                "set_vertices: this tree was built by {} with spatial splits, which cannot \
                 be refitted ({e}); build a new Bvh over the moved mesh",
                self.name()
            ))
        })
    }

    /// The mesh as it is now, for pickling: (V, 3) vertices and (F, 3) faces; `None` for
    /// boxes.
    #[allow(clippy::type_complexity)]
    fn mesh<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<(Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<i64>>)>> {
        let Some(faces) = &self.faces else {
            return Ok(None);
        };
        let vertices: Vec<f32> = self.read().vertices.iter().flatten().copied().collect();
        let rows = vertices.len() / 3;
        let indices: Vec<i64> = faces.iter().flatten().map(|&i| i as i64).collect();
        Ok(Some((
            PyArray1::from_vec(py, vertices).reshape([rows, 3])?,
            PyArray1::from_vec(py, indices).reshape([faces.len(), 3])?,
        )))
    }

    /// The primitives: ("triangles", (F, 3, 3) vertices of each) or ("boxes", (N, 2, 3)
    /// min and max corners), as the structure holds them.
    fn primitives<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(&'static str, Bound<'py, PyArray3<f32>>)> {
        let shared = self.read();
        let accel = &shared.accel;
        let primitives = accel.primitives();
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
        self.read().accel.primitives().len()
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
        let shared = self.read();
        let accel = &shared.accel;
        d.set_item("builder", self.name())?;
        d.set_item("primitives", accel.primitives().len())?;
        d.set_item("build_ms", self.build_ms)?;
        d.set_item("triangles", accel.triangle_test().name())?;
        let Some(tree) = accel.tree() else {
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
        py.detach(|| {
            let shared = self.read();
            let accel = &shared.accel;
            let Some(tree) = accel.tree() else {
                return 0.0;
            };
            canopy_bvh::epo(tree.view(), &self.params.sah, |prim, region| {
                accel.primitives()[prim as usize]
                    .shape
                    .area_in_box(region)
                    .unwrap_or(0.0)
            })
        })
    }

    fn validate(&self) -> PyResult<()> {
        let shared = self.read();
        let accel = &shared.accel;
        match accel.tree() {
            Some(tree) => tree
                .validate(
                    &accel
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
        directions: Option<PyReadonlyArray2<'py, f32>>,
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
                let shared = self.read();
                let accel = &shared.accel;
                // Scattered rays (from surfaces, in any order) are traced by where they
                // start; coherent ones in their own order, in packets.
                let Some(order) =
                    query_order(accel, batch.len(), |i| batch.origin(i)).filter(|_| !coherent)
                else {
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
                            accel.closest_hits(batch, rays, answer, &mut ())
                        });
                };
                order.trace_into(
                    CHUNK,
                    |i| batch.ray(i),
                    |rays, out| {
                        accel.closest_hits_into(
                            rays,
                            out,
                            ALL_MASKS,
                            Coherence::Incoherent,
                            &mut (),
                        )
                    },
                    &HitColumns::new(t, prim, uv),
                )
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
        directions: Option<PyReadonlyArray2<'py, f32>>,
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
                let shared = self.read();
                let accel = &shared.accel;
                let Some(order) =
                    query_order(accel, batch.len(), |i| batch.origin(i)).filter(|_| !coherent)
                else {
                    return blocked
                        .par_chunks_mut(CHUNK)
                        .enumerate()
                        .for_each(|(chunk, out)| {
                            let count = out.len();
                            let rays = |i: usize| batch.ray(chunk * CHUNK + i);
                            let answer = |i: usize, blocked: bool| out[i] = blocked;
                            let batch = RayBatch::new(count).with(Coherence::hint(coherent));
                            accel.any_hits(batch, rays, answer)
                        });
                };
                order.trace_into(
                    CHUNK,
                    |i| batch.ray(i),
                    |rays, out| accel.any_hits_into(rays, out, ALL_MASKS, Coherence::Incoherent),
                    &SliceSlots::new(blocked),
                );
            })
        })?;
        Ok(out)
    }

    fn __repr__(&self) -> String {
        format!(
            "Bvh({} primitives, builder={:?}, width={})",
            self.read().accel.primitives().len(),
            self.name(),
            self.width.children()
        )
    }
}

/// The triangle `face` of `vertices` (indices checked to be in range).
fn triangle(vertices: &[[f32; 3]], [a, b, c]: [u32; 3]) -> Triangle {
    let vertex = |i: u32| Vec3::from(vertices[i as usize]);
    Triangle::new(vertex(a), vertex(b), vertex(c))
}

/// The triangle test a `triangles=` keyword names.
pub(crate) fn triangle_test(triangles: &str) -> PyResult<TriangleTest> {
    match triangles {
        "watertight" => Ok(TriangleTest::Watertight),
        "fast" => Ok(TriangleTest::Fast),
        other => Err(PyValueError::new_err(format!(
            "triangles must be 'watertight' or 'fast', not {other:?}"
        ))),
    }
}
