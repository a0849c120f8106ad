"""canopy behind trimesh's ray queries gives trimesh's own answers."""

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh", reason="trimesh is installed by scripts/test.sh")

import canopy_rt.trimesh_ray  # noqa: E402
from conftest import MESHES  # noqa: E402


def meshes():
    yield "icosphere", trimesh.creation.icosphere(subdivisions=3)
    yield "box", trimesh.creation.box(extents=[1, 2, 3])
    yield "teapot", trimesh.load(MESHES / "teapot.ply", force="mesh")
    yield "bunny", trimesh.load(MESHES / "bunny.ply", force="mesh")


def rays(mesh, n=2000, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds
    size = hi - lo
    origins = lo - 0.5 * size + rng.random((n, 3)) * 2 * size
    targets = lo + rng.random((n, 3)) * size
    return origins, targets - origins


@pytest.mark.parametrize("name, mesh", list(meshes()), ids=lambda x: x if isinstance(x, str) else "")
def test_queries_match_trimesh(name, mesh):
    origins, directions = rays(mesh)
    theirs = trimesh.ray.ray_triangle.RayMeshIntersector(mesh)
    ours = canopy_rt.trimesh_ray.RayMeshIntersector(mesh)

    first_theirs = theirs.intersects_first(origins, directions)
    first_ours = ours.intersects_first(origins, directions)
    same = first_theirs == first_ours
    # Rays through shared edges may report either triangle; nearly all agree exactly.
    assert same.mean() > 0.995, (name, same.mean())
    np.testing.assert_array_equal(
        theirs.intersects_any(origins, directions), ours.intersects_any(origins, directions)
    )

    loc_t, ray_t, tri_t = theirs.intersects_location(origins, directions, multiple_hits=True)
    loc_o, ray_o, tri_o = ours.intersects_location(origins, directions, multiple_hits=True)
    # Hits per ray agree (edge rays aside), and so do the points.
    count_t = np.bincount(ray_t, minlength=len(origins))
    count_o = np.bincount(ray_o, minlength=len(origins))
    assert np.mean(count_t == count_o) > 0.99, name
    for r in np.flatnonzero(count_t == count_o)[:300]:
        a = loc_t[ray_t == r]
        b = loc_o[ray_o == r]
        a = a[np.argsort(np.linalg.norm(a - origins[r], axis=1))]
        np.testing.assert_allclose(a, b, atol=1e-4 * float(np.max(mesh.extents)))

    loc_t, ray_t, _ = theirs.intersects_location(origins, directions, multiple_hits=False)
    loc_o, ray_o, _ = ours.intersects_location(origins, directions, multiple_hits=False)
    assert abs(len(ray_t) - len(ray_o)) <= 0.005 * len(origins)


def test_contains_points_matches_trimesh():
    mesh = trimesh.creation.icosphere(subdivisions=2)
    points = np.random.default_rng(1).random((500, 3)) * 2.4 - 1.2
    ours = canopy_rt.trimesh_ray.RayMeshIntersector(mesh).contains_points(points)
    expected = np.linalg.norm(points, axis=1) < 1.0
    # The icosphere is inside the unit sphere: points between the two may differ.
    between = (np.linalg.norm(points, axis=1) > 0.95) & (np.linalg.norm(points, axis=1) < 1.0)
    np.testing.assert_array_equal(ours[~between], expected[~between])


def test_the_engine_follows_edits_pickles_and_takes_lazy_and_empty_meshes():
    """The causes of trimesh's own ray tests failing, each on its own: answers after an
    edit come from the edited mesh; the intersector pickles (for multiprocessing);
    trimesh's primitives and an empty mesh work; a small box far from the origin is hit
    where it is, with the location on its face in float64."""
    import pickle

    mesh = trimesh.creation.box()
    ray = canopy_rt.trimesh_ray.RayMeshIntersector(mesh)
    origin, direction = [[0, 0, 5]], [[0, 0, -1]]
    assert ray.intersects_any(origin, direction).all()
    mesh.apply_translation([10, 0, 0])
    assert not ray.intersects_any(origin, direction).any()
    assert ray.intersects_any([[10, 0, 5]], direction).all()

    again = pickle.loads(pickle.dumps(mesh))
    again.ray = pickle.loads(pickle.dumps(ray))
    assert again.ray.intersects_any([[10, 0, 5]], direction).all()

    primitive = trimesh.primitives.Box(extents=[1, 1, 1])
    assert canopy_rt.trimesh_ray.RayMeshIntersector(primitive).intersects_any(origin, direction).all()
    empty = canopy_rt.trimesh_ray.RayMeshIntersector(trimesh.Trimesh())
    assert list(empty.intersects_first(origin, direction)) == [-1]
    assert len(empty.intersects_id(origin, direction)[0]) == 0

    far = trimesh.creation.box(extents=[1, 1, 1])
    far.apply_translation([1e7, 0, 0])
    locations, index_ray, _ = canopy_rt.trimesh_ray.RayMeshIntersector(far).intersects_location(
        [[1e7, 0, 100]], direction
    )
    assert list(index_ray) == [0, 0]
    np.testing.assert_allclose(locations[:, 2], [0.5, -0.5], atol=1e-9)
