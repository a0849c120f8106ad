"""canopy as the ray engine of `trimesh <https://trimesh.org>`_ meshes.

>>> import trimesh, canopy.trimesh_ray
>>> mesh = trimesh.creation.icosphere()
>>> mesh.ray = canopy.trimesh_ray.RayMeshIntersector(mesh)
>>> mesh.ray.intersects_first([[0, 0, -5]], [[0, 0, 1]])
array([...])

It answers the queries of trimesh's own intersectors (``trimesh.ray.ray_triangle`` and
the Embree-based ``ray_pyembree``) with the same signatures and conventions: directions
are normalised, so distances and locations are in the mesh's units; triangle and ray
indices are int64. trimesh is needed only to make the mesh; this module imports nothing
from it.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from . import Bvh

# How far past a hit the next search of a ray starts, relative to the scene's size.
_STEP = 1e-5


def _unit(directions: np.ndarray) -> np.ndarray:
    d = np.asarray(directions, dtype=np.float64)
    length = np.linalg.norm(d, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(length > 0, d / length, 0.0)


class RayMeshIntersector:
    """Ray queries on a trimesh ``Trimesh`` through a canopy BVH, built once."""

    def __init__(self, mesh, builder: str = "binned-sah", width: int = 8, threads: Optional[int] = None):
        self.mesh = mesh
        self._threads = threads
        self._bvh = Bvh(
            np.asarray(mesh.vertices, dtype=np.float32),
            np.asarray(mesh.faces, dtype=np.int64),
            builder=builder,
            width=width,
            threads=threads,
        )
        self._step = _STEP * max(float(np.max(mesh.extents)), 1e-12)

    def _cast(self, origins, directions, tnear=0.0):
        return self._bvh.intersect(origins, directions, tnear=tnear, threads=self._threads)

    def intersects_first(self, ray_origins, ray_directions) -> np.ndarray:
        """Index of the first triangle each ray hits, -1 where it hits none."""
        hits = self._cast(ray_origins, _unit(ray_directions))
        return hits.prim

    def intersects_any(self, ray_origins, ray_directions) -> np.ndarray:
        """Whether each ray hits the mesh at all."""
        return self._bvh.occluded(ray_origins, _unit(ray_directions), threads=self._threads)

    def intersects_id(
        self,
        ray_origins,
        ray_directions,
        multiple_hits: bool = True,
        max_hits: int = 20,
        return_locations: bool = False,
    ):
        """Triangle and ray index of every hit (the first only unless ``multiple_hits``,
        at most ``max_hits`` per ray), and with ``return_locations`` the hit points."""
        origins = np.asarray(ray_origins, dtype=np.float64)
        directions = _unit(ray_directions)
        tnear = np.zeros(len(origins), dtype=np.float32)
        active = np.arange(len(origins))
        tris, rays, ts = [], [], []
        rounds = max_hits if multiple_hits else 1
        for _ in range(rounds):
            if len(active) == 0:
                break
            hits = self._cast(origins[active], directions[active], tnear[active])
            hit = hits.prim >= 0
            tris.append(hits.prim[hit])
            rays.append(active[hit])
            ts.append(hits.t[hit].astype(np.float64))
            # Go on past this hit: a small step relative to the scene, never backwards.
            tnear[active[hit]] = hits.t[hit] + self._step
            active = active[hit]
        index_tri = np.concatenate(tris) if tris else np.zeros(0, dtype=np.int64)
        index_ray = np.concatenate(rays) if rays else np.zeros(0, dtype=np.int64)
        order = np.lexsort((np.concatenate(ts) if ts else np.zeros(0), index_ray))
        index_tri, index_ray = index_tri[order], index_ray[order]
        if not return_locations:
            return index_tri, index_ray
        t = (np.concatenate(ts) if ts else np.zeros(0))[order]
        locations = origins[index_ray] + directions[index_ray] * t[:, None]
        return index_tri, index_ray, locations

    def intersects_location(self, ray_origins, ray_directions, multiple_hits: bool = True):
        """Hit points, with the ray and triangle index of each."""
        index_tri, index_ray, locations = self.intersects_id(
            ray_origins, ray_directions, multiple_hits=multiple_hits, return_locations=True
        )
        return locations, index_ray, index_tri

    def contains_points(self, points) -> np.ndarray:
        """Whether each point is inside the (closed) mesh: an odd number of crossings of a
        ray from it in a fixed, generic direction."""
        points = np.asarray(points, dtype=np.float64)
        direction = np.tile(_unit([[0.4395064455, 0.617598629942, 0.652231566745]]), (len(points), 1))
        _, index_ray = self.intersects_id(points, direction, multiple_hits=True, max_hits=1000)
        crossings = np.bincount(index_ray, minlength=len(points))
        return crossings % 2 == 1
