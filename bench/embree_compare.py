#!/usr/bin/env python3
"""canopy against Embree 4 (through embreex) on the same meshes and rays, in one run.

Run it with `bench/embree_compare.sh` (which makes its own venv with embreex, numpy and
canopy's Python bindings). Both libraries are called from this script on the same numpy
arrays: canopy as `canopy.Bvh(...).intersect/occluded`, one call per batch.
For each mesh: 1024x1024 primary rays of a pinhole camera framing it, and 1M incoherent
rays (origins at primary hits, offset along the normal; directions uniform on the sphere);
closest hit and occlusion; 1 and 2 threads. Hits are checked to agree, then a table of
Mrays/s and one line `ratio <mesh> <rays> <query> <threads>: X.XX` per cell is printed.

canopy's batch call traces a large batch over a large tree in the order of the rays'
origins (`canopy_bvh::RayOrder`), which Embree's per-ray calls cannot do for themselves;
the table also times Embree on the rays sorted that way ("canopy's order", ordering time
not counted), so the part of the ratio that comes from the order shows.

embreex calls rtcIntersect1/rtcOccluded1 in a loop over numpy arrays and builds numpy
outputs; that loop costs tens of ns per ray on its own. So Embree is also called from C
(`bench/embree_native.c`, compiled here against the libembree4 that embreex ships, loaded
with ctypes): the same library, per-ray calls, the same rays and threads, no Python loop.
Each of Embree's two modes is compared with its counterpart in canopy: the `ratio` lines
set canopy's fast triangle test (`Bvh(..., triangles="fast")`) against Embree's default
kernel, and the `ratio-robust` lines canopy's default, watertight test against the same
library in its watertight mode (RTC_SCENE_FLAG_ROBUST). Where no C compiler
is found, the kernel figure falls back to an estimate: embreex's time less its time on a
scene whose one triangle no ray comes near. Both are shown when both exist. canopy's
figures are as called from Python, its own conversions and output arrays included.
"""

import argparse
import ctypes
import glob
import json
import os
import subprocess
import sys
import tempfile
import threading
import time

# numpy's BLAS threads spin on idle cores after a call: on a small machine they would
# compete with the traced threads. Nothing here needs BLAS threads.
for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

try:
    import canopy_rt as canopy  # noqa: E402
except ImportError:  # bench/kernel_profile.py borrows the mesh and ray makers without it
    canopy = None
import numpy as np  # noqa: E402
from embreex import rtcore_scene as rtcs  # noqa: E402
from embreex.mesh_construction import TriangleMesh  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(ROOT, "..", "shared", "assets", "meshes")


def read_ply(path):
    """Vertices (V,3) float32 and faces (F,3) int of a binary little-endian triangle PLY."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    if "format binary_little_endian 1.0" not in header:
        sys.exit(f"{path}: only binary little-endian PLY is supported here")
    n_vert = n_face = 0
    vprops = []
    element = None
    for line in header:
        parts = line.split()
        if parts[:1] == ["element"]:
            element = parts[1]
            if element == "vertex":
                n_vert = int(parts[2])
            elif element == "face":
                n_face = int(parts[2])
        elif parts[:1] == ["property"] and element == "vertex":
            vprops.append((parts[2], parts[1]))
    if any(t != "float" for _, t in vprops):
        sys.exit(f"{path}: vertex properties must be float")
    verts = np.frombuffer(data, np.float32, n_vert * len(vprops), end).reshape(n_vert, -1)[:, :3]
    faces = np.frombuffer(data, np.dtype([("n", "u1"), ("i", "<u4", 3)]), n_face, end + 4 * n_vert * len(vprops))
    if np.any(faces["n"] != 3):
        sys.exit(f"{path}: only triangles are supported here")
    return np.ascontiguousarray(verts, np.float32), faces["i"].astype(np.int64)


def primary_rays(verts, size):
    lo, hi = verts.min(0), verts.max(0)
    centre, radius = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    vfov = np.radians(40.0)
    eye = centre + radius / np.tan(vfov / 2) * 1.1 * np.array([0, 0.3, 1.0]) / np.linalg.norm([0, 0.3, 1.0])
    w = (eye - centre) / np.linalg.norm(eye - centre)
    u = np.cross([0, 1, 0], w)
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    h = np.tan(vfov / 2)
    s = (np.arange(size) + 0.5) / size * 2 - 1
    px, py = np.meshgrid(s * h, -s * h)
    d = px[..., None] * u + py[..., None] * v - w
    d = (d / np.linalg.norm(d, axis=-1, keepdims=True)).reshape(-1, 3)
    o = np.broadcast_to(eye, d.shape)
    return np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)


def incoherent_rays(o, d, hit, n, rng):
    idx = np.flatnonzero(hit["primID"] >= 0)
    pick = idx[rng.integers(0, len(idx), n)]
    p = o[pick] + hit["tfar"][pick, None] * d[pick]
    ng = hit["Ng"][pick]
    ng = ng / np.linalg.norm(ng, axis=1, keepdims=True)
    ng = np.where((np.sum(ng * d[pick], axis=1) < 0)[:, None], ng, -ng)  # towards the camera
    scale = np.abs(p).max(axis=1, keepdims=True)
    origin = p + ng * (1e-4 * scale)
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    return np.ascontiguousarray(origin, np.float32), np.ascontiguousarray(dirs, np.float32)


def origin_order(o):
    """The order canopy traces a large batch in over a large tree (`canopy_bvh::RayOrder`):
    by the Morton code of the origin's cell, 32 cells per axis of the origins' bounds,
    stable. For the informational column that gives Embree the same order."""
    lo, hi = o.min(axis=0), o.max(axis=0)
    extent = np.where(hi > lo, hi - lo, 1.0)
    cell = np.clip(((o - lo) / extent * 32).astype(np.int64), 0, 31)
    key = np.zeros(len(o), np.int64)
    for bit in range(5):
        for axis in range(3):
            key |= ((cell[:, axis] >> bit) & 1) << (3 * bit + 2 - axis)
    return np.argsort(key, kind="stable")


def embree_run(scene, o, d, query, threads):
    """Seconds for one pass over all rays, split across `threads` Python threads (embreex
    releases the GIL inside its loop)."""
    parts = np.array_split(np.arange(len(o)), threads)
    results = [None] * threads

    def work(k):
        sl = slice(parts[k][0], parts[k][-1] + 1)
        if query == "closest":
            results[k] = scene.run(o[sl], d[sl], output=1)
        else:
            results[k] = scene.run(o[sl], d[sl], query="OCCLUDED")

    start = time.perf_counter()
    pool = [threading.Thread(target=work, args=(k,)) for k in range(threads)]
    for t in pool:
        t.start()
    for t in pool:
        t.join()
    elapsed = time.perf_counter() - start
    if query == "closest":
        merged = {k: np.concatenate([r[k] for r in results]) for k in ("tfar", "primID", "u", "v", "Ng")}
    else:
        # embreex answers occlusion with the blocking geometry's id, -1 when unblocked.
        merged = np.concatenate(results) >= 0
    return elapsed, merged


class NativeEmbree:
    """Embree called per ray from C (bench/embree_native.c) through ctypes."""

    def __init__(self, lib, verts, faces, robust=False):
        self.lib = lib
        v = np.ascontiguousarray(verts, np.float32)
        f = np.ascontiguousarray(faces, np.uint32)
        self.handle = lib.native_scene(v.ctypes.data, len(v), f.ctypes.data, len(f), int(robust))
        if not self.handle:
            raise RuntimeError("Embree could not build the scene")

    def __del__(self):
        if getattr(self, "handle", None):
            self.lib.native_release(self.handle)

    def run(self, o, d, query, threads):
        """Seconds for one pass over all rays on `threads` threads, and the answers."""
        n = len(o)
        t = np.empty(n, np.float32)
        prim = np.empty(n, np.int32)
        blocked = np.empty(n, np.uint8)
        closest = query == "closest"
        start = time.perf_counter()
        status = self.lib.native_trace(self.handle, o.ctypes.data, d.ctypes.data, n, int(closest),
                                       threads, t.ctypes.data, prim.ctypes.data, blocked.ctypes.data)
        elapsed = time.perf_counter() - start
        if status != 0:
            raise RuntimeError("a tracing thread could not start")
        return elapsed, ({"tfar": t, "primID": prim} if closest else blocked.astype(bool))


def load_native():
    """bench/embree_native.c compiled against embreex's libembree4, or None (with the reason
    on stderr) where that cannot be done."""
    import embreex

    libs = glob.glob(os.path.join(os.path.dirname(os.path.dirname(embreex.__file__)), "embreex.libs", "libembree4*"))
    if not libs:
        print("note: embreex ships no libembree4 here; Embree's kernel figure is an estimate", file=sys.stderr)
        return None
    source = os.path.join(ROOT, "bench", "embree_native.c")
    # The library is loaded before its directory goes: a mapped file outlives its name.
    with tempfile.TemporaryDirectory(prefix="canopy-bench-") as scratch:
        out = os.path.join(scratch, "embree_native.so")
        command = [os.environ.get("CC", "cc"), "-O2", "-shared", "-fPIC", source, "-o", out,
                   f"-L{os.path.dirname(libs[0])}", f"-l:{os.path.basename(libs[0])}",
                   f"-Wl,-rpath,{os.path.dirname(libs[0])}", "-lpthread"]
        try:
            subprocess.run(command, check=True, capture_output=True, text=True)
        except (OSError, subprocess.CalledProcessError) as e:
            print(f"note: could not compile {source} ({getattr(e, 'stderr', '') or e}); "
                  "Embree's kernel figure is an estimate", file=sys.stderr)
            return None
        lib = ctypes.CDLL(out)
    lib.native_scene.restype = ctypes.c_void_p
    lib.native_scene.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_size_t,
                                 ctypes.c_int]
    lib.native_release.argtypes = [ctypes.c_void_p]
    lib.native_trace.restype = ctypes.c_int
    lib.native_trace.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t,
                                 ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
    return lib


def best_of(runs, *fs):
    """Best time and last output of each function, run in turns `runs` times: this
    machine's speed drifts over seconds, and turns expose every side to the same drift."""
    best, out = [float("inf")] * len(fs), [None] * len(fs)
    for _ in range(runs):
        for k, f in enumerate(fs):
            t, out[k] = f()
            best[k] = min(best[k], t)
    return list(zip(best, out))


def canopy_run(bvh, o, d, query, threads):
    """Seconds for one batch call over all rays on `threads` workers, and the answers."""
    start = time.perf_counter()
    if query == "closest":
        hits = bvh.intersect(o, d, threads=threads)
        out = {"tfar": hits.t, "primID": hits.prim}
    else:
        out = bvh.occluded(o, d, threads=threads)
    return time.perf_counter() - start, out


def build_times(verts, faces, builder, runs):
    """Best build times in ms on the CPUs this process may use: Embree's BVH build (the
    commit that the first query triggers; embreex's slow vertex upload excluded) and
    canopy's (build, collapse to 8-wide, triangle packing: `stats()["build_ms"]`)."""
    o = np.zeros((1, 3), np.float32)
    d = np.ones((1, 3), np.float32)
    indices = faces.astype(np.int32)
    embree = canopy_ms = float("inf")
    for _ in range(runs):
        scene = rtcs.EmbreeScene()
        TriangleMesh(scene, verts, indices)
        start = time.perf_counter()
        scene.run(o, d)
        embree = min(embree, (time.perf_counter() - start) * 1e3)
        bvh = canopy.Bvh(verts, faces, builder=builder, width=8, threads=len(os.sched_getaffinity(0)))
        canopy_ms = min(canopy_ms, bvh.stats()["build_ms"])
    return embree, canopy_ms


def compare(query, emb, can):
    """Rays whose answers disagree: hit/miss must match exactly; distances within 1e-4
    relative (a different primitive at the same distance is a tie on a shared edge)."""
    if query == "occluded":
        return int(np.sum(emb != can))
    e_hit, c_hit = emb["primID"] >= 0, can["primID"] >= 0
    bad = e_hit != c_hit
    both = e_hit & c_hit
    et, ct = emb["tfar"][both], can["tfar"][both]
    bad[both] |= np.abs(et - ct) > 1e-4 * np.maximum(np.abs(et), 1e-6)
    return int(np.sum(bad))


def main():
    if canopy is None:
        sys.exit("canopy_rt is not installed in this Python: run bench/embree_compare.sh")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", nargs="*", default=[os.path.join(SHARED, "bunny.ply"), os.path.join(SHARED, "dragon_res2.ply")])
    ap.add_argument("--size", type=int, default=1024, help="primary rays: size x size")
    ap.add_argument("--incoherent", type=int, default=1_000_000)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--builder", default="binned-sah", help="canopy's builder (see canopy.builders())")
    ap.add_argument("--build-only", action="store_true",
                    help="only compare build times, on the CPUs this process may use "
                         "(embree_compare.sh runs it under `taskset` for 1 and 2 cores: "
                         "embreex has no thread setting)")
    args = ap.parse_args()
    if args.build_only:
        threads = len(os.sched_getaffinity(0))
        for mesh in args.meshes:
            verts, faces = read_ply(mesh)
            name = os.path.splitext(os.path.basename(mesh))[0] + f"-{len(faces) // 1000}k"
            embree, ours = build_times(verts, faces, args.builder, args.runs)
            print(f"build {name} {threads} threads: canopy {args.builder} {ours:.1f} ms, "
                  f"Embree {embree:.1f} ms, canopy/Embree time {ours / embree:.2f}")
        return
    rng = np.random.default_rng(7)
    native_lib = load_native()

    # embreex's own per-ray cost: a scene with one triangle far from every ray.
    far = rtcs.EmbreeScene()
    TriangleMesh(far, np.array([[[1e6, 1e6, 1e6], [1e6 + 1, 1e6, 1e6], [1e6, 1e6 + 1, 1e6]]], np.float32))

    rows = []
    for mesh in args.meshes:
        verts, faces = read_ply(mesh)
        name = os.path.splitext(os.path.basename(mesh))[0] + f"-{len(faces) // 1000}k"
        scene = rtcs.EmbreeScene()
        TriangleMesh(scene, verts[faces])
        bvh = canopy.Bvh(verts, faces, builder=args.builder, width=8)
        bvh_fast = canopy.Bvh(verts, faces, builder=args.builder, width=8, triangles="fast")
        native = native_lib and NativeEmbree(native_lib, verts, faces)
        robust = native_lib and NativeEmbree(native_lib, verts, faces, robust=True)
        isa = bvh.stats()["isa"]
        po, pd = primary_rays(verts, args.size)
        _, prim_hits = embree_run(scene, po, pd, "closest", 1)
        io, idir = incoherent_rays(po, pd, prim_hits, args.incoherent, rng)
        for kind, (o, d) in (("primary", (po, pd)), ("incoherent", (io, idir))):
            # The same rays in the order canopy traces them in (a camera's stay as they are).
            order = origin_order(o) if kind == "incoherent" else np.arange(len(o))
            so, sd = np.ascontiguousarray(o[order]), np.ascontiguousarray(d[order])
            for query in ("closest", "occluded"):
                for threads in (1, 2):
                    passes = [
                        lambda: embree_run(scene, o, d, query, threads),
                        lambda: embree_run(far, o, d, query, threads),
                        lambda: canopy_run(bvh, o, d, query, threads),
                        lambda: canopy_run(bvh_fast, o, d, query, threads),
                    ]
                    if native:
                        passes += [lambda: native.run(o, d, query, threads),
                                   lambda: native.run(so, sd, query, threads),
                                   lambda: robust.run(o, d, query, threads)]
                    else:
                        passes += [lambda: embree_run(scene, so, sd, query, threads)]
                    timed = best_of(args.runs, *passes)
                    (e_s, e_out), (x_s, _), (c_s, c_out), (f_s, f_out) = timed[:4]
                    n = len(o)
                    estimate = n / max(e_s - x_s, 1e-9) / 1e6
                    if native:
                        (k_s, k_out), (ks_s, _), (r_s, r_out) = timed[4:]
                        kernel, kernel_ordered = n / k_s / 1e6, n / ks_s / 1e6
                        kernel_robust = n / r_s / 1e6
                    else:
                        k_out = r_out = e_out
                        kernel, kernel_ordered = estimate, n / max(timed[4][0] - x_s, 1e-9) / 1e6
                        kernel_robust = float("nan")
                    row = {
                        "mesh": name, "rays": kind, "query": query, "threads": threads, "n": n,
                        "embree": n / e_s / 1e6,
                        "embree_estimate": estimate,
                        "embree_kernel": kernel,
                        "embree_kernel_ordered": kernel_ordered,
                        "embree_kernel_robust": kernel_robust,
                        "kernel_source": "native" if native else "estimate",
                        "canopy": n / c_s / 1e6,
                        "canopy_fast": n / f_s / 1e6,
                        "mismatches": compare(query, k_out, f_out),
                        "robust_mismatches": compare(query, r_out, c_out),
                        "embreex_mismatches": compare(query, e_out, c_out),
                        "isa": isa,
                    }
                    rows.append(row)
                    print(json.dumps(row), file=sys.stderr, flush=True)

    source = ("called per ray from C (bench/embree_native.c)" if native_lib
              else "estimated: embreex's time less its Python loop's")
    print(f"\ncanopy {canopy.__version__} ({args.builder}, 8-wide, {rows[0]['isa']}) against Embree 4 (embreex's "
          f"library), on the same numpy arrays, Mrays/s, best of {args.runs}. Embree kernel: {source}.\n")
    print("Each mode against its counterpart: canopy's fast triangle test (triangles=\"fast\") "
          "against Embree's default kernel (ratio); canopy's default, watertight test against "
          "Embree with RTC_SCENE_FLAG_ROBUST (ratio, robust). The other columns use canopy's "
          "watertight figure.\n")
    print("| mesh | rays | query | threads | canopy fast | Embree kernel | ratio | canopy | Embree robust "
          "| ratio, robust | Embree kernel, canopy's order | ratio, same order | Embree via embreex "
          "| ratio (as called) | estimated kernel | disagreeing rays |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['mesh']} | {r['rays']} | {r['query']} | {r['threads']} | {r['canopy_fast']:.2f} | "
              f"{r['embree_kernel']:.2f} | {r['canopy_fast'] / r['embree_kernel']:.2f} | {r['canopy']:.2f} | "
              f"{r['embree_kernel_robust']:.2f} | {r['canopy'] / r['embree_kernel_robust']:.2f} | "
              f"{r['embree_kernel_ordered']:.2f} | {r['canopy'] / r['embree_kernel_ordered']:.2f} | "
              f"{r['embree']:.2f} | {r['canopy'] / r['embree']:.2f} | {r['embree_estimate']:.2f} | {r['mismatches']} |")
    print()
    for r in rows:
        print(f"ratio {r['mesh']} {r['rays']} {r['query']} {r['threads']}: {r['canopy_fast'] / r['embree_kernel']:.2f}")
        print(f"ratio-robust {r['mesh']} {r['rays']} {r['query']} {r['threads']}: "
              f"{r['canopy'] / r['embree_kernel_robust']:.2f}")
    if any(max(r["mismatches"], r["embreex_mismatches"], r["robust_mismatches"]) > 0.0001 * r["n"]
           for r in rows):
        sys.exit("hits disagree on more than 0.01% of rays")


if __name__ == "__main__":
    main()
