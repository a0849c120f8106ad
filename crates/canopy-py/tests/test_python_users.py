"""What Python users of trimesh, embreex and Open3D expect of canopy's queries: crossings
counted once at shared edges and vertices, structures that pickle (multiprocessing with
spawn and fork), meshes that move (refit), and Open3D's (n, 6) rays."""

import concurrent.futures
import multiprocessing
import pickle

import numpy as np
import pytest
import trimesh

import canopy_rt as canopy
from conftest import random_rays, random_soup
from test_ray_scene import build


def scene_of(mesh, **options):
    scene = canopy.RayScene(**options)
    scene.add_mesh(mesh.vertices, mesh.faces)
    return scene


@pytest.mark.parametrize("builder, width", [("binned-sah", 8), ("sbvh", 4), ("lbvh", 2), ("none", 2)])
def test_a_ray_through_a_shared_edge_or_vertex_crosses_the_surface_once(builder, width):
    # The box: a ray through a face's diagonal hit 4 triangles, through a corner 7.
    box = trimesh.creation.box()
    scene = scene_of(box, builder=builder, width=width)
    v = box.vertices
    diagonals = [e for e in box.edges_unique if np.sum(v[e[0]] != v[e[1]]) == 2]
    assert len(diagonals) == 6
    origins, directions = [], []
    for a, b in diagonals:
        middle = (v[a] + v[b]) / 2
        normal = np.where(v[a] == v[b], np.sign(v[a]), 0)  # the face's axis
        origins.append(middle + 2 * normal)
        directions.append(-normal)
    origins.append([1.5, 1.5, 1.5])  # through two opposite corners
    directions.append([-1, -1, -1])
    origins, directions = np.array(origins, np.float32), np.array(directions, np.float32)
    assert scene.count_intersections(origins, directions).tolist() == [2] * 7
    per_triangle = scene.count_intersections(origins, directions, per_triangle=True)
    assert per_triangle[:6].tolist() == [4] * 6 and per_triangle[6] > 2
    lists = scene.list_intersections(origins, directions)
    np.testing.assert_array_equal(np.diff(lists.ray_splits), [2] * 7)
    np.testing.assert_allclose(lists.t[:2], [2.0, 3.0])  # in at the face, out at the opposite one
    every = scene.list_intersections(origins, directions, per_triangle=True)
    np.testing.assert_array_equal(np.diff(every.ray_splits), per_triangle)


def test_lines_through_a_spheres_vertices_cross_it_an_even_number_of_times():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    scene = scene_of(sphere)
    rng = np.random.default_rng(3)
    through = np.repeat(sphere.vertices, 4, axis=0)
    directions = rng.normal(size=through.shape)
    origins = (through - 3 * directions / np.linalg.norm(directions, axis=1, keepdims=True))
    counts = scene.count_intersections(origins.astype(np.float32), directions.astype(np.float32))
    assert np.all(counts % 2 == 0), np.unique(counts, return_counts=True)
    assert (counts == 2).mean() > 0.9
    per_triangle = scene.count_intersections(origins.astype(np.float32), directions.astype(np.float32),
                                             per_triangle=True)
    assert np.sum(per_triangle > counts) > len(counts) // 10  # many pass exactly through one


def test_rays_as_one_n_by_6_array_as_open3d_passes_them():
    vertices, faces = random_soup(100, 5)
    origins, directions = random_rays(300, 6)
    rays = np.hstack([origins, directions])
    scene = canopy.RayScene()
    scene.add_mesh(vertices, faces)
    bvh = canopy.Bvh(vertices, faces)
    for a, b in zip(scene.intersect(rays), scene.intersect(origins, directions)):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(scene.occluded(rays, tfar=0.5), scene.occluded(origins, directions, tfar=0.5))
    np.testing.assert_array_equal(scene.count_intersections(rays), scene.count_intersections(origins, directions))
    np.testing.assert_array_equal(bvh.intersect(rays).t, bvh.intersect(origins, directions).t)
    np.testing.assert_array_equal(bvh.occluded(rays), bvh.occluded(origins, directions))
    for a, b in zip(scene.list_intersections(rays), scene.list_intersections(origins, directions)):
        np.testing.assert_array_equal(a, b)
    # Strided rows (every other ray of a larger array) give the same answers.
    both = np.repeat(rays, 2, axis=0)[::2]
    np.testing.assert_array_equal(scene.count_intersections(both), scene.count_intersections(rays))
    with pytest.raises(ValueError, match=r"shape \(n, 6\)"):
        scene.intersect(origins)
    bad = rays.astype(np.float32)
    bad[7, 4] = np.nan
    with pytest.raises(ValueError, match=r"rays\[7\].*not finite"):
        scene.count_intersections(bad)


def same_answers(a, b, origins, directions, points):
    for x, y in zip(a.intersect(origins, directions), b.intersect(origins, directions)):
        np.testing.assert_array_equal(x, y)
    for x, y in zip(a.compute_closest_points(points), b.compute_closest_points(points)):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(a.count_intersections(origins, directions),
                                  b.count_intersections(origins, directions))


def test_scenes_and_bvhs_pickle_to_the_same_answers():
    rng = np.random.default_rng(7)
    scene, _, _ = build(rng, builder="sweep-sah", width=4)
    scene.set_transform(2, np.diag([1.0, -2.0, 0.5, 1.0]))
    origins, directions = random_rays(500, 8)
    points = rng.uniform(-1, 2, size=(200, 3)).astype(np.float32)
    copy = pickle.loads(pickle.dumps(scene))
    assert (copy.geometry_count, copy.instance_count) == (scene.geometry_count, scene.instance_count)
    same_answers(scene, copy, origins, directions, points)
    # Masks travel too.
    masked = canopy.RayScene()
    g = masked.add_geometry(*random_soup(50, 9))
    masked.add_instance(g, None, mask=2)
    again = pickle.loads(pickle.dumps(masked))
    assert np.isinf(again.intersect(origins, directions, mask=1).t).all()
    np.testing.assert_array_equal(again.intersect(origins, directions, mask=2).t,
                                  masked.intersect(origins, directions, mask=2).t)

    vertices, faces = random_soup(300, 10)
    for bvh in [canopy.Bvh(vertices, faces, builder="ploc", width=2, max_leaf_size=2),
                canopy.Bvh.from_boxes(np.sort(np.random.default_rng(1).random((80, 2, 3)), axis=1))]:
        copy = pickle.loads(pickle.dumps(bvh))
        assert (copy.builder, copy.width, copy.primitive_count) == (bvh.builder, bvh.width, bvh.primitive_count)
        assert copy.stats()["nodes"] == bvh.stats()["nodes"]
        for x, y in zip(copy.intersect(origins, directions), bvh.intersect(origins, directions)):
            np.testing.assert_array_equal(x, y)
    # Results pickle as they are.
    hits = scene.intersect(origins, directions)
    for x, y in zip(pickle.loads(pickle.dumps(hits)), hits):
        np.testing.assert_array_equal(x, y)


def count_in_child(scene, origins, directions):
    return scene.count_intersections(origins, directions)


@pytest.mark.parametrize("method", ["spawn", "fork"])
def test_scenes_go_to_worker_processes(method):
    if method not in multiprocessing.get_all_start_methods():
        pytest.skip(f"no {method} on this platform")
    scene, _, _ = build(np.random.default_rng(11))
    origins, directions = random_rays(400, 12)
    expected = scene.count_intersections(origins, directions)
    context = multiprocessing.get_context(method)
    # Timeouts: a child stuck on its parent's thread pool fails the test, not the run.
    with context.Pool(2) as pool:
        work = [(scene, origins[i::2], directions[i::2]) for i in range(2)]
        parts = pool.starmap_async(count_in_child, work).get(timeout=120)
    np.testing.assert_array_equal(parts[0], expected[0::2])
    np.testing.assert_array_equal(parts[1], expected[1::2])
    bvh = canopy.Bvh(*random_soup(100, 13))
    image = canopy.render("paper-1", spp=1, size=(16, 12))
    # The parent's thread pools have been used: a forked child makes its own.
    executor = concurrent.futures.ProcessPoolExecutor(1, mp_context=context)
    try:
        hits = executor.submit(canopy.Bvh.intersect, bvh, origins, directions).result(timeout=120)
        rendered = executor.submit(canopy.render, "paper-1", spp=1, size=(16, 12)).result(timeout=120)
    finally:
        for process in list(executor._processes.values()):
            process.kill()
        executor.shutdown(wait=False, cancel_futures=True)
    np.testing.assert_array_equal(hits.t, bvh.intersect(origins, directions).t)
    np.testing.assert_array_equal(rendered, image)


def test_moved_vertices_are_refitted_and_answer_as_a_new_build():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    scene = canopy.RayScene()
    g = scene.add_mesh(sphere.vertices, sphere.faces)
    scene.add_instance(g, np.diag([0.5, 0.5, 0.5, 1.0]))  # a second copy, inside the first
    origins, directions = random_rays(400, 14)
    points = np.random.default_rng(15).uniform(-2, 2, size=(300, 3)).astype(np.float32)
    before = scene.intersect(origins, directions)
    moved = sphere.vertices * [1.5, 1.0, 0.7] + [0.2, 0.0, 0.0]
    scene.set_vertices(g, moved)
    fresh = canopy.RayScene()
    fg = fresh.add_mesh(moved, sphere.faces)
    fresh.add_instance(fg, np.diag([0.5, 0.5, 0.5, 1.0]))
    same_answers(scene, fresh, origins, directions, points)
    np.testing.assert_array_equal(scene.compute_occupancy(points), fresh.compute_occupancy(points))
    assert not np.array_equal(before.t, scene.intersect(origins, directions).t)
    with pytest.raises(ValueError, match=r"has 162 vertices, not 3"):
        scene.set_vertices(g, moved[:3])
    with pytest.raises(ValueError, match="geometry 5 does not exist"):
        scene.set_vertices(5, moved)
    with pytest.raises(ValueError, match=r"vertices\[0\].*not finite"):
        scene.set_vertices(g, np.full_like(moved, np.nan))
    # Long slivers, which sbvh cuts: their tree cannot be refitted.
    rng = np.random.default_rng(21)
    a, b = rng.random((400, 3)), rng.random((400, 3))
    slivers = np.stack([a, b, a + 0.01 * (b - a) + 0.02], axis=1).reshape(-1, 3).astype(np.float32)
    faces = np.arange(1200).reshape(400, 3)
    split = canopy.RayScene(builder="sbvh")
    split.add_mesh(slivers, faces)
    with pytest.raises(ValueError, match="sbvh with spatial splits"):
        split.set_vertices(0, slivers + 1)
    # A refused update leaves the scene as it was.
    reference = canopy.Bvh(slivers, faces, builder="none").intersect(origins, directions)
    np.testing.assert_array_equal(split.intersect(origins, directions).t, reference.t)


def test_occupancy_of_closed_and_open_meshes_follows_the_winding_number():
    # Closed: the exact signed count of a ray's crossings; open: the winding number.
    sphere = trimesh.creation.icosphere(subdivisions=3)
    points = np.random.default_rng(16).uniform(-1.3, 1.3, size=(4000, 3)).astype(np.float32)
    closed = scene_of(sphere)
    inside = closed.compute_occupancy(points)
    radius = np.linalg.norm(points, axis=1)
    clear = np.abs(radius - 0.99) > 0.02  # the icosphere's faces lie within 1% of the unit sphere
    np.testing.assert_array_equal(inside[clear], (radius < 0.99)[clear])
    np.testing.assert_array_equal(inside[clear], (closed.winding_number(points) > 0.5)[clear])
    holed = trimesh.Trimesh(sphere.vertices, sphere.faces[5:])
    open_scene = scene_of(holed)
    np.testing.assert_array_equal(open_scene.compute_occupancy(points)[clear], (radius < 0.99)[clear])



@pytest.mark.parametrize("builder, width", [("binned-sah", 8), ("lbvh", 4), ("ploc", 2), ("none", 2)])
def test_a_bvh_takes_moved_vertices_and_answers_as_a_new_build(builder, width):
    sphere = trimesh.creation.icosphere(subdivisions=2)
    bvh = canopy.Bvh(sphere.vertices, sphere.faces, builder=builder, width=width)
    origins, directions = random_rays(600, 22)
    before = bvh.intersect(origins, directions)
    moved = (sphere.vertices * [1.5, 1.0, 0.7] + [0.2, 0.0, 0.0]).astype(np.float32)
    bvh.set_vertices(moved)
    bvh.validate()
    fresh = canopy.Bvh(moved, sphere.faces, builder=builder, width=width)
    for x, y in zip(bvh.intersect(origins, directions), fresh.intersect(origins, directions)):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(bvh.occluded(origins, directions), fresh.occluded(origins, directions))
    assert not np.array_equal(before.t, bvh.intersect(origins, directions).t)
    # A copy holds the moved mesh, and moves again as the original does.
    copy = pickle.loads(pickle.dumps(bvh))
    np.testing.assert_array_equal(copy.intersect(origins, directions).t, fresh.intersect(origins, directions).t)
    copy.set_vertices(sphere.vertices)
    np.testing.assert_array_equal(copy.intersect(origins, directions).t, before.t)
    with pytest.raises(ValueError, match=r"has 162 vertices, not 3"):
        bvh.set_vertices(moved[:3])
    with pytest.raises(ValueError, match=r"vertices\[0\].*not finite"):
        bvh.set_vertices(np.full_like(moved, np.nan))


def test_a_bvh_that_cannot_be_refitted_refuses_moved_vertices_and_stays_as_it_was():
    rng = np.random.default_rng(23)
    a, b = rng.random((400, 3)), rng.random((400, 3))
    slivers = np.stack([a, b, a + 0.01 * (b - a) + 0.02], axis=1).reshape(-1, 3).astype(np.float32)
    faces = np.arange(1200).reshape(400, 3)
    split = canopy.Bvh(slivers, faces, builder="sbvh")
    assert split.stats()["references"] > 400, "sbvh split some slivers"
    with pytest.raises(ValueError, match="sbvh with spatial splits"):
        split.set_vertices(slivers + 1)
    origins, directions = random_rays(400, 24)
    reference = canopy.Bvh(slivers, faces, builder="none").intersect(origins, directions)
    np.testing.assert_array_equal(split.intersect(origins, directions).t, reference.t)
    boxes = canopy.Bvh.from_boxes(np.sort(rng.random((20, 2, 3)), axis=1))
    with pytest.raises(ValueError, match="over boxes"):
        boxes.set_vertices(slivers)


def test_queries_and_refits_from_several_threads_wait_for_each_other():
    # A refit takes the structure alone; queries share it. Ordered by events, not time:
    # every answer is that of the mesh before or after a move, never a mixture.
    sphere = trimesh.creation.icosphere(subdivisions=4)
    bvh = canopy.Bvh(sphere.vertices, sphere.faces)
    origins, directions = random_rays(20000, 25)
    shapes = [sphere.vertices.astype(np.float32), (sphere.vertices * 1.3).astype(np.float32)]
    expected = [canopy.Bvh(v, sphere.faces).intersect(origins, directions).t for v in shapes]
    seen = []

    def query():
        for _ in range(6):
            t = bvh.intersect(origins, directions).t
            seen.append(any(np.array_equal(t, e) for e in expected))

    def move():
        for k in range(6):
            bvh.set_vertices(shapes[(k + 1) % 2])

    with concurrent.futures.ThreadPoolExecutor(3) as pool:
        for f in [pool.submit(query), pool.submit(move), pool.submit(query)]:
            f.result(timeout=300)
    assert len(seen) == 12 and all(seen)
