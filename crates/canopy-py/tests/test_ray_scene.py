"""canopy.RayScene: several meshes placed by instances, against brute force over every
instance's triangles in world space (float64), with masks, moves and bad input."""

import pickle

import numpy as np
import pytest

import canopy_rt as canopy
from conftest import edge_midpoint_rays, random_rays, random_soup


def random_transform(rng, mirror: bool) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if (np.linalg.det(q) < 0) != mirror:
        q[:, 0] = -q[:, 0]
    m = np.eye(4)
    m[:3, :3] = q @ np.diag(rng.uniform(0.4, 1.6, size=3))  # non-uniform scale
    m[:3, 3] = rng.uniform(-0.8, 0.8, size=3)
    return m


def brute_force(world_triangles, origins, directions):
    """Closest (t, index) of each ray over (m, 3, 3) triangles, Moller-Trumbore in float64."""
    parts = [brute_force_chunk(world_triangles, origins[i:i + 200], directions[i:i + 200])
             for i in range(0, len(origins), 200)]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def brute_force_chunk(world_triangles, origins, directions):
    v0, v1, v2 = (world_triangles[:, i][None] for i in range(3))
    o, d = origins[:, None].astype(np.float64), directions[:, None].astype(np.float64)
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(d, e2)
    det = np.sum(e1 * p, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - v0
        u = np.sum(s * p, axis=-1) * inv
        q = np.cross(s, e1)
        v = np.sum(d * q, axis=-1) * inv
        t = np.sum(e2 * q, axis=-1) * inv
    ok = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0)
    t = np.where(ok, t, np.inf)
    best = np.argmin(t, axis=1)
    return t[np.arange(len(t)), best], best


def build(rng, builder="binned-sah", width=8):
    meshes = [random_soup(200, 1), random_soup(150, 2)]
    scene = canopy.RayScene(builder=builder, width=width)
    ids = [scene.add_geometry(v, f) for v, f in meshes]
    placed, world = [], []
    for k in range(6):
        geometry = ids[k % 2]
        m = random_transform(rng, mirror=k % 3 == 0)
        assert scene.add_instance(geometry, m) == k
        v, f = meshes[geometry]
        homogeneous = np.c_[v.astype(np.float64), np.ones(len(v))] @ m.T
        for prim, face in enumerate(f):
            world.append(homogeneous[face, :3])
            placed.append((k, geometry, prim, np.linalg.det(m[:3, :3])))
    return scene, np.array(world), placed


@pytest.mark.parametrize("builder, width", [("binned-sah", 8), ("sweep-sah", 4), ("lbvh", 2), ("none", 2)])
def test_closest_hits_match_brute_force_over_every_instance(builder, width):
    rng = np.random.default_rng(7)
    scene, world, placed = build(rng, builder, width)
    origins, directions = random_rays(2000, 3)
    hits = scene.intersect(origins, directions)
    t, best = brute_force(world, origins, directions)
    hit = np.isfinite(t)
    assert 300 < hit.sum() < 2000, hit.sum()
    # Where canopy and float64 brute force disagree on whether a ray hits, it grazes an edge.
    agree = np.isfinite(hits.t) == hit
    assert agree.mean() > 0.995, agree.mean()
    both = hit & np.isfinite(hits.t)
    np.testing.assert_allclose(hits.t[both], t[both], rtol=2e-4, atol=1e-5)
    expected = np.array([placed[i][:3] for i in best[both]])
    found = np.c_[hits.instance[both], hits.geometry[both], hits.prim[both]]
    assert (found == expected).all(axis=1).mean() > 0.995
    # The normal is the triangle's, in world space, as the mesh winds it (a mirror
    # reverses the world winding).
    same = (found == expected).all(axis=1)
    tri = world[best[both]][same]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n *= np.sign([placed[i][3] for i in best[both][same]])[:, None]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    np.testing.assert_allclose(hits.normal[both][same], n, atol=2e-3)
    # Barycentrics put the hit where t does.
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    uv = hits.uv[both][same].astype(np.float64)
    point = a + uv[:, :1] * (b - a) + uv[:, 1:] * (c - a)
    along = origins[both][same] + hits.t[both][same, None] * directions[both][same]
    np.testing.assert_allclose(point, along, atol=2e-3)
    # Misses are marked.
    miss = ~np.isfinite(hits.t)
    assert (hits.instance[miss] == -1).all() and (hits.prim[miss] == -1).all()
    # Occlusion says the same, up to the closest hit.
    blocked = scene.occluded(origins, directions)
    assert (blocked == np.isfinite(hits.t)).all()


def test_masks_select_instances_and_moves_take_effect():
    vertices = np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0]], dtype=np.float32)
    scene = canopy.RayScene()
    tri = scene.add_mesh(vertices, [[0, 1, 2]], mask=0b01)
    lower = np.eye(4)
    lower[2, 3] = -1
    scene.add_instance(tri, lower, mask=0b10)
    rays = dict(origins=[[0, 0, 5]], directions=[[0, 0, -1]])
    assert scene.intersect(**rays).instance.tolist() == [0]
    assert scene.intersect(**rays, mask=0b10).instance.tolist() == [1]
    assert scene.intersect(**rays, mask=0b100).instance.tolist() == [-1]
    assert scene.occluded(**rays, mask=0b100).tolist() == [False]
    far = np.eye(4)
    far[0, 3] = 10
    scene.set_transform(0, far)
    hits = scene.intersect(**rays)
    assert hits.instance.tolist() == [1] and hits.t.tolist() == [6.0]


def test_one_untransformed_mesh_answers_as_a_bvh_does():
    vertices, faces = random_soup(300, 5)
    origins, directions = random_rays(3000, 6)
    scene = canopy.RayScene()
    scene.add_mesh(vertices, faces)
    ours = scene.intersect(origins, directions)
    theirs = canopy.Bvh(vertices, faces).intersect(origins, directions)
    np.testing.assert_array_equal(ours.t, theirs.t)
    np.testing.assert_array_equal(ours.prim, theirs.prim)
    np.testing.assert_array_equal(ours.uv, theirs.uv)


def test_an_empty_scene_misses_and_bad_input_is_refused():
    scene = canopy.RayScene()
    hits = scene.intersect([[0, 0, 0]], [[0, 0, 1]])
    assert hits.t.tolist() == [np.inf] and hits.instance.tolist() == [-1]
    tri = scene.add_geometry([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    for call, words in [
        (lambda: scene.add_instance(tri, np.zeros((3, 4))), "invertible"),
        (lambda: scene.add_instance(4), "geometry 4 does not exist"),
        (lambda: scene.add_instance(tri, mask=-1), "mask must be"),
        (lambda: scene.set_transform(9, np.eye(4)), "instance 9 does not exist"),
        (lambda: scene.add_geometry([[0, 0, 0]], [[0, 0, 1]]), "faces[0]"),
        (lambda: canopy.RayScene(builder="octree"), "unknown"),
    ]:
        with pytest.raises(ValueError) as e:
            call()
        assert words in str(e.value), str(e.value)
    assert scene.instance_count == 0 and scene.geometry_count == 1


@pytest.mark.parametrize("builder, width", [("binned-sah", 8), ("lbvh", 4), ("sweep-sah", 2)])
def test_the_fast_triangle_test_answers_as_brute_force_in_that_mode_and_pickles(builder, width):
    # One untransformed instance and rays aimed exactly at edge midpoints, where the two
    # modes can differ: each mode's tree answers as brute force in the same mode.
    vertices, faces = random_soup(300, 3)
    origins, directions = edge_midpoint_rays(vertices, faces, 5)
    hits = {}
    for mode in ("watertight", "fast"):
        scene = canopy.RayScene(builder=builder, width=width, triangles=mode)
        reference = canopy.RayScene(builder="none", triangles=mode)
        for s in (scene, reference):
            s.add_mesh(vertices, faces)
        assert scene.triangles == mode
        got, expected = scene.intersect(origins, directions), reference.intersect(origins, directions)
        np.testing.assert_array_equal(got.prim, expected.prim)
        np.testing.assert_array_equal(got.t, expected.t)
        np.testing.assert_array_equal(scene.occluded(origins, directions), expected.prim >= 0)
        copy = pickle.loads(pickle.dumps(scene))
        assert copy.triangles == mode
        np.testing.assert_array_equal(copy.intersect(origins, directions).prim, got.prim)
        hits[mode] = got.prim >= 0
    # The fast test stops every ray the watertight one stops.
    assert np.all(hits["fast"][hits["watertight"]])
    with pytest.raises(ValueError, match="'watertight' or 'fast'"):
        canopy.RayScene(triangles="robust")


def test_the_triangle_modes_differ_where_a_ray_grazes_an_edge():
    # Each ray looks only at a short segment around an edge midpoint of the triangle it
    # aims at: the fast test stops a few more of them, never fewer (so `triangles=` is
    # the mode the queries use).
    vertices, faces = random_soup(20000, 3)
    origins, directions = edge_midpoint_rays(vertices, faces, 5)
    stopped = {}
    for mode in ("watertight", "fast"):
        scene = canopy.RayScene(triangles=mode)
        scene.add_mesh(vertices, faces)
        stopped[mode] = scene.occluded(origins, directions, 0.999, 1.001)
    assert not np.any(stopped["watertight"] & ~stopped["fast"])
    assert np.sum(stopped["fast"] & ~stopped["watertight"]) > 0
