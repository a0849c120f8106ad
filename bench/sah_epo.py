#!/usr/bin/env python3
"""How well SAH and EPO predict the measured cost of tracing, across builders.

For each mesh and builder: the 8-wide tree's SAH and EPO, and the measured ns per
incoherent ray (closest hit, one thread, best of --runs) through canopy's Python API.
Prints a table and, per mesh, the Pearson and Spearman correlation of each metric with
ns/ray across builders; writes a scatter plot when matplotlib is installed.

Run it with `bench/sah_epo.sh` (makes bench/.venv with numpy and matplotlib and builds
canopy's wheel into it).
"""

import argparse
import os
import sys
import time

import numpy as np

import canopy_rt as canopy

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(ROOT, "..", "shared", "assets", "meshes")


def incoherent_rays(vertices, n, seed):
    """Rays from points on the mesh's surface region in uniform directions."""
    rng = np.random.default_rng(seed)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    origins = lo + rng.random((n, 3)) * (hi - lo)
    directions = rng.normal(size=(n, 3))
    return origins.astype(np.float32), directions.astype(np.float32)


def ranks(x):
    order = np.argsort(x)
    r = np.empty(len(x))
    r[order] = np.arange(len(x))
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", nargs="*", default=[
        os.path.join(ROOT, "scenes", "meshes", "bunny.ply"),
        os.path.join(SHARED, "dragon_res3.ply"),
        os.path.join(SHARED, "dragon_res2.ply"),
    ])
    ap.add_argument("--rays", type=int, default=200_000)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--width", type=int, default=8)
    ap.add_argument("--plot", default="sah_epo.png")
    args = ap.parse_args()
    builders = [b for b in canopy.builders() if not b.startswith("sort-") and b != "agglomerative"]
    results = {}
    print(f"| mesh | builder | SAH | EPO | ns/ray (1 thread, {args.width}-wide) |")
    print("|---|---|---|---|---|")
    for mesh in args.meshes:
        vertices, faces = canopy.load_mesh(mesh)
        name = f"{os.path.splitext(os.path.basename(mesh))[0]} ({len(faces) // 1000}k)"
        origins, directions = incoherent_rays(vertices, args.rays, 1)
        rows = []
        for builder in builders:
            bvh = canopy.Bvh(vertices, faces, builder=builder, width=args.width)
            sah, epo = bvh.stats()["sah_cost"], bvh.epo()
            best = np.inf
            for _ in range(args.runs):
                start = time.perf_counter()
                bvh.intersect(origins, directions, threads=1)
                best = min(best, time.perf_counter() - start)
            ns = best / args.rays * 1e9
            rows.append((builder, sah, epo, ns))
            print(f"| {name} | {builder} | {sah:.2f} | {epo:.3f} | {ns:.0f} |", flush=True)
        results[name] = rows
    print("\n| mesh | corr(SAH, ns/ray) Pearson / Spearman | corr(EPO, ns/ray) Pearson / Spearman |")
    print("|---|---|---|")
    for name, rows in results.items():
        sah, epo, ns = (np.array([r[i] for r in rows]) for i in (1, 2, 3))
        p = lambda a: np.corrcoef(a, ns)[0, 1]
        s = lambda a: np.corrcoef(ranks(a), ranks(ns))[0, 1]
        print(f"| {name} | {p(sah):.2f} / {s(sah):.2f} | {p(epo):.2f} / {s(epo):.2f} |")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("(matplotlib not installed: no plot)", file=sys.stderr)
        return
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for name, rows in results.items():
        ns = [r[3] for r in rows]
        for ax, i, label in ((axes[0], 1, "SAH cost"), (axes[1], 2, "EPO")):
            ax.scatter([r[i] for r in rows], ns, label=name)
            for r in rows:
                ax.annotate(r[0], (r[i], r[3]), fontsize=6)
            ax.set_xlabel(label)
            ax.set_ylabel("ns per incoherent ray (1 thread)")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"SAH and EPO against measured cost, {args.width}-wide trees")
    fig.tight_layout()
    fig.savefig(args.plot, dpi=110)
    print(f"wrote {args.plot}", file=sys.stderr)


if __name__ == "__main__":
    main()
