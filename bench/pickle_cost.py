#!/usr/bin/env python3
"""What pickling canopy's structures costs, and what serialising their trees would save:
a RayScene and a Bvh over a mesh (the 202k dragon by default) are pickled and loaded
(loading builds the trees again, on all cores or `--threads`), against copying a blob as
large as the trees through pickle, the least that loading a serialised tree would cost.

Run with a venv that has canopy_rt (bench/distance_compare.sh makes one):
    bench/.venv/bin/python bench/pickle_cost.py [--mesh FILE] [--runs 3]
"""

import argparse
import os
import pickle
import time

import numpy as np

import canopy_rt as canopy

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DRAGON = os.path.join(ROOT, "..", "shared", "assets", "meshes", "dragon_res2.ply")


def best(runs, call):
    times, result = [], None
    for _ in range(runs):
        start = time.perf_counter()
        result = call()
        times.append(time.perf_counter() - start)
    return min(times), result


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", default=DRAGON)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    vertices, faces = canopy.load_mesh(args.mesh)
    print(f"{os.path.basename(args.mesh)}: {len(faces)} triangles, {os.cpu_count()} cores")
    bvh = canopy.Bvh(vertices, faces)
    scene = canopy.RayScene()
    scene.add_mesh(vertices, faces)
    scene.compute_distance(vertices[:1])  # the trees for point queries too
    tree_bytes = bvh.stats()["memory_bytes"]
    for name, thing in [("RayScene", scene), ("Bvh", bvh)]:
        dump, blob = best(args.runs, lambda: pickle.dumps(thing))
        load, _ = best(args.runs, lambda: pickle.loads(blob))
        print(f"{name:<9} pickle {dump * 1e3:7.1f} ms, {len(blob) / 1e6:6.2f} MB; "
              f"load (builds the tree) {load * 1e3:7.1f} ms")
    tree = np.zeros(tree_bytes, np.uint8)
    dump, blob = best(args.runs, lambda: pickle.dumps(tree))
    load, _ = best(args.runs, lambda: pickle.loads(blob))
    print(f"a serialised tree would add {tree_bytes / 1e6:.2f} MB to the pickle; copying that "
          f"many bytes through pickle takes {dump * 1e3:.1f} ms to dump and {load * 1e3:.1f} ms "
          f"to load, before any check or fix-up of the nodes")


if __name__ == "__main__":
    main()
