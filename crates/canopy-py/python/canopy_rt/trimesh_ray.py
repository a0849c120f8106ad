"""canopy as the ray engine of `trimesh <https://trimesh.org>`_ meshes.

>>> import trimesh, canopy_rt.trimesh_ray
>>> mesh = trimesh.creation.icosphere()
>>> mesh.ray = canopy_rt.trimesh_ray.RayMeshIntersector(mesh)
>>> mesh.ray.intersects_first([[0, 0, -5]], [[0, 0, 1]])
array([...])

It answers the queries of trimesh's own intersectors (``trimesh.ray.ray_triangle`` and
the Embree-based ``ray_pyembree``) with the same signatures and conventions, and passes
trimesh's own ray tests installed in their place:

- directions are normalised, so distances and locations are in the mesh's units;
  triangle and ray indices are int64; ``max_hits`` is 100, as with Embree;
- the BVH is built at the first query, and again whenever the mesh has changed since
  (keyed on the mesh's content hash, as trimesh's engines are): an edited mesh never
  answers from its old shape, and meshes trimesh builds lazily (``Box``, ``Sphere``,
  empty meshes) work;
- the mesh is moved to its centre and, with ``scale_to_box`` (the default, as with
  Embree), scaled to a box about 100 units wide before it is stored in float32, so a
  small part far from the origin is hit as precisely as one at the origin;
- hit locations are recomputed in float64 on the plane of the face hit, as trimesh does;
- the intersector pickles (without its BVH, rebuilt on first use), so meshes carrying it
  go through ``multiprocessing``.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from . import Bvh

# How far past a hit the next search along a ray starts, relative to the mesh's size (in
# the scaled space, where the mesh is about 100 units wide with `scale_to_box`); doubled
# each time the same triangle is found again.
_STEP = 1e-6
_STEP_FLOOR = 1e-8


def _unit(directions: np.ndarray) -> np.ndarray:
    d = np.asarray(directions, dtype=np.float64)
    length = np.linalg.norm(d, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(length > 0, d / length, 0.0)


def _rays(origins, directions):
    origins = np.array(origins, dtype=np.float64).reshape(-1, 3)
    directions = np.array(directions, dtype=np.float64).reshape(-1, 3)
    if origins.shape != directions.shape:
        raise ValueError("Ray origin and direction don't match!")
    return origins, _unit(directions)


class RayMeshIntersector:
    """Ray queries on a trimesh ``Trimesh`` through a canopy BVH, built at the first query
    and rebuilt when the mesh changes."""

    def __init__(
        self,
        geometry,
        scale_to_box: bool = True,
        builder: str = "binned-sah",
        width: int = 8,
        threads: Optional[int] = None,
    ):
        self.mesh = geometry
        self._scale_to_box = scale_to_box
        self._builder = builder
        self._width = width
        self._threads = threads
        self._key = None
        self._bvh = None

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_key"], state["_bvh"] = None, None
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)

    def _structure(self):
        """The BVH of the mesh as it is now (None when it has no faces), its centre and
        scale: BVH coordinates are ``(world - centre) * scale``."""
        key = self.mesh.__hash__()
        if self._key != key:
            vertices = np.asarray(self.mesh.vertices, dtype=np.float64).reshape(-1, 3)
            faces = np.asarray(self.mesh.faces, dtype=np.int64).reshape(-1, 3)
            if len(faces) == 0:
                self._bvh, self._centre, self._scale = None, np.zeros(3), 1.0
            else:
                lo, hi = vertices.min(axis=0), vertices.max(axis=0)
                size = float(np.linalg.norm(hi - lo))
                self._centre = (lo + hi) / 2.0
                self._scale = 100.0 / size if self._scale_to_box and size > 0 else 1.0
                local = ((vertices - self._centre) * self._scale).astype(np.float32)
                self._bvh = Bvh(local, faces, builder=self._builder, width=self._width, threads=self._threads)
            self._key = key
        return self._bvh

    def _local(self, origins):
        return (origins - self._centre) * self._scale

    def intersects_first(self, ray_origins, ray_directions) -> np.ndarray:
        """Index of the first triangle each ray hits, -1 where it hits none."""
        origins, directions = _rays(ray_origins, ray_directions)
        bvh = self._structure()
        if bvh is None:
            return np.full(len(origins), -1, dtype=np.int64)
        return bvh.intersect(self._local(origins), directions, threads=self._threads).prim

    def intersects_any(self, ray_origins, ray_directions) -> np.ndarray:
        """Whether each ray hits the mesh at all."""
        origins, directions = _rays(ray_origins, ray_directions)
        bvh = self._structure()
        if bvh is None:
            return np.zeros(len(origins), dtype=bool)
        return bvh.occluded(self._local(origins), directions, threads=self._threads)

    def intersects_id(
        self,
        ray_origins,
        ray_directions,
        multiple_hits: bool = True,
        max_hits: int = 100,
        return_locations: bool = False,
    ):
        """Triangle and ray index of every hit (the first only unless ``multiple_hits``,
        at most ``max_hits`` per ray), nearest first along each ray, and with
        ``return_locations`` the hit points."""
        origins, directions = _rays(ray_origins, ray_directions)
        bvh = self._structure()
        tris, rays, locations = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)], [np.zeros((0, 3))]
        if bvh is not None:
            local = self._local(origins)
            # The search along each ray starts at tnear (in BVH units), just past the
            # last hit; a triangle found twice in a row (a grazing hit, rounding) is
            # skipped with a step twice as long.
            base = max(_STEP_FLOOR, _STEP * 100.0 if self._scale_to_box else _STEP * float(self.mesh.scale))
            tnear = np.zeros(len(origins))
            step = np.full(len(origins), base)
            last = np.full(len(origins), -1, dtype=np.int64)
            live = np.arange(len(origins))
            vertices = np.asarray(self.mesh.vertices, dtype=np.float64)
            faces = np.asarray(self.mesh.faces, dtype=np.int64)
            for _ in range(max_hits if multiple_hits else 1):
                if len(live) == 0:
                    break
                hits = bvh.intersect(local[live], directions[live], tnear=tnear[live], threads=self._threads)
                found = hits.prim >= 0
                live, prim, t = live[found], hits.prim[found], hits.t[found].astype(np.float64)
                again = last[live] == prim
                last[live] = prim
                new, new_prim = live[~again], prim[~again]
                # Where the ray meets the face's plane, in float64 and world units.
                corner = vertices[faces[new_prim, 0]]
                normal = np.cross(vertices[faces[new_prim, 1]] - corner, vertices[faces[new_prim, 2]] - corner)
                with np.errstate(invalid="ignore", divide="ignore"):
                    along = np.einsum("ij,ij->i", corner - origins[new], normal) / np.einsum(
                        "ij,ij->i", directions[new], normal
                    )
                along = np.where(np.isfinite(along), along, t[~again] / self._scale)
                tris.append(new_prim)
                rays.append(new)
                locations.append(origins[new] + directions[new] * along[:, None])
                step[live[again]] *= 2.0
                step[new] = base
                tnear[live] = t + step[live]
        index_tri, index_ray = np.concatenate(tris), np.concatenate(rays)
        if not return_locations:
            return index_tri, index_ray
        return index_tri, index_ray, np.concatenate(locations)

    def intersects_location(self, ray_origins, ray_directions, multiple_hits: bool = True):
        """Hit points, with the ray and triangle index of each."""
        index_tri, index_ray, locations = self.intersects_id(
            ray_origins, ray_directions, multiple_hits=multiple_hits, return_locations=True
        )
        return locations, index_ray, index_tri

    def contains_points(self, points) -> np.ndarray:
        """Whether each point is inside the (closed) mesh, by trimesh's own ray test run
        through this intersector."""
        from trimesh.ray.ray_util import contains_points

        return contains_points(self, points)
