"""canopy_rt.distributed's costs on a local Ray cluster, and a model of larger ones.

Measured, each best of --runs, in one run of this script:
- overhead per task: an image of 1x1-pixel tiles at 1 sample (the render itself is
  nanoseconds), time per tile on one node of one CPU;
- shipping: a scene's file bundle of --megabytes put into the object store and written
  out by a worker as a task would (canopy's own bundling and materializing), per MB;
- speedup: paper-1 at --size, --spp rendered by canopy in one process on one thread, and
  distributed over 1 and 2 nodes of one CPU each (tile 32).

Then a model (stated, not measured) of a 4K frame and a 240-frame animation on 8, 64 and
512 nodes of 32 cores: time = work / (busy cores x efficiency) + tasks x overhead / busy
cores + 1 MB shipped, where busy cores = min(cores, tasks in flight) and the efficiency
and overheads are the ones measured here.
"""

import argparse
import os
import tempfile
import time

import numpy as np
import ray
from ray.cluster_utils import Cluster

import canopy_rt as canopy
import canopy_rt.distributed as distributed


def best(runs, f):
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        f()
        times.append(time.perf_counter() - start)
    return min(times)


def cluster_of(nodes):
    cluster = Cluster(initialize_head=True, head_node_args=dict(num_cpus=1, include_dashboard=False))
    for _ in range(nodes - 1):
        cluster.add_node(num_cpus=1)
    ray.init(address=cluster.address, include_dashboard=False, log_to_driver=False)
    cluster.wait_for_nodes()
    return cluster


def close(cluster):
    ray.shutdown()
    cluster.shutdown()


def mesh_scene(directory, megabytes):
    """A scene file with a binary PLY of about `megabytes` (a grid of triangles)."""
    n = max(2, int((megabytes * 2**20 / 38) ** 0.5))  # 12 bytes a vertex, 2 x 13 a face
    xs, ys = np.meshgrid(np.linspace(-1, 1, n, dtype=np.float32), np.linspace(-1, 1, n, dtype=np.float32))
    vertices = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n, np.float32)], 1)
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    faces = np.concatenate([np.stack([i, i + 1, i + n], -1).reshape(-1, 3),
                            np.stack([i + 1, i + n + 1, i + n], -1).reshape(-1, 3)]).astype(np.int32)
    path = os.path.join(directory, f"grid-{megabytes}.ply")
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\n"
                 "property float x\nproperty float y\nproperty float z\n"
                 f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode())
        f.write(vertices.tobytes())
        rows = np.zeros(len(faces), dtype=[("n", "u1"), ("v", "<i4", 3)])
        rows["n"], rows["v"] = 3, faces
        f.write(rows.tobytes())
    scene = os.path.join(directory, f"grid-{megabytes}.toml")
    with open(scene, "w") as f:
        f.write(f'camera = {{ look_from = [0, 0, 3], look_at = [0, 0, 0] }}\n'
                f'render = {{ width = 8, height = 8, spp = 1 }}\n'
                f'[[meshes]]\nfile = "grid-{megabytes}.ply"\n'
                f'material = {{ type = "lambertian", albedo = [0.5, 0.5, 0.5] }}\n')
    return scene, os.path.getsize(path) / 2**20


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--tasks", type=int, default=256, help="tiles in the overhead test")
    parser.add_argument("--megabytes", type=float, default=32)
    parser.add_argument("--size", default="320x192")
    parser.add_argument("--spp", type=int, default=128)
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))

    cluster = cluster_of(1)
    side = int(args.tasks ** 0.5)
    distributed.render("paper-3", size=(side, side), spp=1, tile=1)  # warm the workers
    overhead = best(args.runs, lambda: distributed.render("paper-3", size=(side, side), spp=1, tile=1)) / side**2
    print(f"overhead per task: {overhead * 1e3:.2f} ms ({side * side} tiles of 1 pixel, 1 node of 1 CPU)")
    with tempfile.TemporaryDirectory() as directory:
        large, large_mb = mesh_scene(directory, args.megabytes)
        source, files = distributed._bundle(large)

        @ray.remote(num_cpus=1)
        def written(bundle):
            source, files = bundle
            path = distributed._materialize(source, files)
            return os.path.getsize(os.path.join(os.path.dirname(path), os.path.basename(large)[:-5] + ".ply"))

        runs = iter(range(10**6))

        def ship():
            # A file name of its own each run, so that no worker has the bundle already.
            bundle = (source, {**files, f"{directory}/run-{next(runs)}": b""})
            assert ray.get(written.remote(ray.put(bundle))) > 0

        t_ship = best(args.runs, ship)
    per_mb = t_ship / large_mb
    print(f"shipping: {large_mb:.1f} MB of scene files in {t_ship:.2f} s: {per_mb * 1e3:.1f} ms per MB "
          "(object store, transfer to the worker, files written)")
    close(cluster)

    settings = dict(size=(width, height), spp=args.spp, seed=1)
    one_thread = best(args.runs, lambda: canopy.render("paper-1", threads=1, **settings))
    print(f"paper-1 {width}x{height} {args.spp} spp: one process, one thread {one_thread:.2f} s")
    times = {}
    for nodes in (1, 2):
        cluster = cluster_of(nodes)
        distributed.render("paper-1", size=(32, 32), spp=1, tile=32)
        times[nodes] = best(args.runs, lambda: distributed.render("paper-1", tile=32, **settings))
        close(cluster)
        print(f"  distributed over {nodes} node(s) of 1 CPU: {times[nodes]:.2f} s, "
              f"speedup {one_thread / times[nodes]:.2f}x over one thread")
    efficiency = one_thread / (2 * times[2])
    print(f"parallel efficiency on 2 nodes: {efficiency:.0%} (this machine has 2 cores; the "
          "driver and Ray's own processes share them)")

    # The model: paper-1's cost per pixel-sample scaled to a 4K frame at 1024 spp.
    per_sample = one_thread / (width * height * args.spp)
    frame = 3840 * 2160 * 1024 * per_sample
    tasks = (3840 // 64) * (2160 // 64 + 1)
    print(f"\nmodel: a 4K frame of paper-1 at 1024 spp is {frame / 3600:.1f} core-hours; tiles of 64 px: {tasks} tasks")
    print("| nodes x 32 cores | 4K frame | 240 frames |")
    print("|---|---|---|")
    cores_efficiency = max(min(efficiency, 1.0), 0.5)
    for nodes in (8, 64, 512):
        cores = nodes * 32
        # At most one task per tile runs at once (one thread each): a frame of 2040 tiles
        # cannot use more cores than that.
        def hours(frames):
            busy = min(cores, frames * tasks)
            return (frames * frame / (busy * cores_efficiency) + frames * tasks * overhead / busy
                    + per_mb * 1.0)
        print(f"| {nodes} | {hours(1):.1f} s | {hours(240) / 3600:.2f} h |")

if __name__ == "__main__":
    main()
