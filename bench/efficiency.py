"""Efficiency of canopy's estimators on a scene: time and noise of renders with two seeds,
and 1 / (sigma^2 t) (higher is better: the inverse of the time to a given error).

    bench/.venv/bin/python bench/efficiency.py paper-1 paper-3 [--size 240x240 --spp 32 --depth 5]

(after any bench/*.sh has made bench/.venv with canopy's wheel). Noise is the RMS over the
image of |a - b| / sqrt(2) for renders a, b with seeds 0 and 1; time is the faster of the
two.
"""

import argparse
import time

import numpy as np

import canopy_rt as canopy

VARIANTS = [
    ("path", {}),
    ("path, independent", {"sampler": "independent"}),
    ("path, no roulette", {"russian_roulette": False}),
    ("bsdf", {"integrator": "bsdf"}),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="*", default=["paper-1", "paper-3"])
    parser.add_argument("--size", default="240x240")
    parser.add_argument("--spp", type=int, default=32)
    parser.add_argument("--depth", type=int, help="default: the scene's")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.lower().split("x"))
    for scene in args.scenes:
        for label, options in VARIANTS:
            images, seconds = [], []
            for seed in (0, 1):
                start = time.perf_counter()
                images.append(canopy.render(scene, size=size, spp=args.spp, max_depth=args.depth,
                                            seed=seed, threads=args.threads, **options))
                seconds.append(time.perf_counter() - start)
            sigma = float(np.sqrt(np.mean((images[0] - images[1]) ** 2) / 2))
            t = min(seconds)
            print(f"{scene:12s} {label:18s} {t:6.2f} s  sigma {sigma:.4f}  "
                  f"efficiency {1 / (sigma * sigma * t):10.0f}  mean {images[0].mean():.4f}")


if __name__ == "__main__":
    main()
