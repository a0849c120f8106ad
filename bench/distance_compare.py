#!/usr/bin/env python3
"""canopy's point queries against Open3D's RaycastingScene on the same mesh and points,
in one run.

Run it with `bench/distance_compare.sh` (which makes its own venv with open3d, numpy and
canopy's Python bindings; Open3D needs Debian's libusb-1.0-0). Both libraries are called
from this script on the same float32 arrays: canopy as `canopy.RayScene`, Open3D as
`open3d.t.geometry.RaycastingScene`, each with its thread count set per call (`threads=`
and `nthreads=`). For each query (closest points, distance, signed distance, occupancy,
and counting and listing every crossing along rays from the same points in random
directions) and thread count the two run in turns, best of `--runs`; the script prints a table and
one line `ratio <mesh> <query> <threads>: X.XX` per cell: canopy's speed over Open3D's.

Query points: half uniform in the mesh's box grown by a fifth on every side, half near
the surface (points on triangles, moved along a random direction by up to 2% of the box's
diagonal). Agreement is checked on every point: distances within 1e-5 of the diagonal,
and inside/outside identical away from the surface (farther than 1e-3 of the diagonal).
The two inside tests differ by design: canopy's is the generalised winding number,
Open3D's the parity of one ray's crossings (`nsamples=1`, its default) or a vote of
several rays; disagreements are counted, and up to `--judge` of them settled by the
exact winding number (a float64 sum over every triangle). Build times are shown for
information.
"""

import argparse
import os
import time

for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import canopy_rt as canopy  # noqa: E402
import numpy as np  # noqa: E402
import open3d as o3d  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DRAGON = os.path.join(ROOT, "..", "shared", "assets", "meshes", "dragon_res2.ply")


def query_points(vertices, faces, count, seed):
    rng = np.random.default_rng(seed)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    diagonal = float(np.linalg.norm(high - low))
    grow = (high - low) / 5
    uniform = rng.uniform(low - grow, high + grow, size=(count // 2, 3))
    tri = vertices[faces[rng.integers(0, len(faces), count - count // 2)]]
    a, b = rng.random((2, len(tri), 1))
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    on_surface = tri[:, 0] + a * (tri[:, 1] - tri[:, 0]) + b * (tri[:, 2] - tri[:, 0])
    direction = rng.normal(size=on_surface.shape)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    near = on_surface + direction * rng.uniform(0, 0.02 * diagonal, size=(len(tri), 1))
    return np.ascontiguousarray(np.concatenate([uniform, near]), np.float32), diagonal


def exact_winding_number(triangles, point):
    """The winding number at `point` by a sum of every triangle's solid angle (float64)."""
    a, b, c = (triangles[:, i] - point for i in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    numerator = dot(a, np.cross(b, c))
    denominator = la * lb * lc + dot(a, b) * lc + dot(a, c) * lb + dot(b, c) * la
    return 2 * np.arctan2(numerator, denominator).sum() / (4 * np.pi)


def best_of(runs, call):
    times, result = [], None
    for _ in range(runs):
        start = time.perf_counter()
        result = call()
        times.append(time.perf_counter() - start)
    return min(times), result


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", default=DRAGON)
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--nsamples", type=int, default=1,
                        help="rays Open3D's inside test votes with (its default: 1)")
    parser.add_argument("--queries", nargs="+",
                        default=["closest", "distance", "signed", "occupancy", "count", "list"],
                        help="the queries to time (all by default)")
    parser.add_argument("--judge", type=int, default=50,
                        help="disagreements on inside/outside settled by the exact winding "
                             "number, a sum over every triangle in float64")
    args = parser.parse_args()

    vertices, faces = canopy.load_mesh(args.mesh)
    vertices = np.ascontiguousarray(vertices, np.float32)
    name = os.path.splitext(os.path.basename(args.mesh))[0]
    points, diagonal = query_points(vertices, faces, args.points, seed=1)
    print(f"{name}: {len(faces)} triangles, {len(points)} query points, diagonal {diagonal:.4g}")

    start = time.perf_counter()
    ours = canopy.RayScene()
    ours.add_mesh(vertices, faces)
    ours.compute_distance(points[:1])  # builds the top tree too
    ours_build = time.perf_counter() - start
    start = time.perf_counter()
    theirs = o3d.t.geometry.RaycastingScene()
    theirs.add_triangles(o3d.core.Tensor(vertices), o3d.core.Tensor(faces.astype(np.uint32)))
    theirs.compute_distance(o3d.core.Tensor(points[:1]))  # Embree commits the scene here
    theirs_build = time.perf_counter() - start
    print(f"build (all cores, information only): canopy {ours_build * 1e3:.0f} ms, "
          f"Open3D {theirs_build * 1e3:.0f} ms")

    tensor = o3d.core.Tensor(points)
    # Rays for counting and listing hits: from the query points, in random directions.
    directions = np.random.default_rng(2).normal(size=points.shape).astype(np.float32)
    rays = np.ascontiguousarray(np.hstack([points, directions]))
    ray_tensor = o3d.core.Tensor(rays)
    n = args.nsamples
    queries = {
        "closest": (lambda t: ours.compute_closest_points(points, threads=t),
                    lambda t: theirs.compute_closest_points(tensor, nthreads=t)),
        "distance": (lambda t: ours.compute_distance(points, threads=t),
                     lambda t: theirs.compute_distance(tensor, nthreads=t)),
        "signed": (lambda t: ours.compute_signed_distance(points, threads=t),
                   lambda t: theirs.compute_signed_distance(tensor, nthreads=t, nsamples=n)),
        "occupancy": (lambda t: ours.compute_occupancy(points, threads=t),
                      lambda t: theirs.compute_occupancy(tensor, nthreads=t, nsamples=n)),
        "count": (lambda t: ours.count_intersections(rays, threads=t),
                  lambda t: theirs.count_intersections(ray_tensor, nthreads=t)),
        "list": (lambda t: ours.list_intersections(rays, threads=t),
                 lambda t: theirs.list_intersections(ray_tensor, nthreads=t)),
    }
    unknown = set(args.queries) - set(queries)
    if unknown:
        parser.error(f"unknown queries {sorted(unknown)}: choose from {list(queries)}")
    queries = {name: calls for name, calls in queries.items() if name in args.queries}
    rows, answers = [], {}
    for query, (canopy_call, open3d_call) in queries.items():
        for threads in args.threads:
            ours_best, theirs_best = np.inf, np.inf
            for _ in range(args.runs):  # in turns, so load changes hit both alike
                t, answers[query, "canopy"] = best_of(1, lambda: canopy_call(threads))
                ours_best = min(ours_best, t)
                t, answers[query, "open3d"] = best_of(1, lambda: open3d_call(threads))
                theirs_best = min(theirs_best, t)
            rows.append((query, threads, ours_best, theirs_best))

    print(f"\n{'query':<10} {'threads':>7} {'canopy ms':>10} {'Open3D ms':>10} "
          f"{'canopy Mq/s':>12} {'Open3D Mq/s':>12} {'ratio':>6}")
    for query, threads, ours_t, theirs_t in rows:
        print(f"{query:<10} {threads:>7} {ours_t * 1e3:>10.0f} {theirs_t * 1e3:>10.0f} "
              f"{len(points) / ours_t / 1e6:>12.2f} {len(points) / theirs_t / 1e6:>12.2f} "
              f"{theirs_t / ours_t:>6.2f}")

    print()
    for query, threads, ours_t, theirs_t in rows:
        print(f"ratio {name} {query} {threads}: {theirs_t / ours_t:.2f}")
    # Agreement, of the queries timed.
    if ("count", "canopy") in answers and ("list", "canopy") in answers:
        counts = answers["count", "canopy"]
        their_counts = answers["count", "open3d"].numpy()
        listed = answers["list", "canopy"]
        their_splits = answers["list", "open3d"]["ray_splits"].numpy()
        print(f"\ncrossings along {len(rays)} rays: counts differ on {int(np.sum(counts != their_counts))} "
              f"rays (canopy counts a crossing at a shared edge once; Embree, under Open3D, once per "
              f"triangle or not at all); {int(np.sum(counts % 2 != their_counts % 2))} differ in parity; "
              f"lists agree with counts: {np.array_equal(np.diff(listed.ray_splits), counts)} (canopy), "
              f"{np.array_equal(np.diff(their_splits), their_counts)} (Open3D)")
        # A ray from a point crosses a closed surface an odd number of times exactly when
        # the point is inside: judge the parity by the exact winding number at the origin.
        odd = np.nonzero(counts % 2 != their_counts % 2)[0][:args.judge]
        if len(odd):
            triangles = vertices[faces].astype(np.float64)
            exact = np.array([exact_winding_number(triangles, points[i].astype(np.float64)) > 0.5
                              for i in odd])
            print(f"judged by the exact winding number at the origins of {len(odd)} of the rays whose "
                  f"parities differ: canopy's parity right at {int(np.sum(exact == (counts[odd] % 2 == 1)))}, "
                  f"Open3D's at {int(np.sum(exact == (their_counts[odd] % 2 == 1)))}")
    if not all((q, "canopy") in answers for q in ("distance", "closest", "signed", "occupancy")):
        return
    distance = answers["distance", "canopy"]
    their_distance = answers["distance", "open3d"].numpy()
    worst = float(np.max(np.abs(distance - their_distance)))
    closest = answers["closest", "canopy"]
    their_points = answers["closest", "open3d"]["points"].numpy()
    point_gap = np.linalg.norm(closest.point - their_points, axis=1)
    signed = answers["signed", "canopy"]
    their_signed = answers["signed", "open3d"].numpy()
    away = distance > 1e-3 * diagonal
    sign_differs = int(np.sum((signed < 0)[away] != (their_signed < 0)[away]))
    inside = answers["occupancy", "canopy"]
    their_inside = answers["occupancy", "open3d"].numpy() > 0.5
    occupancy_differs = int(np.sum(inside[away] != their_inside[away]))
    print(f"\nagreement: distances within {worst / diagonal:.2e} of the diagonal "
          f"(aim 1e-5: {'met' if worst <= 1e-5 * diagonal else 'MISSED'}); nearest points "
          f"differ by more than 1e-5 of the diagonal at {int(np.sum(point_gap > 1e-5 * diagonal))} "
          f"points (equidistant ties); away from the surface ({int(away.sum())} points), "
          f"signs differ at {sign_differs} and occupancy at {occupancy_differs} "
          f"(Open3D nsamples={n}); {float(inside.mean()):.3f} of the points inside")

    differ = np.nonzero(away & (inside != their_inside))[0][:args.judge]
    if len(differ):
        triangles = vertices[faces].astype(np.float64)
        exact = np.array([exact_winding_number(triangles, points[i].astype(np.float64)) > 0.5
                          for i in differ])
        print(f"judged by the exact winding number at {len(differ)} of those points: canopy "
              f"right at {int(np.sum(exact == inside[differ]))}, Open3D right at "
              f"{int(np.sum(exact == their_inside[differ]))}")



if __name__ == "__main__":
    main()
