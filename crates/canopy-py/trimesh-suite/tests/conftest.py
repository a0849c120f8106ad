"""trimesh's own ray tests (trimesh 5.2.0, MIT; see ../LICENSE-trimesh.md) with canopy's
engine installed in place of both of trimesh's: `trimesh.ray.ray_triangle` and the
Embree-based `trimesh.ray.ray_pyembree`. The session fails if canopy's engine was never
used, so a passing run cannot be trimesh's own engine passing."""

import trimesh
import trimesh.ray.ray_pyembree
import trimesh.ray.ray_triangle

import canopy_rt.trimesh_ray

_made = []


class _Counted(canopy_rt.trimesh_ray.RayMeshIntersector):
    def __init__(self, *args, **kwargs):
        _made.append(1)
        super().__init__(*args, **kwargs)


trimesh.ray.ray_triangle.RayMeshIntersector = _Counted
trimesh.ray.ray_pyembree.RayMeshIntersector = _Counted


def pytest_sessionfinish(session, exitstatus):
    if session.testscollected and not _made:
        raise RuntimeError("canopy's intersector was never used: the tests ran trimesh's own")
