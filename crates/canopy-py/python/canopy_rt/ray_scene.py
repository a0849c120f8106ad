"""Ray and point queries over several meshes placed by instances, as Embree's and
Open3D's ray-casting scenes answer them: each mesh gets its own BVH once, a top-level BVH
over the instances' world boxes finds the instance a ray (or a point's neighbourhood)
meets, and the query continues through the mesh's tree in the mesh's own space.

Point queries (Open3D's names): nearest points, distances, signed distances and
occupancy, the inside test by generalised winding number; every hit along a ray,
counted or listed.

>>> import numpy as np, canopy_rt as canopy
>>> scene = canopy.RayScene()
>>> tri = scene.add_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
>>> below = np.eye(4); below[2, 3] = -2
>>> copy = scene.add_instance(tri, below)
>>> hits = scene.intersect([[0.2, 0.2, 1.0], [0.2, 0.2, -1.0]], [[0, 0, -1], [0, 0, -1]])
>>> hits.t.tolist(), hits.instance.tolist(), hits.normal[0].tolist()
([1.0, 1.0], [0, 1], [0.0, 0.0, 1.0])
"""

from __future__ import annotations

from typing import NamedTuple, Optional

import numpy as np

from . import _canopy
from ._arguments import naming_arguments_of_methods
from .scene import _transform

EVERY_RAY = 0xFFFFFFFF
"""The mask of an instance every ray sees, and of a ray that sees every instance."""


class RayHits(NamedTuple):
    """Closest hits of a batch of rays, one row per ray."""

    t: np.ndarray
    """(n,) float32 distance along the ray (in units of its direction's length); inf on a miss."""
    instance: np.ndarray
    """(n,) int64 index of the instance hit (in the order added); -1 on a miss."""
    geometry: np.ndarray
    """(n,) int64 index of that instance's geometry; -1 on a miss."""
    prim: np.ndarray
    """(n,) int64 index of the triangle (face row) in its geometry; -1 on a miss."""
    uv: np.ndarray
    """(n, 2) float32 barycentric weights of the triangle's vertices 1 and 2 (0 on a miss)."""
    normal: np.ndarray
    """(n, 3) float32 unit geometric normal, (v1 - v0) x (v2 - v0), in world space (0 on a miss)."""


class ClosestPoints(NamedTuple):
    """The nearest surface point to each query point, one row per query point."""

    point: np.ndarray
    """(n, 3) float32 the nearest point (NaN where nothing is within ``max_distance``)."""
    distance: np.ndarray
    """(n,) float32 its distance from the query point (inf where there is none)."""
    instance: np.ndarray
    """(n,) int64 index of the instance it lies on; -1 where there is none."""
    geometry: np.ndarray
    """(n,) int64 index of that instance's geometry; -1 where there is none."""
    prim: np.ndarray
    """(n,) int64 index of the triangle; -1 where there is none."""
    uv: np.ndarray
    """(n, 2) float32 barycentric weights of the triangle's vertices 1 and 2 there."""
    normal: np.ndarray
    """(n, 3) float32 unit geometric normal of the triangle, in world space."""


class RayHitLists(NamedTuple):
    """Every hit of a batch of rays, nearest first within each ray: the hits of ray
    ``i`` are rows ``ray_splits[i]:ray_splits[i + 1]``."""

    ray_splits: np.ndarray
    """(n + 1,) int64 where each ray's rows begin (and the last one ends)."""
    ray: np.ndarray
    """(m,) int64 the ray each row belongs to."""
    t: np.ndarray
    """(m,) float32 distance along the ray (in units of its direction's length)."""
    instance: np.ndarray
    """(m,) int64 index of the instance hit."""
    geometry: np.ndarray
    """(m,) int64 index of that instance's geometry."""
    prim: np.ndarray
    """(m,) int64 index of the triangle."""
    uv: np.ndarray
    """(m, 2) float32 barycentric weights of the triangle's vertices 1 and 2."""
    normal: np.ndarray
    """(m, 3) float32 unit geometric normal, in world space."""


def _mask(mask) -> int:
    mask = int(mask)
    if not 0 <= mask <= EVERY_RAY:
        raise ValueError(f"mask must be a 32-bit unsigned integer, not {mask}")
    return mask


@naming_arguments_of_methods
class RayScene:
    """Triangle meshes, each stored and built once, placed by any number of instances
    (any invertible affine transform: rotations, mirrors, non-uniform scale), each with
    a 32-bit mask that rays select by. ``builder`` and ``width`` choose the BVHs, and
    ``triangles`` how ray queries test triangles, as for :class:`canopy.Bvh`:
    ``"watertight"`` (the default) or ``"fast"`` (Embree's default test; crossing counts
    and lists always use exact signs). The top-level tree is rebuilt at the first query after
    instances change (milliseconds for thousands).

    Rays are ``origins`` and ``directions`` (n, 3), or one (n, 6) array of origin and
    direction rows (Open3D's). A scene pickles (for ``multiprocessing``, Ray's object
    store): the pickle holds its meshes and instances, and the trees are built again."""

    def __init__(self, *, builder: str = "binned-sah", width: int = 8, triangles: str = "watertight"):
        if not isinstance(builder, str):
            raise TypeError(f"builder must be a name (see canopy_rt.builders()), not {builder!r}")
        self._native = _canopy.RayScene(builder, int(width), str(triangles))

    @property
    def triangles(self) -> str:
        """How ray queries test triangles: ``"watertight"`` or ``"fast"``."""
        return self._native.triangles

    def __getstate__(self) -> dict:
        # The meshes and instances; unpickling builds the trees again (see Bvh).
        builder, width, geometries, instances = self._native.state()
        return {"builder": builder, "width": width, "triangles": self.triangles,
                "geometries": geometries, "instances": instances}

    def __setstate__(self, state: dict) -> None:
        self.__init__(builder=state["builder"], width=state["width"],
                      triangles=state.get("triangles", "watertight"))
        for vertices, faces in state["geometries"]:
            self.add_geometry(vertices, faces)
        for geometry, transform, mask in state["instances"]:
            self.add_instance(geometry, transform, mask=mask)

    def add_geometry(self, vertices, faces, *, threads: Optional[int] = None) -> int:
        """Adds a triangle mesh (``vertices`` (V, 3), ``faces`` (F, 3)) without placing
        it; returns its geometry index for :meth:`add_instance`."""
        from . import _array

        vertices = _array(vertices, "vertices", np.float32, 2, "(V, 3)")
        faces = _array(faces, "faces", np.int64, 2, "(F, 3)")
        return self._native.add_geometry(vertices, faces, threads)

    def add_mesh(self, vertices, faces, transform=None, *, mask: int = EVERY_RAY,
                 threads: Optional[int] = None) -> int:
        """Adds a triangle mesh and places one instance of it by ``transform`` (4x4 or
        3x4; identity by default), as Open3D's ``add_triangles`` does; returns the
        geometry's index (its instance is the last one added)."""
        geometry = self.add_geometry(vertices, faces, threads=threads)
        self.add_instance(geometry, transform, mask=mask)
        return geometry

    def add_instance(self, geometry: int, transform=None, *, mask: int = EVERY_RAY) -> int:
        """Places ``geometry`` by ``transform``; returns the instance's index, which hits
        report. The geometry is not copied."""
        return self._native.add_instance(int(geometry), _transform(transform), _mask(mask))

    def set_transform(self, instance: int, transform) -> None:
        """Moves an instance (the top-level tree is rebuilt at the next query)."""
        self._native.set_transform(int(instance), _transform(transform))

    def set_vertices(self, geometry: int, vertices, *, threads: Optional[int] = None) -> None:
        """Moves a geometry's vertices (``vertices`` (V, 3), as many as it has; its
        triangles stay) and refits its tree: every box recomputed, the topology kept,
        far faster than a new build (a tree whose nodes overlap more after large moves
        traces more slowly). Every instance of the geometry moves with it. Refused for a
        tree built with spatial splits (``builder="sbvh"``)."""
        from . import _array

        vertices = _array(vertices, "vertices", np.float32, 2, "(V, 3)")
        self._native.set_vertices(int(geometry), vertices, threads)

    @property
    def geometry_count(self) -> int:
        return self._native.geometry_count

    @property
    def instance_count(self) -> int:
        return self._native.instance_count

    def _rays(self, origins, directions, tnear, tfar):
        from . import _ray_batch

        return _ray_batch(origins, directions, tnear, tfar)

    def intersect(self, origins, directions=None, tnear=0.0, tfar=np.inf, *, mask: int = EVERY_RAY,
                  threads: Optional[int] = None) -> RayHits:
        """Closest hits of the rays ``origin + t * direction``, ``tnear <= t <= tfar``,
        among the instances whose mask shares a bit with ``mask``. Ties go to the lower
        instance, then the lower triangle."""
        hits = self._native.intersect(*self._rays(origins, directions, tnear, tfar), _mask(mask), threads)
        return RayHits(*hits)

    def occluded(self, origins, directions=None, tnear=0.0, tfar=np.inf, *, mask: int = EVERY_RAY,
                 threads: Optional[int] = None) -> np.ndarray:
        """(n,) bool: whether anything ``mask`` sees lies on each ray within its range."""
        return self._native.occluded(*self._rays(origins, directions, tnear, tfar), _mask(mask), threads)

    def _points(self, points) -> np.ndarray:
        from . import _array

        return _array(points, "points", np.float32, 2, "(n, 3)")

    def compute_closest_points(self, points, max_distance: float = np.inf, *,
                               threads: Optional[int] = None) -> ClosestPoints:
        """The nearest point of every instance's surface to each of ``points`` (n, 3),
        looked for no farther than ``max_distance``. Equal distances go to the lower
        instance, then the lower triangle."""
        point, distance, rows = self._native.closest_points(
            self._points(points), float(max_distance), threads)
        return ClosestPoints(point, distance, *rows)

    def compute_distance(self, points, *, threads: Optional[int] = None) -> np.ndarray:
        """(n,) float32 distance from each point to the surface (inf with no surface)."""
        return self._native.distances(self._points(points), False, threads)

    def compute_signed_distance(self, points, *, threads: Optional[int] = None) -> np.ndarray:
        """(n,) float32 distance to the surface, negative inside (as Open3D's; trimesh's
        ``signed_distance`` is positive inside). Inside is where the winding number is
        above one half: see :meth:`winding_number`."""
        return self._native.distances(self._points(points), True, threads)

    def winding_number(self, points, *, threads: Optional[int] = None) -> np.ndarray:
        """(n,) float64 generalised winding number of the surface at each point: 1 inside
        a closed surface whose triangles face out (counter-clockwise seen from outside),
        0 outside, fractional near holes; overlapping instances add up. Robust where ray
        parity is not (holes, duplicated or overlapping triangles, rays through edges),
        and the same for every choice of rays. Computed with Barill et al.'s
        second-order far field (within about 1e-2 of the exact sum)."""
        return self._native.winding_numbers(self._points(points), threads)

    def compute_occupancy(self, points, *, threads: Optional[int] = None) -> np.ndarray:
        """(n,) bool: whether each point lies inside: a winding number above one half,
        computed only as accurately as that needs (to about 0.1). Open3D returns the
        same as 0.0 and 1.0."""
        return self._native.inside(self._points(points), threads)

    def count_intersections(self, origins, directions=None, tnear=0.0, tfar=np.inf, *,
                            mask: int = EVERY_RAY, per_triangle: bool = False,
                            threads: Optional[int] = None) -> np.ndarray:
        """(n,) int64 how many times each ray crosses the surface within its range.

        A ray through an edge or a vertex that triangles share crosses there once, so a
        ray through a closed mesh from outside crosses it an even number of times
        wherever it passes (the exact tie rule of symbolic perturbation; a ray that only
        grazes an edge counts 0 or 2). Coincident triangles facing apart are two
        crossings. ``per_triangle=True`` counts every triangle hit instead (a ray
        through a shared edge hits each triangle around it)."""
        return self._native.count_intersections(
            *self._rays(origins, directions, tnear, tfar), _mask(mask), bool(per_triangle), threads)

    def list_intersections(self, origins, directions=None, tnear=0.0, tfar=np.inf, *,
                           mask: int = EVERY_RAY, per_triangle: bool = False,
                           threads: Optional[int] = None) -> RayHitLists:
        """Each crossing of the surface by each ray within its range, nearest first
        (equal distances by instance, then triangle): the rows
        :meth:`count_intersections` counts, one triangle for each crossing.
        ``per_triangle=True`` lists every triangle hit instead."""
        lists = self._native.list_intersections(
            *self._rays(origins, directions, tnear, tfar), _mask(mask), bool(per_triangle), threads)
        splits, ray, t, rows = lists
        return RayHitLists(splits, ray, t, *rows)

    def __repr__(self) -> str:
        return repr(self._native)
