"""canopy.RayScene's point queries (nearest points, distances, signed distances,
occupancy, winding numbers) and every hit along a ray, against trimesh's own
implementations and brute force in float64, for a mesh alone and for placed instances."""

import numpy as np
import pytest
import trimesh

import canopy_rt as canopy
from test_ray_scene import random_transform


def scene_of(*placed, **options):
    """A RayScene of (mesh, transform) pairs, each mesh its own geometry."""
    scene = canopy.RayScene(**options)
    for mesh, transform in placed:
        scene.add_mesh(mesh.vertices, mesh.faces, transform)
    return scene


def torus():
    return trimesh.creation.torus(major_radius=1.0, minor_radius=0.35, major_sections=48,
                                  minor_sections=24)


def query_points(rng, n, scale):
    return rng.uniform(-scale, scale, size=(n, 3)).astype(np.float32)


@pytest.mark.parametrize("builder,width", [("binned-sah", 8), ("sbvh", 4), ("ploc", 2), ("none", 2)])
def test_nearest_points_match_trimesh(builder, width):
    mesh = torus()
    scene = scene_of((mesh, None), builder=builder, width=width)
    points = query_points(np.random.default_rng(1), 500, 2.0)
    found = scene.compute_closest_points(points)
    closest, distance, triangle = trimesh.proximity.closest_point(mesh, points.astype(np.float64))
    np.testing.assert_allclose(found.distance, distance, atol=1e-5)
    # Points and triangles differ only where two are (nearly) equally near: an edge or
    # vertex is nearest, or points on the torus's axis see a whole circle.
    same = found.prim == triangle
    assert same.mean() > 0.5
    np.testing.assert_allclose(found.point[same], closest[same], atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(found.point - points, axis=1), found.distance, rtol=1e-5)
    assert np.all(found.instance == 0) and np.all(found.geometry == 0)
    faces = mesh.vertices[mesh.faces[found.prim]]
    at = faces[:, 0] + found.uv[:, :1] * (faces[:, 1] - faces[:, 0]) + found.uv[:, 1:] * (faces[:, 2] - faces[:, 0])
    np.testing.assert_allclose(at, found.point, atol=1e-5)
    np.testing.assert_allclose(found.normal, mesh.face_normals[found.prim], atol=1e-5)
    np.testing.assert_array_equal(scene.compute_distance(points), found.distance)


def test_signed_distance_and_occupancy_agree_with_trimesh_away_from_the_surface():
    mesh = torus()
    scene = scene_of((mesh, None))
    points = query_points(np.random.default_rng(2), 2000, 1.6)
    inside = scene.compute_occupancy(points)
    assert inside.dtype == np.bool_ and 0.05 < inside.mean() < 0.5
    distance = scene.compute_distance(points)
    away = distance > 1e-3
    np.testing.assert_array_equal(inside[away], mesh.contains(points[away]))
    signed = scene.compute_signed_distance(points)
    np.testing.assert_array_equal(np.abs(signed), distance)
    np.testing.assert_array_equal(signed < 0, inside)
    # trimesh's convention is the opposite sign: positive inside.
    theirs = trimesh.proximity.signed_distance(mesh, points[away][:200])
    np.testing.assert_allclose(-signed[away][:200], theirs, atol=1e-5)
    winding = scene.winding_number(points)
    assert winding.dtype == np.float64
    np.testing.assert_allclose(winding[away], inside[away].astype(float), atol=0.03)


def test_a_mesh_with_a_hole_still_has_an_inside():
    # A box without one of its twelve triangles: ray parity breaks along rays through
    # the hole; the winding number is still near 1 deep inside.
    box = trimesh.creation.box()
    scene = scene_of((trimesh.Trimesh(box.vertices, box.faces[1:], process=False), None))
    centre_and_corner = np.array([[0, 0, 0], [0.3, -0.3, 0.2], [2, 0, 0]], np.float32)
    np.testing.assert_array_equal(scene.compute_occupancy(centre_and_corner), [True, True, False])
    winding = scene.winding_number(centre_and_corner)
    assert 0.7 < winding[0] < 1.0 and abs(winding[2]) < 0.1


def test_instances_are_measured_in_the_world():
    rng = np.random.default_rng(3)
    mesh = torus()
    transforms = [random_transform(rng, mirror=i == 2) for i in range(4)]
    scene = scene_of(*[(mesh, t) for t in transforms])
    points = query_points(rng, 400, 2.5)
    found = scene.compute_closest_points(points)
    per_instance = np.stack([
        trimesh.proximity.closest_point(mesh.copy().apply_transform(t), points.astype(np.float64))[1]
        for t in transforms
    ])
    np.testing.assert_allclose(found.distance, per_instance.min(axis=0), atol=1e-5)
    clear = np.sort(per_instance, axis=0)[1] - per_instance.min(axis=0) > 1e-4
    np.testing.assert_array_equal(found.instance[clear], per_instance.argmin(axis=0)[clear])
    inside = np.stack([mesh.copy().apply_transform(t).contains(points) for t in transforms])
    away = found.distance > 1e-3
    np.testing.assert_array_equal(scene.compute_occupancy(points)[away], inside.any(axis=0)[away])


def test_every_hit_along_a_ray_is_listed_in_order_and_counted():
    mesh = torus()
    scene = scene_of((mesh, None), (mesh, None))
    # Off the planes of the tessellation's vertices: a ray along an edge meets every
    # triangle sharing it.
    origins = np.array([[-3, 0.013, 0.021], [0, 0, 5], [-3, 0.013, 0.021]], np.float32)
    directions = np.array([[1, 0, 0], [0, 0, -1], [1, 0, 0]], np.float32)
    tfar = np.array([np.inf, np.inf, 2.5], np.float32)
    lists = scene.list_intersections(origins, directions, tfar=tfar)
    counts = scene.count_intersections(origins, directions, tfar=tfar)
    np.testing.assert_array_equal(np.diff(lists.ray_splits), counts)
    # Along x through the ring: in and out of the tube twice, for each of two copies.
    assert counts.tolist() == [8, 0, 4]
    first = lists.t[lists.ray_splits[0]:lists.ray_splits[1]]
    assert np.all(np.diff(first) >= 0)
    expected = np.repeat([3 - 1.35, 3 - 0.65, 3 + 0.65, 3 + 1.35], 2)
    np.testing.assert_allclose(first, expected, atol=0.02)
    assert sorted(lists.instance[:8].tolist()) == [0] * 4 + [1] * 4
    hits = np.asarray(origins)[lists.ray][:, None] + lists.t[:, None, None] * np.asarray(directions)[lists.ray][:, None]
    faces = mesh.vertices[mesh.faces[lists.prim]]
    at = faces[:, 0] + lists.uv[:, :1] * (faces[:, 1] - faces[:, 0]) + lists.uv[:, 1:] * (faces[:, 2] - faces[:, 0])
    np.testing.assert_allclose(at, hits[:, 0], atol=1e-4)
    # Masks select instances as for closest hits.
    masked = canopy.RayScene()
    masked.add_mesh(mesh.vertices, mesh.faces, mask=1)
    masked.add_mesh(mesh.vertices, mesh.faces, mask=2)
    assert masked.count_intersections(origins[:1], directions[:1], mask=2).tolist() == [4]


def test_counts_match_brute_force_on_random_rays():
    rng = np.random.default_rng(4)
    mesh = torus()
    scene = scene_of((mesh, None))
    origins = query_points(rng, 300, 3.0)
    directions = (query_points(rng, 300, 1.2) - origins).astype(np.float32)
    counts = scene.count_intersections(origins, directions)
    locations, index_ray, _ = trimesh.ray.ray_triangle.RayMeshIntersector(mesh).intersects_location(
        origins, directions, multiple_hits=True)
    theirs = np.bincount(index_ray, minlength=300)
    # Rays through an edge may be counted once or twice by either; none here.
    assert (counts != theirs).sum() <= 3
    assert counts.sum() > 300


def test_large_batches_answer_every_row_as_small_ones_do():
    # A mesh whose tree outgrows the cache (32k triangles, more than 1 MiB of nodes and
    # packs) and batches above 4096 rows are answered in the order of their origins;
    # the answers must come back to their rows, as batches of 1000 (in the caller's
    # order) give them.
    mesh = trimesh.creation.torus(major_radius=1.0, minor_radius=0.35, major_sections=256,
                                  minor_sections=64)
    assert len(mesh.faces) >= 32_000
    scene = scene_of((mesh, None))
    rng = np.random.default_rng(8)
    points = query_points(rng, 9000, 1.6)
    directions = rng.normal(size=points.shape).astype(np.float32)

    def in_pieces(call, *arrays):
        pieces = [call(*(a[i:i + 1000] for a in arrays)) for i in range(0, len(points), 1000)]
        return pieces

    def same(whole, pieces):
        np.testing.assert_array_equal(whole, np.concatenate(pieces))

    same(scene.compute_distance(points), in_pieces(scene.compute_distance, points))
    same(scene.compute_occupancy(points), in_pieces(scene.compute_occupancy, points))
    same(scene.winding_number(points), in_pieces(scene.winding_number, points))
    whole = scene.compute_closest_points(points)
    pieces = in_pieces(scene.compute_closest_points, points)
    for field in ("point", "distance", "prim", "uv", "normal"):
        same(getattr(whole, field), [getattr(p, field) for p in pieces])
    counts = scene.count_intersections(points, directions)
    same(counts, in_pieces(scene.count_intersections, points, directions))
    assert counts.sum() > 1000
    lists = scene.list_intersections(points, directions)
    np.testing.assert_array_equal(np.diff(lists.ray_splits), counts)
    pieces = in_pieces(scene.list_intersections, points, directions)
    for field in ("t", "prim", "instance", "uv", "normal"):
        same(getattr(lists, field), [getattr(p, field) for p in pieces])
    same(lists.ray, [p.ray + 1000 * i for i, p in enumerate(pieces)])


def test_threads_give_the_same_answers():
    mesh = torus()
    scene = scene_of((mesh, None))
    points = query_points(np.random.default_rng(5), 3000, 2.0)
    one = scene.compute_closest_points(points, threads=1)
    every = scene.compute_closest_points(points)
    for a, b in zip(one, every):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(scene.winding_number(points, threads=1), scene.winding_number(points))


def test_limits_empty_scenes_and_bad_input():
    mesh = torus()
    scene = scene_of((mesh, None))
    far = np.array([[0, 0, 10]], np.float32)
    miss = scene.compute_closest_points(far, max_distance=5.0)
    assert miss.distance.tolist() == [np.inf] and miss.prim.tolist() == [-1]
    assert np.isnan(miss.point).all()
    assert scene.compute_closest_points(far, max_distance=10.0).prim[0] >= 0
    empty = canopy.RayScene()
    assert empty.compute_distance(far).tolist() == [np.inf]
    assert empty.compute_occupancy(far).tolist() == [False]
    assert empty.count_intersections(far, [[0, 0, -1]]).tolist() == [0]
    assert empty.compute_closest_points(np.zeros((0, 3))).distance.shape == (0,)
    with pytest.raises(ValueError, match=r"points\[1\].*not finite"):
        scene.compute_distance([[0, 0, 0], [np.nan, 0, 0]])
    with pytest.raises(ValueError, match=r"points must have shape \(n, 3\)"):
        scene.compute_signed_distance(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="max_distance"):
        scene.compute_closest_points(far, max_distance=-1.0)
