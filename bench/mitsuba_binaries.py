"""canopy binaries against Mitsuba 3 at equal spp, in turns in one run: to weigh a change
to the renderer against Mitsuba without building the release wheel.

    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so \\
    bench/.venv/bin/python bench/mitsuba_binaries.py target/release/canopy /tmp/canopy-before \\
        --scenes bench/scenes/dragon-lit.toml cornell [--spp 64 --depth 5 --threads 2 --turns 2]

(after `bench/mitsuba_render.sh` has made bench/.venv with Mitsuba and a canopy wheel; the
wheel only exports the scene, the binaries render it). Run that script again when the
scene export may have changed: an older wheel's export once doubled Mitsuba's time on
paper-3 (docs/performance.md, "Rerun on 2026-12-06"). Each binary's time is the `render`
line it prints (the scene's loading and tree left out), Mitsuba's that of `mi.render`;
each is the best of the turns, and each binary's speed over Mitsuba's is printed. Mitsuba
renders with `--sampler` (multijitter was its best on every scene of docs/performance.md).
Noise is not compared: `bench/mitsuba_render.sh` measures the equal-error ratio.
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np

import canopy_rt as canopy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from mitsuba_render import mitsuba_scene  # noqa: E402 (the bench folder, put on the path above)

SHARED = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared")


def canopy_seconds(binary: str, scene: str, args: argparse.Namespace) -> float:
    """The render time a `canopy render` run reports."""
    command = [binary, "render", scene, "--size", f"{args.size}x{args.size}", "--spp",
               str(args.spp), "--depth", str(args.depth), "--threads", str(args.threads),
               "-o", os.path.join(args.workdir, "canopy.png")]
    if os.path.isdir(SHARED):
        command += ["--allow-path", SHARED]
    out = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True, check=True).stdout
    match = re.search(r"^render\s+([\d.]+) s", out, re.MULTILINE)
    if not match:
        raise RuntimeError(f"{binary} printed no render time:\n{out}")
    return float(match.group(1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("binaries", nargs="+", help="canopy binaries to time")
    parser.add_argument("--scenes", nargs="+", default=["paper-1"])
    parser.add_argument("--size", type=int, default=480, help="width and height")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--depth", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--turns", type=int, default=2)
    parser.add_argument("--sampler", default="multijitter", help="Mitsuba's sampler")
    args = parser.parse_args()

    import drjit as dr
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    dr.set_thread_count(args.threads)
    print(f"mitsuba {mi.__version__} ({args.sampler}); {args.size}x{args.size}, {args.spp} spp, "
          f"depth {args.depth}, {args.threads} threads, best of {args.turns}")
    allow = [os.path.join(SHARED, "assets")] if os.path.isdir(SHARED) else []
    for name in args.scenes:
        info = canopy.load_scene(name, allow_paths=allow)
        with tempfile.TemporaryDirectory() as workdir:
            args.workdir = workdir
            scene = mi.load_dict(mitsuba_scene(mi, info, args.size, args.size, args.depth,
                                               workdir, args.sampler, args.spp))
            times = {side: [] for side in ["mitsuba", *args.binaries]}
            for turn in range(args.turns):
                start = time.perf_counter()
                np.array(mi.render(scene, spp=args.spp, seed=turn))
                times["mitsuba"].append(time.perf_counter() - start)
                for binary in args.binaries:
                    times[binary].append(canopy_seconds(binary, name, args))
        theirs = min(times["mitsuba"])
        print(f"{name}: mitsuba {theirs:.2f} s")
        for binary in args.binaries:
            ours = min(times[binary])
            print(f"  {binary}: {ours:.2f} s, {theirs / ours:.2f}x Mitsuba's speed")


if __name__ == "__main__":
    main()
