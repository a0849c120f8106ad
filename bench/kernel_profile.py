#!/usr/bin/env python3
"""Where a ray's time goes: canopy's and Embree's single-ray kernels on the same rays.

Run it with `bench/kernel_profile.sh`, which builds canopy's side
(`crates/canopy-render/examples/kernel_profile.rs`) and calls this script in the bench venv
(embreex ships Embree's library). For each mesh: primary rays of a pinhole camera and
incoherent rays from the surface (the rays of `bench/embree_compare.py`, the incoherent ones
in the order canopy's batch calls trace them, for both), closest hit and occlusion, and
four kernels: canopy's default (watertight) and its fast triangle test, Embree's default
and Embree's robust mode (the counterparts: canopy fast and Embree, canopy and Embree
robust).

Per ray it prints
- ns: the best of `--runs` native passes on one thread, each library with the best kernels
  this CPU has;
- under valgrind's callgrind (cache and branch simulation, only the tracing function
  counted; valgrind has no AVX-512, so both libraries run their AVX2 kernels there):
  instructions, L1 data misses, last-level misses, mispredicted branches;
- canopy's node visits and primitive tests (Embree does not expose its counts).

Cycles and IPC need hardware counters, which this project's machines do not expose
(`perf stat` says "not supported"); where they exist, `perf stat -e
cycles,instructions,branch-misses,L1-dcache-load-misses,LLC-load-misses` over the printed
commands gives them.
"""

import argparse
import os
import platform
import re
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from embree_compare import (SHARED, incoherent_rays, origin_order, primary_rays,  # noqa: E402
                            read_ply)
from embreex import rtcore_scene as rtcs  # noqa: E402
from embreex.mesh_construction import TriangleMesh  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EVENTS = ("Ir", "D1mr", "D1mw", "ILmr", "DLmr", "DLmw", "Bcm", "Bim")


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def write_mesh(path, verts, faces):
    with open(path, "wb") as f:
        np.array([len(verts), len(faces)], "<u8").tofile(f)
        np.ascontiguousarray(verts, "<f4").tofile(f)
        np.ascontiguousarray(faces, "<u4").tofile(f)


def write_rays(path, o, d):
    with open(path, "wb") as f:
        np.array([len(o)], "<u8").tofile(f)
        np.ascontiguousarray(o, "<f4").tofile(f)
        np.ascontiguousarray(d, "<f4").tofile(f)


def compile_embree(scratch):
    """bench/embree_native.c with its profiling main, linked to embreex's libembree4."""
    import embreex
    import glob

    libs = glob.glob(os.path.join(os.path.dirname(os.path.dirname(embreex.__file__)),
                                  "embreex.libs", "libembree4*"))
    if not libs:
        sys.exit("embreex ships no libembree4 here")
    out = os.path.join(scratch, "embree_profile")
    subprocess.run([os.environ.get("CC", "cc"), "-O2", "-DNATIVE_PROFILE_MAIN",
                    os.path.join(ROOT, "bench", "embree_native.c"), "-o", out,
                    f"-L{os.path.dirname(libs[0])}", f"-l:{os.path.basename(libs[0])}",
                    f"-Wl,-rpath,{os.path.dirname(libs[0])}", "-lpthread"], check=True)
    return out


def parse_line(text):
    """The `key value` pairs of a side's output line."""
    words = text.split()
    return {k: float(v) for k, v in zip(words[::2], words[1::2])}


def callgrind(command, function, scratch):
    """Events per traced call of `function` (all of them summed), from callgrind."""
    out = os.path.join(scratch, "callgrind.out")
    subprocess.run(["valgrind", "--tool=callgrind", "--cache-sim=yes", "--branch-sim=yes",
                    "--collect-atstart=no", f"--toggle-collect={function}",
                    f"--callgrind-out-file={out}", *command],
                   check=True, capture_output=True, text=True)
    with open(out) as f:
        text = f.read()
    names = re.search(r"^events:\s*(.*)$", text, re.M).group(1).split()
    totals = re.search(r"^(?:summary|totals):\s*(.*)$", text, re.M).group(1).split()
    counts = dict(zip(names, (int(v) for v in totals)))
    return {e: counts.get(e, 0) for e in EVENTS}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", nargs="*", default=[os.path.join(SHARED, "bunny.ply"),
                                                     os.path.join(SHARED, "dragon_res2.ply")])
    ap.add_argument("--canopy", default=os.path.join(ROOT, "target", "release", "examples",
                                                     "kernel_profile"))
    ap.add_argument("--primary", type=int, default=256, help="primary rays: size x size")
    ap.add_argument("--incoherent", type=int, default=20_000)
    ap.add_argument("--runs", type=int, default=5, help="native passes (best is kept)")
    ap.add_argument("--no-valgrind", action="store_true", help="native times and counts only")
    ap.add_argument("--keep", metavar="DIR",
                    help="write the mesh, ray files and Embree's profiler into DIR and keep them "
                         "(for walk_profile, canopy-bvh's example, and repeated counts)")
    args = ap.parse_args()
    rng = np.random.default_rng(7)
    print(f"CPU: {cpu_model()}; one thread; instruction and miss counts from callgrind "
          "(AVX2 kernels), times native (best kernels)\n")
    print("| mesh | rays | query | kernel | ns/ray | instructions/ray | L1d misses/ray "
          "| LL misses/ray | mispredicted branches/ray | node visits/ray | primitive tests/ray |")
    print("|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory(prefix="canopy-profile-") as temporary:
        scratch = args.keep or temporary
        os.makedirs(scratch, exist_ok=True)
        embree = compile_embree(scratch)
        for mesh in args.meshes:
            verts, faces = read_ply(mesh)
            name = os.path.splitext(os.path.basename(mesh))[0] + f"-{len(faces) // 1000}k"
            mesh_file = os.path.join(scratch, f"{name}.bin")
            write_mesh(mesh_file, verts, faces)
            po, pd = primary_rays(verts, args.primary)
            scene = rtcs.EmbreeScene()
            TriangleMesh(scene, verts[faces])
            io, idir = incoherent_rays(po, pd, scene.run(po, pd, output=1), args.incoherent, rng)
            order = origin_order(io)
            ray_sets = {"primary": (po, pd), "incoherent": (io[order], idir[order])}
            for kind, (o, d) in ray_sets.items():
                ray_file = os.path.join(scratch, f"{name}-{kind}.bin")
                write_rays(ray_file, o, d)
                for query in ("closest", "occluded"):
                    canopy = [args.canopy, mesh_file, ray_file, query]
                    # Each side: its command, what follows the pass count, the function counted.
                    sides = {
                        "canopy": (canopy, [], "*profiled_*"),
                        "canopy fast": (canopy, ["--fast"], "*profiled_*"),
                        "Embree": ([embree, mesh_file, ray_file, query, "0"], [], "trace_range"),
                        "Embree robust": ([embree, mesh_file, ray_file, query, "1"], [], "trace_range"),
                    }
                    for side, (command, flags, function) in sides.items():
                        line = subprocess.run(command + [str(args.runs)] + flags, check=True,
                                              capture_output=True, text=True).stdout
                        native = parse_line(line)
                        cells = [f"{native['ns_per_ray']:.1f}"]
                        if args.no_valgrind:
                            cells += ["", "", "", ""]
                        else:
                            quiet = command + ["1"] + flags
                            quiet += ["--no-stats"] if side.startswith("canopy") else []
                            ev = callgrind(quiet, function, scratch)
                            n = len(o)
                            cells += [f"{ev['Ir'] / n:.0f}", f"{(ev['D1mr'] + ev['D1mw']) / n:.2f}",
                                      f"{(ev['ILmr'] + ev['DLmr'] + ev['DLmw']) / n:.2f}",
                                      f"{(ev['Bcm'] + ev['Bim']) / n:.2f}"]
                        cells += [f"{native['visits_per_ray']:.1f}", f"{native['tests_per_ray']:.1f}"] \
                            if "visits_per_ray" in native else ["", ""]
                        print(f"| {name} | {kind} ({len(o)}) | {query} | {side} | " + " | ".join(cells) + " |",
                              flush=True)


if __name__ == "__main__":
    main()
