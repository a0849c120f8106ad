//! `canopy_rt._canopy.RayScene`: triangle meshes placed by instances and queried with
//! batches of rays, as Embree's and Open3D's ray-casting scenes are. A hit names the
//! instance, its geometry, the triangle, t, barycentrics and the geometric normal in
//! world space.

use crate::arrays;
use crate::bvh::{batch, query_order};
use crate::pools;
use canopy_bvh::{
    Blas, BlasParams, Hit, HitsAlong, Instance, Nearest, Ray, RayQuery, SurfaceQuery, Tlas,
    TriangleMesh,
};
use glam::Vec3;
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rayon::prelude::*;
use std::sync::{Arc, Mutex};

type MeshBlas = Arc<Blas<TriangleMesh>>;

/// Meshes (each with its own BVH, built once) and the instances placing them; the top
/// tree over the instances is built at the first query after a change.
#[pyclass(module = "canopy_rt._canopy")]
pub struct RayScene {
    meshes: Vec<MeshBlas>,
    instances: Vec<Instance>,
    params: BlasParams,
    /// The top tree of the current instances, once a query has needed it.
    tlas: Mutex<Option<Arc<Tlas<MeshBlas>>>>,
}

impl RayScene {
    fn tlas(&self, threads: Option<usize>) -> PyResult<Arc<Tlas<MeshBlas>>> {
        let mut cached = self.tlas.lock().expect("no query panics holding the lock");
        if let Some(tlas) = &*cached {
            return Ok(tlas.clone());
        }
        let tlas = pools::install(threads, || {
            Tlas::build(self.meshes.clone(), self.instances.clone(), &self.params)
        })?
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
        let tlas = Arc::new(tlas);
        *cached = Some(tlas.clone());
        Ok(tlas)
    }

    /// `answer(tlas, query(i))` for rows `0..n` (`query(i)` reads the caller's row `i`),
    /// in parallel with the GIL released, as a new (n,) array. Rows are answered in the
    /// order of `place(i)` (a ray's origin, a query point) where the scene is larger
    /// than the cache ([`RayQuery::orders_batches`]): queries that start near each other
    /// walk the same nodes while these are cached.
    fn per_row<'py, Q: Copy + Send, T: numpy::Element + Copy + Default + Send + Sync>(
        &self,
        py: Python<'py>,
        n: usize,
        threads: Option<usize>,
        place: impl Fn(usize) -> Vec3 + Sync + Send,
        query: impl Fn(usize) -> Q + Sync + Send,
        answer: impl Fn(&Tlas<MeshBlas>, Q) -> T + Sync,
    ) -> PyResult<Bound<'py, PyArray1<T>>> {
        let each = |tlas: &Tlas<MeshBlas>, queries: &[Q], answers: &mut [T]| {
            for (a, &q) in answers.iter_mut().zip(queries) {
                *a = answer(tlas, q);
            }
        };
        self.per_batch(py, n, threads, place, query, each)
    }

    /// [`RayScene::per_row`] where `answer(tlas, queries, answers)` answers a run of up
    /// to [`POINT_CHUNK`] rows at once (one walk of the tree for a batch of rays).
    fn per_batch<'py, Q: Send, T: numpy::Element + Copy + Default + Send + Sync>(
        &self,
        py: Python<'py>,
        n: usize,
        threads: Option<usize>,
        place: impl Fn(usize) -> Vec3 + Sync + Send,
        query: impl Fn(usize) -> Q + Sync + Send,
        answer: impl Fn(&Tlas<MeshBlas>, &[Q], &mut [T]) + Sync,
    ) -> PyResult<Bound<'py, PyArray1<T>>> {
        let tlas = py.detach(|| self.tlas(threads))?;
        // SAFETY (both): the array is made here, and every element is written below
        // before it is returned; nothing else refers to it yet.
        let out = unsafe { PyArray1::<T>::new(py, n, false) };
        let values = unsafe { out.as_slice_mut().expect("contiguous") };
        let answer = |queries: &[Q], answers: &mut [T]| answer(&tlas, queries, answers);
        py.detach(|| {
            pools::install(threads, || match query_order(&tlas, n, place) {
                Some(order) => order.answer_batches_into(POINT_CHUNK, query, answer, values),
                None => values
                    .par_chunks_mut(POINT_CHUNK)
                    .enumerate()
                    .for_each_init(Vec::new, |queries, (chunk, answers)| {
                        let first = chunk * POINT_CHUNK;
                        queries.clear();
                        queries.extend((first..first + answers.len()).map(&query));
                        answer(queries, answers)
                    }),
            })
        })?;
        Ok(out)
    }

    /// The builder's name, as `RayScene(builder=...)` takes it.
    fn builder_name(&self) -> String {
        match self.params.builder {
            None => canopy_render::AccelKind::None,
            Some(builder) => canopy_render::AccelKind::Bvh(builder),
        }
        .to_string()
    }

    fn changed(&mut self) {
        *self
            .tlas
            .get_mut()
            .expect("no query panics holding the lock") = None;
    }
}

/// Why `instance` (number `index`) cannot be placed, as the call `what` says it.
fn check_transform(instance: &Instance, index: usize, what: &str) -> PyResult<()> {
    instance.check(index).map_err(|e| {
        PyValueError::new_err(format!(
            "{what}: the transform must be finite and invertible: {e}"
        ))
    })
}

/// Which hits along a ray count: each crossing of the surface once, or every triangle.
fn hits_along(per_triangle: bool) -> HitsAlong {
    match per_triangle {
        true => HitsAlong::Triangles,
        false => HitsAlong::Crossings,
    }
}

/// Points per parallel task of the point queries.
const POINT_CHUNK: usize = 256;

/// Rays whose listed hits are written out as one task.
const ROWS_CHUNK: usize = 4096;

/// The arrays a batch of hits (of rays, or nearest points) is written into, one row
/// each: instance, geometry and triangle (-1 where there is none), barycentrics and
/// the world-space unit geometric normal (0 where there is none).
struct HitRows<'a> {
    inst: &'a mut [i64],
    geom: &'a mut [i64],
    prim: &'a mut [i64],
    uv: &'a mut [f32],
    normal: &'a mut [f32],
}

impl<'a> HitRows<'a> {
    /// The rows before `row` and the rows from it on, to be written apart.
    fn split_at(self, row: usize) -> (Self, Self) {
        let (inst, inst_rest) = self.inst.split_at_mut(row);
        let (geom, geom_rest) = self.geom.split_at_mut(row);
        let (prim, prim_rest) = self.prim.split_at_mut(row);
        let (uv, uv_rest) = self.uv.split_at_mut(2 * row);
        let (normal, normal_rest) = self.normal.split_at_mut(3 * row);
        let before = HitRows {
            inst,
            geom,
            prim,
            uv,
            normal,
        };
        let after = HitRows {
            inst: inst_rest,
            geom: geom_rest,
            prim: prim_rest,
            uv: uv_rest,
            normal: normal_rest,
        };
        (before, after)
    }

    /// Row `i` says what `hit` (instance, triangle, barycentrics) names.
    #[inline]
    fn write(&mut self, tlas: &Tlas<MeshBlas>, i: usize, hit: Option<Hit>) {
        match hit {
            Some(hit) => {
                self.inst[i] = hit.inst as i64;
                self.geom[i] = tlas.instances()[hit.inst as usize].blas as i64;
                self.prim[i] = hit.prim as i64;
                self.uv[2 * i..2 * i + 2].copy_from_slice(&[hit.u, hit.v]);
                let normal = geometric_normal(tlas, &hit).to_array();
                self.normal[3 * i..3 * i + 3].copy_from_slice(&normal);
            }
            None => {
                (self.inst[i], self.geom[i], self.prim[i]) = (-1, -1, -1);
                self.uv[2 * i..2 * i + 2].fill(0.0);
                self.normal[3 * i..3 * i + 3].fill(0.0);
            }
        }
    }
}

/// The hit record of a nearest point: its triangle, instance and barycentrics.
fn as_hit(n: &Nearest) -> Hit {
    Hit {
        t: n.distance,
        inst: n.inst,
        prim: n.prim,
        u: n.u,
        v: n.v,
    }
}

type Rows<'py> = (
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray2<f32>>,
    Bound<'py, PyArray2<f32>>,
);

/// Zeroed arrays for `n` rows of [`HitRows`].
fn hit_arrays(py: Python<'_>, n: usize) -> Rows<'_> {
    (
        PyArray1::<i64>::zeros(py, n, false),
        PyArray1::<i64>::zeros(py, n, false),
        PyArray1::<i64>::zeros(py, n, false),
        PyArray2::<f32>::zeros(py, [n, 2], false),
        PyArray2::<f32>::zeros(py, [n, 3], false),
    )
}

/// Mutable views of arrays made by [`hit_arrays`].
///
/// # Safety
/// The arrays must have just been made, with nothing else referring to them.
unsafe fn hit_rows<'a>(arrays: &'a Rows<'_>) -> HitRows<'a> {
    // SAFETY: as the caller promises.
    unsafe {
        HitRows {
            inst: arrays.0.as_slice_mut().expect("contiguous"),
            geom: arrays.1.as_slice_mut().expect("contiguous"),
            prim: arrays.2.as_slice_mut().expect("contiguous"),
            uv: arrays.3.as_slice_mut().expect("contiguous"),
            normal: arrays.4.as_slice_mut().expect("contiguous"),
        }
    }
}

/// The world-space unit normal of the triangle `hit` names, (v1 - v0) x (v2 - v0) in its
/// mesh, through its instance's inverse transpose.
fn geometric_normal(tlas: &Tlas<MeshBlas>, hit: &Hit) -> Vec3 {
    let instance = &tlas.instances()[hit.inst as usize];
    let mesh = tlas.blases()[instance.blas as usize].geometry();
    let [a, b, c] = mesh.vertices_of(hit.prim);
    instance
        .normal_to_world((b - a).cross(c - a))
        .normalize_or_zero()
}

#[pymethods]
impl RayScene {
    #[new]
    #[pyo3(signature = (builder="binned-sah", width=8, triangles="watertight"))]
    fn new(builder: &str, width: u32, triangles: &str) -> PyResult<Self> {
        let triangle_test = crate::bvh::triangle_test(triangles)?;
        let kind: canopy_render::AccelKind = builder
            .parse()
            .map_err(|e: canopy_bvh::UnknownBuilder| PyValueError::new_err(e.to_string()))?;
        let width: canopy_bvh::BvhWidth =
            width.to_string().parse().map_err(PyValueError::new_err)?;
        let builder = match kind {
            canopy_render::AccelKind::None => None,
            canopy_render::AccelKind::Bvh(b) => Some(b),
        };
        let mut params = BlasParams::new(builder, width);
        params.build = canopy_bvh::packed_params(&params.build);
        params.triangle_test = triangle_test;
        Ok(Self {
            meshes: Vec::new(),
            instances: Vec::new(),
            params,
            tlas: Mutex::new(None),
        })
    }

    /// Adds a mesh and builds its BVH; returns the geometry's index. It is placed by
    /// `add_instance` only.
    #[pyo3(signature = (vertices, faces, threads=None))]
    fn add_geometry(
        &mut self,
        py: Python<'_>,
        vertices: PyReadonlyArray2<'_, f32>,
        faces: PyReadonlyArray2<'_, i64>,
        threads: Option<usize>,
    ) -> PyResult<u32> {
        let positions: Vec<Vec3> = arrays::points("vertices", &vertices)?
            .iter()
            .map(|&p| p.into())
            .collect();
        let triangles: Vec<[u32; 3]> = arrays::faces(&faces, positions.len())?
            .iter()
            .map(|f| f.map(|i| i as u32))
            .collect();
        let mesh = TriangleMesh::new(positions, triangles)
            .map_err(|e| PyValueError::new_err(format!("add_geometry: {e}")))?;
        let params = self.params;
        let blas = py.detach(|| pools::install(threads, || Blas::build(mesh, &params)))?;
        self.meshes.push(Arc::new(blas));
        Ok(self.meshes.len() as u32 - 1)
    }

    /// Places geometry `geometry` by `transform` (a (3, 4) float32 matrix), seen by rays
    /// whose mask shares a bit with `mask`; returns the instance's index.
    fn add_instance(
        &mut self,
        geometry: u32,
        transform: PyReadonlyArray2<'_, f32>,
        mask: u32,
    ) -> PyResult<u32> {
        if geometry as usize >= self.meshes.len() {
            return Err(PyValueError::new_err(format!(
                "add_instance: geometry {geometry} does not exist (the scene has {})",
                self.meshes.len()
            )));
        }
        if self.instances.len() >= u32::MAX as usize {
            return Err(PyValueError::new_err("add_instance: too many instances"));
        }
        let id = self.instances.len() as u32;
        let instance = Instance::new(geometry, arrays::affine(&transform)?)
            .with_mask(mask)
            .with_id(id);
        check_transform(&instance, id as usize, "add_instance")?;
        self.instances.push(instance);
        self.changed();
        Ok(id)
    }

    /// Moves instance `instance` to `transform`.
    fn set_transform(
        &mut self,
        instance: u32,
        transform: PyReadonlyArray2<'_, f32>,
    ) -> PyResult<()> {
        let count = self.instances.len();
        let to_world = arrays::affine(&transform)?;
        let Some(slot) = self.instances.get_mut(instance as usize) else {
            return Err(PyValueError::new_err(format!(
                "set_transform: instance {instance} does not exist (the scene has {count})"
            )));
        };
        let moved = slot.with_transform(to_world);
        check_transform(&moved, instance as usize, "set_transform")?;
        *slot = moved;
        self.changed();
        Ok(())
    }

    /// Gives geometry `geometry` new vertex positions (as many as it has; the triangles
    /// stay) and refits its tree: every box recomputed, the topology kept.
    #[pyo3(signature = (geometry, vertices, threads=None))]
    fn set_vertices(
        &mut self,
        py: Python<'_>,
        geometry: u32,
        vertices: PyReadonlyArray2<'_, f32>,
        threads: Option<usize>,
    ) -> PyResult<()> {
        let count = self.meshes.len();
        let Some(slot) = self.meshes.get(geometry as usize) else {
            return Err(PyValueError::new_err(format!(
                "set_vertices: geometry {geometry} does not exist (the scene has {count})"
            )));
        };
        let has = slot.geometry().vertices().len();
        let positions: Vec<Vec3> = arrays::points("vertices", &vertices)?
            .iter()
            .map(|&p| p.into())
            .collect();
        if positions.len() != has {
            return Err(PyValueError::new_err(format!(
                "set_vertices: geometry {geometry} has {has} vertices, not {}; a mesh with \
                 other vertices or triangles is a new geometry (add_geometry)",
                positions.len()
            )));
        }
        self.changed();
        let blas = Arc::make_mut(&mut self.meshes[geometry as usize]);
        let mut edited = Ok(());
        let refit = py.detach(|| {
            pools::install(threads, || {
                blas.update(|mesh| edited = mesh.set_vertices(positions))
            })
        })?;
        refit.map_err(|e| {
            PyValueError::new_err(format!(
                "set_vertices: geometry {geometry} was built by {} with spatial splits, \
                 which cannot be refitted ({e}); add the moved mesh as a new geometry",
                self.builder_name()
            ))
        })?;
        // Checked above: the count matches and the positions are finite.
        edited.map_err(|e| PyValueError::new_err(format!("set_vertices: {e}")))
    }

    /// How ray queries test triangles: "watertight" or "fast".
    #[getter]
    fn triangles(&self) -> &'static str {
        self.params.triangle_test.name()
    }

    /// Everything the scene was made from, for pickling: (builder, width, each
    /// geometry's (vertices, faces), each instance's (geometry, (3, 4) transform, mask)).
    #[allow(clippy::type_complexity)]
    fn state<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        String,
        u32,
        Vec<(Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<i64>>)>,
        Vec<(u32, Bound<'py, PyArray2<f32>>, u32)>,
    )> {
        let mut geometries = Vec::with_capacity(self.meshes.len());
        for blas in &self.meshes {
            let mesh = blas.geometry();
            let vertices: Vec<f32> = mesh.vertices().iter().flat_map(|v| v.to_array()).collect();
            let faces: Vec<i64> = mesh.indices().iter().flatten().map(|&i| i as i64).collect();
            geometries.push((
                PyArray1::from_vec(py, vertices).reshape([mesh.vertices().len(), 3])?,
                PyArray1::from_vec(py, faces).reshape([mesh.indices().len(), 3])?,
            ));
        }
        let mut instances = Vec::with_capacity(self.instances.len());
        for instance in &self.instances {
            let m = instance.to_world();
            let (x, y, z, t) = (
                m.matrix3.x_axis,
                m.matrix3.y_axis,
                m.matrix3.z_axis,
                m.translation,
            );
            let rows: Vec<f32> = (0..3).flat_map(|r| [x[r], y[r], z[r], t[r]]).collect();
            let transform = PyArray1::from_vec(py, rows).reshape([3, 4])?;
            instances.push((instance.blas, transform, instance.mask));
        }
        let width = self.params.width.children();
        Ok((self.builder_name(), width, geometries, instances))
    }

    #[getter]
    fn geometry_count(&self) -> usize {
        self.meshes.len()
    }

    #[getter]
    fn instance_count(&self) -> usize {
        self.instances.len()
    }

    /// Closest hits: t (inf on a miss), instance, geometry and primitive (-1 on a miss),
    /// barycentrics uv and the world-space unit geometric normal (0 on a miss).
    #[pyo3(signature = (origins, directions, tnear, tfar, mask, threads=None))]
    #[allow(clippy::type_complexity, clippy::too_many_arguments)]
    fn intersect<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'py, f32>,
        directions: Option<PyReadonlyArray2<'py, f32>>,
        tnear: Bound<'py, PyAny>,
        tfar: Bound<'py, PyAny>,
        mask: u32,
        threads: Option<usize>,
    ) -> PyResult<(
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray2<f32>>,
        Bound<'py, PyArray2<f32>>,
    )> {
        let (mut near, mut far) = (None, None);
        let batch = batch(&origins, &directions, &tnear, &mut near, &tfar, &mut far)?;
        let n = batch.len();
        let tlas = py.detach(|| self.tlas(threads))?;
        let t_out = PyArray1::<f32>::zeros(py, n, false);
        let inst_out = PyArray1::<i64>::zeros(py, n, false);
        let geom_out = PyArray1::<i64>::zeros(py, n, false);
        let prim_out = PyArray1::<i64>::zeros(py, n, false);
        let uv_out = PyArray2::<f32>::zeros(py, [n, 2], false);
        let normal_out = PyArray2::<f32>::zeros(py, [n, 3], false);
        // SAFETY: the arrays were just made here and nothing else refers to them yet.
        let (t, inst, geom, prim, uv, normal) = unsafe {
            (
                t_out.as_slice_mut().expect("contiguous"),
                inst_out.as_slice_mut().expect("contiguous"),
                geom_out.as_slice_mut().expect("contiguous"),
                prim_out.as_slice_mut().expect("contiguous"),
                uv_out.as_slice_mut().expect("contiguous"),
                normal_out.as_slice_mut().expect("contiguous"),
            )
        };
        py.detach(|| {
            pools::install(threads, || {
                let rays: Vec<Ray> = (0..n).into_par_iter().map(|i| batch.ray(i)).collect();
                let mut hits = vec![None; n];
                tlas.intersect_batch(&rays, &mut hits, mask);
                t.par_iter_mut()
                    .zip(inst.par_iter_mut())
                    .zip(geom.par_iter_mut())
                    .zip(prim.par_iter_mut())
                    .zip(uv.par_chunks_mut(2))
                    .zip(normal.par_chunks_mut(3))
                    .zip(hits.par_iter())
                    .for_each(
                        |((((((t, inst), geom), prim), uv), normal), hit)| match hit {
                            Some(hit) => {
                                *t = hit.t;
                                *inst = hit.inst as i64;
                                *geom = tlas.instances()[hit.inst as usize].blas as i64;
                                *prim = hit.prim as i64;
                                uv.copy_from_slice(&[hit.u, hit.v]);
                                normal.copy_from_slice(&geometric_normal(&tlas, hit).to_array());
                            }
                            None => {
                                *t = f32::INFINITY;
                                (*inst, *geom, *prim) = (-1, -1, -1);
                            }
                        },
                    );
            })
        })?;
        Ok((t_out, inst_out, geom_out, prim_out, uv_out, normal_out))
    }

    /// Whether anything `mask` sees lies on each ray within [tnear, tfar].
    #[pyo3(signature = (origins, directions, tnear, tfar, mask, threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn occluded<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'py, f32>,
        directions: Option<PyReadonlyArray2<'py, f32>>,
        tnear: Bound<'py, PyAny>,
        tfar: Bound<'py, PyAny>,
        mask: u32,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let (mut near, mut far) = (None, None);
        let batch = batch(&origins, &directions, &tnear, &mut near, &tfar, &mut far)?;
        let n = batch.len();
        let tlas = py.detach(|| self.tlas(threads))?;
        let out = PyArray1::<bool>::zeros(py, n, false);
        // SAFETY: the array was just made here and nothing else refers to it yet.
        let blocked = unsafe { out.as_slice_mut().expect("contiguous") };
        py.detach(|| {
            pools::install(threads, || {
                let rays: Vec<Ray> = (0..n).into_par_iter().map(|i| batch.ray(i)).collect();
                tlas.occluded_batch(&rays, blocked, mask);
            })
        })?;
        Ok(out)
    }

    /// The nearest point of the surface to each query point no farther than
    /// `max_distance`: (point, distance, then the rows of [`HitRows`]); inf distance, NaN
    /// point and -1 indices where nothing is that near.
    #[pyo3(signature = (points, max_distance, threads=None))]
    #[allow(clippy::type_complexity)]
    fn closest_points<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        max_distance: f32,
        threads: Option<usize>,
    ) -> PyResult<(
        Bound<'py, PyArray2<f32>>,
        Bound<'py, PyArray1<f32>>,
        Rows<'py>,
    )> {
        let queries = arrays::points("points", &points)?;
        if max_distance.is_nan() || max_distance < 0.0 {
            return Err(PyValueError::new_err(format!(
                "max_distance must be a distance (0 or more), not {max_distance}"
            )));
        }
        let n = queries.len();
        let tlas = py.detach(|| self.tlas(threads))?;
        let point_out = PyArray2::<f32>::zeros(py, [n, 3], false);
        let distance_out = PyArray1::<f32>::zeros(py, n, false);
        let rows = hit_arrays(py, n);
        // SAFETY: the arrays were just made here and nothing else refers to them yet.
        let (point, distance, mut all) = unsafe {
            (
                point_out.as_slice_mut().expect("contiguous"),
                distance_out.as_slice_mut().expect("contiguous"),
                hit_rows(&rows),
            )
        };
        py.detach(|| {
            pools::install(threads, || {
                let query = |i: usize| Vec3::from(queries[i]);
                let nearest_to = |q: Vec3| tlas.closest_point(q, max_distance);
                let mut nearest: Vec<Option<Nearest>> = vec![None; n];
                match query_order(&tlas, n, query) {
                    Some(order) => order.answer_into(POINT_CHUNK, query, nearest_to, &mut nearest),
                    None => nearest
                        .par_iter_mut()
                        .with_min_len(POINT_CHUNK)
                        .enumerate()
                        .for_each(|(i, v)| *v = nearest_to(query(i))),
                }
                for (i, found) in nearest.iter().enumerate() {
                    all.write(&tlas, i, found.as_ref().map(as_hit));
                    let (p, d) =
                        found.map_or((Vec3::NAN, f32::INFINITY), |n| (n.point, n.distance));
                    point[3 * i..3 * i + 3].copy_from_slice(&p.to_array());
                    distance[i] = d;
                }
            })
        })?;
        Ok((point_out, distance_out, rows))
    }

    /// Distance from each point to the surface (inf where there is none); negative
    /// inside where `signed` (a winding number above one half).
    #[pyo3(signature = (points, signed, threads=None))]
    fn distances<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        signed: bool,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let queries = arrays::points("points", &points)?;
        let point = |i: usize| Vec3::from(queries[i]);
        self.per_row(
            py,
            queries.len(),
            threads,
            point,
            point,
            |tlas, q| match signed {
                true => tlas.signed_distance(q),
                false => tlas.distance(q),
            },
        )
    }

    /// Whether each point lies inside (a winding number above one half).
    #[pyo3(signature = (points, threads=None))]
    fn inside<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let queries = arrays::points("points", &points)?;
        let point = |i: usize| Vec3::from(queries[i]);
        self.per_row(py, queries.len(), threads, point, point, |tlas, q| {
            tlas.contains(q)
        })
    }

    /// The generalised winding number of the surface at each point (1 inside a closed
    /// surface, 0 outside).
    #[pyo3(signature = (points, threads=None))]
    fn winding_numbers<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let queries = arrays::points("points", &points)?;
        let point = |i: usize| Vec3::from(queries[i]);
        self.per_row(py, queries.len(), threads, point, point, |tlas, q| {
            tlas.winding_number(q)
        })
    }

    /// How many times each ray crosses the surface within [tnear, tfar] (or, with
    /// `per_triangle`, how many triangles it hits).
    #[pyo3(signature = (origins, directions, tnear, tfar, mask, per_triangle, threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn count_intersections<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'py, f32>,
        directions: Option<PyReadonlyArray2<'py, f32>>,
        tnear: Bound<'py, PyAny>,
        tfar: Bound<'py, PyAny>,
        mask: u32,
        per_triangle: bool,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let (mut near, mut far) = (None, None);
        let batch = batch(&origins, &directions, &tnear, &mut near, &tfar, &mut far)?;
        let along = hits_along(per_triangle);
        let (origin, ray) = (|i| batch.origin(i), |i| batch.ray(i));
        self.per_batch(py, batch.len(), threads, origin, ray, |tlas, rays, out| {
            let mut counts = [0; POINT_CHUNK];
            let counts = &mut counts[..rays.len()];
            tlas.count_hits_each(rays, mask, along, counts);
            for (o, &count) in out.iter_mut().zip(counts.iter()) {
                *o = count as i64;
            }
        })
    }

    /// The hits of each ray within [tnear, tfar], nearest first, one per crossing of the
    /// surface (or, with `per_triangle`, one per triangle hit): (ray_splits, ray, t,
    /// then the rows of [`HitRows`]); ray i's hits are rows ray_splits[i]..ray_splits[i+1].
    #[pyo3(signature = (origins, directions, tnear, tfar, mask, per_triangle, threads=None))]
    #[allow(clippy::type_complexity, clippy::too_many_arguments)]
    fn list_intersections<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'py, f32>,
        directions: Option<PyReadonlyArray2<'py, f32>>,
        tnear: Bound<'py, PyAny>,
        tfar: Bound<'py, PyAny>,
        mask: u32,
        per_triangle: bool,
        threads: Option<usize>,
    ) -> PyResult<(
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<f32>>,
        Rows<'py>,
    )> {
        let (mut near, mut far) = (None, None);
        let batch = batch(&origins, &directions, &tnear, &mut near, &tfar, &mut far)?;
        let along = hits_along(per_triangle);
        let n = batch.len();
        let tlas = py.detach(|| self.tlas(threads))?;
        // Rays are traced in the order of their origins where that pays (as `per_row`
        // answers them). Each task lists its rays' hits in one vector (no allocation per
        // ray); the hits are then written out in the caller's order of rays.
        let order =
            py.detach(|| pools::install(threads, || query_order(&tlas, n, |i| batch.origin(i))))?;
        let ray_at = |k: usize| order.as_ref().map_or(k, |o| o.indices()[k] as usize);
        let per_task: Vec<(Vec<usize>, Vec<Hit>)> = py.detach(|| {
            pools::install(threads, || {
                (0..n.div_ceil(POINT_CHUNK))
                    .into_par_iter()
                    .map(|task| {
                        let traced = task * POINT_CHUNK..((task + 1) * POINT_CHUNK).min(n);
                        // Gathered first, as `RayOrder::answer_into` does.
                        let rays: Vec<Ray> = traced.map(|k| batch.ray(ray_at(k))).collect();
                        let mut counts = vec![0; rays.len()];
                        let mut hits = Vec::new();
                        tlas.hits_each(&rays, mask, along, &mut hits, &mut counts);
                        (counts, hits)
                    })
                    .collect()
            })
        })?;
        // The k-th traced ray's hits: where they start in its task's list, and how many.
        let mut traced_hits = Vec::with_capacity(n);
        for (counts, _) in &per_task {
            let mut first = 0;
            for &count in counts {
                traced_hits.push((first, count));
                first += count;
            }
        }
        let hits_of = |k: usize| {
            let (first, count) = traced_hits[k];
            &per_task[k / POINT_CHUNK].1[first..first + count]
        };
        let rank = |i: usize| order.as_ref().map_or(i, |o| o.ranks()[i] as usize);
        let splits_out = PyArray1::<i64>::zeros(py, n + 1, false);
        // SAFETY: the array was just made here and nothing else refers to it yet.
        let splits = unsafe { splits_out.as_slice_mut().expect("contiguous") };
        let mut total = 0;
        for (i, split) in splits[..n].iter_mut().enumerate() {
            *split = total as i64;
            total += traced_hits[rank(i)].1;
        }
        splits[n] = total as i64;
        let ray_out = PyArray1::<i64>::zeros(py, total, false);
        let t_out = PyArray1::<f32>::zeros(py, total, false);
        let rows = hit_arrays(py, total);
        // SAFETY: the arrays were just made here and nothing else refers to them yet.
        let (mut ray, mut t, mut all) = unsafe {
            (
                ray_out.as_slice_mut().expect("contiguous"),
                t_out.as_slice_mut().expect("contiguous"),
                hit_rows(&rows),
            )
        };
        // The rows are written in parallel, each run of rays into its own part of the
        // arrays (the normals alone are a third of a list's time).
        let mut parts = Vec::new();
        for first in (0..n).step_by(ROWS_CHUNK) {
            let rays = first..(first + ROWS_CHUNK).min(n);
            let rows_here = splits[rays.end] as usize - splits[first] as usize;
            let (ray_here, ray_rest) = std::mem::take(&mut ray).split_at_mut(rows_here);
            let (t_here, t_rest) = std::mem::take(&mut t).split_at_mut(rows_here);
            let (all_here, all_rest) = all.split_at(rows_here);
            parts.push((rays, ray_here, t_here, all_here));
            (ray, t, all) = (ray_rest, t_rest, all_rest);
        }
        py.detach(|| {
            pools::install(threads, || {
                parts.into_par_iter().for_each(|(rays, ray, t, mut all)| {
                    let mut row = 0;
                    for i in rays {
                        for hit in hits_of(rank(i)) {
                            (ray[row], t[row]) = (i as i64, hit.t);
                            all.write(&tlas, row, Some(*hit));
                            row += 1;
                        }
                    }
                    debug_assert_eq!(row, ray.len(), "every row of the part written");
                })
            })
        })?;
        Ok((splits_out, ray_out, t_out, rows))
    }

    fn __repr__(&self) -> String {
        format!(
            "RayScene({} geometries, {} instances)",
            self.meshes.len(),
            self.instances.len()
        )
    }
}
