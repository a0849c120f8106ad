"""The BVH API: the same answers as canopy's Rust brute force and an independent numpy
reference, for every builder and width; bad input raises; the GIL is released."""

import os
import pickle
import sys
import threading
import time

import numpy as np
import pytest

import canopy_rt as canopy
from conftest import MESHES, edge_midpoint_rays, random_rays, random_soup


def moller_trumbore(vertices, faces, origins, directions):
    """Closest hit distance and triangle per ray, in float64 (a plain loop over triangles)."""
    v = vertices.astype(np.float64)[faces]
    o, d = origins.astype(np.float64), directions.astype(np.float64)
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    best_t = np.full(len(o), np.inf)
    best_prim = np.full(len(o), -1)
    for i in range(len(faces)):
        p = np.cross(d, e2[i])
        det = p @ e1[i]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = o - v[i, 0]
            u = np.sum(s * p, axis=1) * inv
            q = np.cross(s, e1[i])
            w = np.sum(d * q, axis=1) * inv
            t = (q @ e2[i]) * inv
        ok = (np.abs(det) > 1e-12) & (u >= 0) & (w >= 0) & (u + w <= 1) & (t >= 0) & (t < best_t)
        best_t[ok], best_prim[ok] = t[ok], i
    return best_t, best_prim


def test_version_builders_and_repr():
    assert canopy.__version__.count(".") == 2
    names = canopy.builders()
    assert {"binned-sah", "sweep-sah", "lbvh", "ploc", "agglomerative"} <= set(names)
    v, f = random_soup(10, 0)
    assert "10 primitives" in repr(canopy.Bvh(v, f))


@pytest.mark.parametrize("builder", canopy.builders())
@pytest.mark.parametrize("width", [2, 4, 8])
def test_every_builder_and_width_gives_the_brute_force_answer(builder, width):
    vertices, faces = random_soup(300, 1)
    origins, directions = random_rays(2000, 2)
    reference = canopy.Bvh(vertices, faces, builder="none").intersect(origins, directions)
    bvh = canopy.Bvh(vertices, faces, builder=builder, width=width)
    bvh.validate()
    hits = bvh.intersect(origins, directions)
    # Bit for bit: the same primitive, distance and barycentrics.
    np.testing.assert_array_equal(hits.prim, reference.prim)
    np.testing.assert_array_equal(hits.t, reference.t)
    np.testing.assert_array_equal(hits.uv, reference.uv)
    np.testing.assert_array_equal(bvh.occluded(origins, directions), reference.prim >= 0)
    stats = bvh.stats()
    assert stats["builder"] == builder and stats["width"] == width
    assert stats["primitives"] == 300 and stats["sah_cost"] > 0 and stats["build_ms"] >= 0


@pytest.mark.parametrize("builder", ["none", "binned-sah"])
@pytest.mark.parametrize("width", [2, 4, 8])
def test_the_fast_triangle_test_agrees_with_itself_and_hits_wherever_the_watertight_one_does(builder, width):
    # Rays aimed exactly at edge midpoints, where the two modes can differ.
    vertices, faces = random_soup(300, 3)
    origins, directions = edge_midpoint_rays(vertices, faces, 4)
    reference = canopy.Bvh(vertices, faces, builder="none", triangles="fast")
    fast = canopy.Bvh(vertices, faces, builder=builder, width=width, triangles="fast")
    watertight = canopy.Bvh(vertices, faces, builder=builder, width=width)
    assert fast.stats()["triangles"] == "fast" and watertight.stats()["triangles"] == "watertight"
    hits, expected = fast.intersect(origins, directions), reference.intersect(origins, directions)
    np.testing.assert_array_equal(hits.prim, expected.prim)
    np.testing.assert_array_equal(hits.t, expected.t)
    np.testing.assert_array_equal(fast.occluded(origins, directions), expected.prim >= 0)
    # Every ray the watertight test stops, the fast one stops too.
    assert np.all(fast.occluded(origins, directions)[watertight.occluded(origins, directions)])
    # The mode survives a pickle.
    assert pickle.loads(pickle.dumps(fast)).stats()["triangles"] == "fast"


@pytest.mark.parametrize("width", [2, 4, 8])
def test_coherent_rays_in_packets_give_the_same_answers(width):
    """A camera's rays row by row and shadow rays from one patch towards one point, as
    packets: the same hits, bit for bit, and the same occlusion as ray by ray."""
    vertices, faces = random_soup(1500, 5)
    bvh = canopy.Bvh(vertices, faces, width=width)
    eye = np.array([0.2, 0.1, -3.0], np.float32)
    ys, xs = np.mgrid[-0.2:1.2:40j, -0.2:1.2:50j]
    targets = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1).astype(np.float32)
    origins = np.broadcast_to(eye, targets.shape).copy()
    camera = (origins, targets - origins)
    hits = bvh.intersect(*camera)
    assert 0.2 < np.mean(hits.prim >= 0) < 0.95
    packets = bvh.intersect(*camera, coherent=True)
    np.testing.assert_array_equal(packets.prim, hits.prim)
    np.testing.assert_array_equal(packets.t, hits.t)
    np.testing.assert_array_equal(packets.uv, hits.uv)
    light = np.array([0.5, 2.0, 1.0], np.float32)
    found = hits.prim >= 0
    points = origins[found] + hits.t[found, None] * camera[1][found] * np.float32(0.999)
    shadows = (points, light - points)
    blocked = bvh.occluded(*shadows, tfar=0.999)
    assert 0.05 < np.mean(blocked) < 0.95
    np.testing.assert_array_equal(bvh.occluded(*shadows, tfar=0.999, coherent=True), blocked)


@pytest.mark.parametrize("builder", ["none", "binned-sah", "lbvh"])
@pytest.mark.parametrize("width", [2, 4, 8])
def test_zero_and_denormal_directions_miss_in_every_structure(builder, width):
    """A direction with no component of normal size (zero, or denormal throughout) cannot
    hit anything: every structure answers a miss, never a hit at t = inf."""
    vertices = np.array([[-1, -1, -2], [1, -1, -2], [0, 1, -2]], dtype=np.float32)
    faces = np.array([[0, 1, 2]])
    bvh = canopy.Bvh(vertices, faces, builder=builder, width=width)
    directions = np.array(
        [[0, 0, -1e-45], [0, 0, 0], [1e-40, 0, -1e-42], [0, 0, -1e-20], [0, 0, -1]], dtype=np.float32
    )
    origins = np.zeros_like(directions)
    hits = bvh.intersect(origins, directions)
    assert list(hits.prim) == [-1, -1, -1, 0, 0]
    assert np.isfinite(hits.t[3:]).all()
    assert list(bvh.occluded(origins, directions)) == [False, False, False, True, True]


def test_hits_agree_with_an_independent_float64_reference():
    vertices, faces = canopy.load_mesh(MESHES / "teapot.ply")
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    rng = np.random.default_rng(3)
    targets = lo + rng.random((3000, 3)) * (hi - lo)
    origins = np.tile((lo + hi) / 2 + np.array([0, 0.5, 2.0]) * (hi - lo), (3000, 1))
    directions = targets - origins
    hits = canopy.Bvh(vertices, faces).intersect(origins, directions)
    t, prim = moller_trumbore(vertices, faces, origins, directions)
    agree = hits.prim == prim
    assert agree.mean() > 0.995, agree.mean()  # edge rays may resolve either way
    assert np.all((hits.prim >= 0) == (prim >= 0)) or np.mean((hits.prim >= 0) != (prim >= 0)) < 0.002
    both = agree & (prim >= 0)
    np.testing.assert_allclose(hits.t[both], t[both], rtol=1e-5)
    # Barycentrics locate the hit point.
    v = vertices[faces[hits.prim[both]]].astype(np.float64)
    uv = hits.uv[both].astype(np.float64)
    points = v[:, 0] * (1 - uv[:, :1] - uv[:, 1:]) + v[:, 1] * uv[:, :1] + v[:, 2] * uv[:, 1:]
    expected = origins[both] + directions[both] * t[both, None]
    np.testing.assert_allclose(points, expected, atol=1e-4 * float(np.max(hi - lo)))


def test_epo_prices_overlap_that_sah_ignores():
    vertices, faces = canopy.load_mesh(MESHES / "bunny.ply")
    good = canopy.Bvh(vertices, faces, builder="sweep-sah", width=2)
    sorted_x = canopy.Bvh(vertices, faces, builder="sort-x", width=2)
    assert 0 < good.epo() < sorted_x.epo()
    # Wide layouts with triangles packed in their leaves (padded packs) have an EPO too,
    # below the badly sorted tree's (not below the binary tree's: leaves of up to two packs
    # overlap more than the binary tree's leaves of four).
    wide = canopy.Bvh(vertices, faces, builder="sweep-sah", width=8)
    assert 0 < wide.epo() < sorted_x.epo()
    assert canopy.Bvh(vertices, faces, builder="none").epo() == 0.0
    boxes = np.array([[[0, 0, 0], [1, 1, 1]], [[0.5, 0, 0], [1.5, 1, 1]]], dtype=np.float32)
    assert canopy.Bvh.from_boxes(boxes, width=2, max_leaf_size=1).epo() > 0


def test_optimized_trees_give_the_same_hits_with_a_lower_sah():
    vertices, faces = random_soup(2000, 11)
    origins, directions = random_rays(3000, 12)
    plain = canopy.Bvh(vertices, faces, builder="lbvh", width=2)
    better = canopy.Bvh(vertices, faces, builder="lbvh", width=2, optimize=0.2)
    better.validate()
    assert better.stats()["sah_cost"] < plain.stats()["sah_cost"]
    a, b = plain.intersect(origins, directions), better.intersect(origins, directions)
    np.testing.assert_array_equal(a.prim, b.prim)
    np.testing.assert_array_equal(a.t, b.t)
    with pytest.raises(ValueError, match="optimize must be a time"):
        canopy.Bvh(vertices, faces, optimize=-1)


def test_spatial_splits_duplicate_long_triangles_and_keep_the_answers():
    # Long slivers in every direction: sbvh cuts them, and the hits stay exact.
    rng = np.random.default_rng(21)
    a, b = rng.random((400, 3)), rng.random((400, 3))
    c = a + 0.01 * (b - a) + 0.02
    vertices = np.stack([a, b, c], axis=1).reshape(-1, 3).astype(np.float32)
    faces = np.arange(1200).reshape(400, 3)
    origins, directions = random_rays(3000, 22)
    reference = canopy.Bvh(vertices, faces, builder="none").intersect(origins, directions)
    for width in [2, 8]:
        sbvh = canopy.Bvh(vertices, faces, builder="sbvh", width=width, max_duplication=1.0)
        sbvh.validate()
        stats = sbvh.stats()
        assert 400 < stats["references"] <= 800, stats
        hits = sbvh.intersect(origins, directions)
        np.testing.assert_array_equal(hits.prim, reference.prim)
        np.testing.assert_array_equal(hits.t, reference.t)
        np.testing.assert_array_equal(sbvh.occluded(origins, directions), reference.prim >= 0)
    none = canopy.Bvh(vertices, faces, builder="sbvh", max_duplication=0.0).stats()
    assert none["references"] == 400
    with pytest.raises(ValueError, match="max_duplication"):
        canopy.Bvh(vertices, faces, builder="sbvh", max_duplication=-0.5)


def test_tnear_and_tfar_limit_each_ray():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
    bvh = canopy.Bvh(vertices, [[0, 1, 2]])
    o = np.array([[0.2, 0.2, 1.0]] * 4)
    d = np.array([[0, 0, -1.0]] * 4)
    hits = bvh.intersect(o, d, tnear=[0, 0, 1.5, 0.5], tfar=[np.inf, 0.5, np.inf, 1.0])
    np.testing.assert_array_equal(hits.prim, [0, -1, -1, 0])
    np.testing.assert_array_equal(hits.t, [1, np.inf, np.inf, 1])
    np.testing.assert_allclose(hits.uv, [[0.2, 0.2], [0, 0], [0, 0], [0.2, 0.2]], rtol=1e-6)
    np.testing.assert_array_equal(bvh.occluded(o, d, tfar=0.99), [False] * 4)
    np.testing.assert_array_equal(bvh.occluded(o, d, tfar=1.0), [True] * 4)


def test_boxes_are_hit_where_rays_enter_them():
    boxes = np.array([[[0, 0, 0], [1, 1, 1]], [[2, 0, 0], [3, 1, 1]]], dtype=np.float32)
    bvh = canopy.Bvh.from_boxes(boxes, builder="sweep-sah", width=4)
    hits = bvh.intersect([[-1, 0.5, 0.5], [2.5, 0.5, -2], [5, 5, 5]], [[1, 0, 0], [0, 0, 1], [1, 0, 0]])
    np.testing.assert_array_equal(hits.prim, [0, 1, -1])
    np.testing.assert_array_equal(hits.t, [1, 2, np.inf])
    bvh.validate()


def test_inputs_of_other_dtypes_and_layouts_are_converted():
    vertices, faces = random_soup(50, 4)
    origins, directions = random_rays(500, 5)
    expected = canopy.Bvh(vertices, faces).intersect(origins, directions)
    bvh = canopy.Bvh(vertices.astype(np.float64).tolist(), faces.astype(np.int32), builder="binned-sah")
    got = bvh.intersect(np.asfortranarray(origins.astype(np.float64)), directions[::1].copy(order="F"))
    np.testing.assert_array_equal(got.prim, expected.prim)
    # Read-only, unaligned buffers (a mesh read straight from a file's bytes) too.
    raw = bytes(1) + vertices.tobytes()
    unaligned = np.frombuffer(raw, np.float32, vertices.size, 1).reshape(-1, 3)
    assert not unaligned.flags.aligned
    np.testing.assert_array_equal(
        canopy.Bvh(unaligned, faces).intersect(origins, directions).prim, expected.prim
    )
    # Strided views work too.
    wide = np.zeros((500, 6), dtype=np.float32)
    wide[:, ::2] = origins
    np.testing.assert_array_equal(bvh.intersect(wide[:, ::2], directions).prim, expected.prim)


def test_empty_batches_give_empty_answers():
    vertices, faces = random_soup(5, 6)
    bvh = canopy.Bvh(vertices, faces)
    hits = bvh.intersect(np.zeros((0, 3)), np.zeros((0, 3)))
    assert hits.t.shape == (0,) and hits.prim.shape == (0,) and hits.uv.shape == (0, 2)
    assert bvh.occluded(np.zeros((0, 3)), np.zeros((0, 3))).shape == (0,)


GOOD_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)


@pytest.mark.parametrize(
    "make, error, words",
    [
        (lambda: canopy.Bvh(GOOD_V, [[0, 1, 3]]), ValueError, "faces[0] refers to vertex 3"),
        (lambda: canopy.Bvh(GOOD_V, [[0, 1, -1]]), ValueError, "faces[0] refers to vertex -1"),
        (lambda: canopy.Bvh(GOOD_V, [[0, 1, 2**62]]), ValueError, "faces[0] refers to vertex"),
        (lambda: canopy.Bvh(GOOD_V, np.array([[0, 1, 2**63 + 5]], dtype=np.uint64)), ValueError, "beyond any vertex count"),
        (lambda: canopy.Bvh(GOOD_V, [[0, 1, 1.5]]), TypeError, "integer indices"),
        (lambda: canopy.Bvh(GOOD_V, [[0, 1]]), ValueError, "faces must have shape (n, 3)"),
        (lambda: canopy.Bvh(GOOD_V[:, :2], [[0, 1, 2]]), ValueError, "vertices must have shape (n, 3)"),
        (lambda: canopy.Bvh(GOOD_V.ravel(), [[0, 1, 2]]), ValueError, "vertices must have shape (V, 3)"),
        (lambda: canopy.Bvh([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]), ValueError, "vertices[0]"),
        (lambda: canopy.Bvh([[0, 0, np.inf], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]), ValueError, "not finite"),
        (lambda: canopy.Bvh(np.zeros((0, 3)), np.zeros((0, 3), dtype=int)), ValueError, "at least one primitive"),
        (lambda: canopy.Bvh([["a", "b", "c"]], [[0, 0, 0]]), TypeError, "vertices must be numeric"),
        (lambda: canopy.Bvh([[0, 0], [1, 0, 0]], [[0, 1, 2]]), TypeError, "vertices"),
        (lambda: canopy.Bvh(GOOD_V, [[0, 1, 2]], builder="octree"), ValueError, "unknown"),
        (lambda: canopy.Bvh(GOOD_V, [[0, 1, 2]], builder=3), TypeError, "builder must be a name"),
        (lambda: canopy.Bvh(GOOD_V, [[0, 1, 2]], width=3), ValueError, "2, 4 or 8"),
        (lambda: canopy.Bvh(GOOD_V, [[0, 1, 2]], triangles="robust"), ValueError, "'watertight' or 'fast'"),
        (lambda: canopy.Bvh(GOOD_V, [[0, 1, 2]], max_leaf_size=0), ValueError, "max_leaf_size"),
        (lambda: canopy.Bvh(GOOD_V, [[0, 1, 2]], sah_traversal=-1.0), ValueError, "SAH cost"),
        (lambda: canopy.Bvh(GOOD_V, [[0, 1, 2]], threads=0), ValueError, "threads must be in 1..=1024"),
        (lambda: canopy.Bvh.from_boxes([[[1, 0, 0], [0, 1, 1]]]), ValueError, "min <= max"),
        (lambda: canopy.Bvh.from_boxes([[0, 0, 0]]), ValueError, "(N, 2, 3)"),
    ],
)
def test_bad_input_raises_a_clear_exception(make, error, words):
    with pytest.raises(error) as e:
        make()
    assert words in str(e.value), str(e.value)


@pytest.mark.parametrize(
    "origins, directions, kwargs, words",
    [
        ([[0, 0, 1]], [[0, 0, -1], [0, 0, -1]], {}, "same number of rows"),
        ([[0, 0, np.nan]], [[0, 0, -1]], {}, "origins[0]"),
        ([[0, 0, 1]], [[0, np.inf, -1]], {}, "directions[0]"),
        ([[0, 0, 1]], [[0, 0, -1]], {"tnear": np.nan}, "tnear = NaN must be >= 0"),
        ([[0, 0, 1]], [[0, 0, -1]], {"tfar": -1}, "tfar = -1 must be >= 0"),
        ([[0, 0, 1]], [[0, 0, -1]], {"tfar": [np.nan]}, "tfar[0] = NaN must be >= 0"),
        ([[0, 0, 1]], [[0, 0, -1]], {"tfar": [1, 2]}, "tfar must be a number or have shape (1,)"),
        ([0, 0, 1], [[0, 0, -1]], {}, "origins must have shape (n, 3)"),
    ],
)
def test_bad_rays_raise_value_errors(origins, directions, kwargs, words):
    bvh = canopy.Bvh(GOOD_V, [[0, 1, 2]])
    for query in (bvh.intersect, bvh.occluded):
        with pytest.raises(ValueError) as e:
            query(origins, directions, **kwargs)
        assert words in str(e.value), str(e.value)


def test_scattered_batches_over_a_large_tree_answer_each_ray_in_place():
    """A tree larger than the cache traces scattered rays in the order of their origins:
    the answers still land on their own rays (reversing the batch reverses them), and equal
    those of small batches, which are traced in the caller's order."""
    vertices, faces = random_soup(60_000, seed=3)
    bvh = canopy.Bvh(vertices, faces)
    assert bvh.stats()["memory_bytes"] > 2 << 20
    rng = np.random.default_rng(11)
    n = 20_000
    origins = rng.random((n, 3)).astype(np.float32)
    directions = rng.normal(size=(n, 3)).astype(np.float32)
    t, prim, uv = bvh.intersect(origins, directions)
    blocked = bvh.occluded(origins, directions, tfar=0.05)
    assert 0.3 < (prim >= 0).mean() < 1.0
    rt, rprim, ruv = bvh.intersect(origins[::-1].copy(), directions[::-1].copy())
    assert np.array_equal(rprim[::-1], prim) and np.array_equal(rt[::-1], t)
    assert np.array_equal(ruv[::-1], uv)
    # Batches of 1000 (below the size worth reordering) give the same answers.
    for lo in range(0, n, 1000):
        st, sprim, _ = bvh.intersect(origins[lo : lo + 1000], directions[lo : lo + 1000])
        assert np.array_equal(sprim, prim[lo : lo + 1000]) and np.array_equal(st, t[lo : lo + 1000])
        sblocked = bvh.occluded(origins[lo : lo + 1000], directions[lo : lo + 1000], tfar=0.05)
        assert np.array_equal(sblocked, blocked[lo : lo + 1000])


def big_scene():
    vertices, faces = canopy.load_mesh(MESHES / "bunny.ply")
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    rng = np.random.default_rng(7)
    n = 400_000
    origins = (lo + rng.random((n, 3)) * (hi - lo)).astype(np.float32)
    directions = rng.normal(size=(n, 3)).astype(np.float32)
    return canopy.Bvh(vertices, faces), origins, directions


def calls_completed_during(call, other):
    """How many times `other` ran to completion in another thread while `call` ran in this
    one. The interpreter's switch interval is raised so far that no thread is ever made to
    give up the GIL: the other thread can run during `call` only if `call` releases it.
    Proved by counting events, not by timing, so a loaded machine changes nothing."""
    counter = [0]
    done = threading.Event()

    def loop():
        while not done.is_set():
            other()
            counter[0] += 1

    old = sys.getswitchinterval()
    sys.setswitchinterval(1000.0)
    worker = threading.Thread(target=loop)
    try:
        worker.start()
        while counter[0] == 0:  # the other thread is running
            time.sleep(0)
        before = counter[0]
        call()
        after = counter[0]
    finally:
        done.set()
        worker.join()
        sys.setswitchinterval(old)
    return after - before


def test_queries_release_the_gil():
    """While a query traces, another thread runs Python code."""
    bvh, origins, directions = big_scene()
    ran = calls_completed_during(
        lambda: bvh.intersect(origins, directions, threads=1), lambda: time.sleep(0)
    )
    assert ran > 0


def test_two_python_threads_trace_at_the_same_time():
    """While one Python thread traces, another completes traces of its own (each on its
    own one-worker pool)."""
    bvh, origins, directions = big_scene()
    ran = calls_completed_during(
        lambda: bvh.intersect(origins, directions, threads=1),
        lambda: bvh.occluded(origins[:2000], directions[:2000], threads=1),
    )
    assert ran > 0


def os_threads():
    return len(os.listdir("/proc/self/task"))


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="counts threads in /proc")
def test_thread_counts_of_many_sizes_do_not_pile_up():
    """A loop over thread counts holds one pool at a time: the workers of the sizes asked
    for before end (asynchronously, so the count is awaited, not timed)."""
    bvh, origins, directions = big_scene()
    before = os_threads()
    for n in range(1, 65):
        bvh.intersect(origins[:64], directions[:64], threads=n)
    # Kept all, 1 + 2 + ... + 64 = 2080 workers would be alive.
    deadline = time.monotonic() + 120
    while os_threads() > before + 64 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert os_threads() <= before + 64, os_threads()
