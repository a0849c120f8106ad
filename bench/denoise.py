"""Denoising at equal time: for each scene and sample count, the error of the noisy render
and of its denoised image against a high-spp reference (relative MSE and HDR FLIP), the
undenoised render given the denoiser's time as extra samples, and the sample count the
undenoised render would need to reach the denoised error. Also the denoiser's own time per
megapixel on a one-megapixel image.

Run through bench/denoise.sh (it installs flip-evaluator, canopy's wheel and OIDN).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

import canopy_rt as canopy

ROOT = Path(__file__).resolve().parents[1]
SCENES = {
    "cornell": "cornell",
    "paper-3": "paper-3",
    "duck (glTF)": str(ROOT / "scenes" / "gltf" / "Duck.glb"),
}


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def relative_mse(image: np.ndarray, reference: np.ndarray) -> float:
    return float(np.mean((image - reference) ** 2 / (reference**2 + 1e-2)))


def flip(image: np.ndarray, reference: np.ndarray) -> float:
    import flip_evaluator

    _, mean, _ = flip_evaluator.evaluate(
        np.ascontiguousarray(reference, np.float32),
        np.ascontiguousarray(np.maximum(image, 0), np.float32),
        "HDR",
        applyMagma=False,
    )
    return float(mean)


def reference(scene: str, label: str, size, spp: int, cache: Path) -> np.ndarray:
    """The scene at `spp`, rendered once and kept (the slow part of the benchmark)."""
    path = cache / f"{label.split()[0]}-{size[0]}x{size[1]}-{spp}.exr"
    if path.exists():
        return canopy.read_image(path)
    start = time.perf_counter()
    image = canopy.render(scene, size=size, spp=spp, seed=7)
    print(f"  reference {label}: {spp} spp in {time.perf_counter() - start:.0f} s", flush=True)
    canopy.write_image(path, image)
    return image


def samples_to_match(scene, size, spp: int, target: float, ref: np.ndarray, noisy_error: float) -> str:
    """The samples per pixel an undenoised render needs for the error `target`: renders
    at twice, four times ... `spp` until one is at or below it, then interpolated in
    log-log between the two around it. "<= spp" where `spp` already does."""
    if noisy_error <= target:
        return f"<= {spp}"
    low, low_error = spp, noisy_error
    high = spp * 2
    while high <= 1 << 16:
        error = relative_mse(canopy.render(scene, size=size, spp=high), ref)
        if error <= target:
            t = (np.log(low_error) - np.log(target)) / (np.log(low_error) - np.log(error))
            return str(round(float(np.exp(np.log(low) + t * (np.log(high) - np.log(low))))))
        low, low_error, high = high, error, high * 2
    return f"> {1 << 16}"


def timed(function):
    start = time.perf_counter()
    result = function()
    return result, time.perf_counter() - start


def best_of(runs: int, function):
    """The result and the shortest time of `runs` calls (the machine is shared)."""
    results = [timed(function) for _ in range(runs)]
    return results[0][0], min(t for _, t in results)


def denoiser_time_per_megapixel(runs: int) -> dict:
    """Seconds per megapixel of the denoiser alone, on a 1024x1024 noisy image with
    albedo and normal, with and without prefiltering the guides."""
    noisy, aovs = canopy.render("cornell", size=(128, 128), spp=4, aovs=["albedo", "normal"])
    grow = lambda a: np.ascontiguousarray(np.tile(a, (8, 8, 1)))
    noisy, albedo, normal = grow(noisy), grow(aovs["albedo"]), grow(aovs["normal"])
    megapixels = noisy.shape[0] * noisy.shape[1] / 1e6
    times = {}
    for prefilter in (True, False):
        _, seconds = best_of(runs, lambda: canopy.denoise(noisy, albedo, normal, prefilter=prefilter))
        times["prefiltered guides" if prefilter else "raw guides"] = seconds / megapixels
    color_only = lambda: canopy.denoise(noisy)
    times["colour only"] = best_of(runs, color_only)[1] / megapixels
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--size", default="128x128", help="image size, WIDTHxHEIGHT")
    parser.add_argument("--reference-spp", type=int, default=16384)
    parser.add_argument("--spp", default="4,16,64", help="sample counts to denoise")
    parser.add_argument("--runs", type=int, default=3, help="timings are the best of this many")
    parser.add_argument("--out", default=str(ROOT / "target" / "bench-denoise"))
    parser.add_argument("--prefilter-guides", action="store_true",
                        help="denoise the albedo and normal first (OIDN's cleanAux mode)")
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    counts = [int(v) for v in args.spp.split(",")]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    threads = os.cpu_count()
    print(f"CPU: {cpu_model()}, {threads} threads; {size[0]}x{size[1]}, reference {args.reference_spp} spp")

    rows = []
    for label, scene in SCENES.items():
        ref = reference(scene, label, size, args.reference_spp, out)
        for spp in counts:
            (noisy, aovs), render_s = best_of(
                args.runs, lambda: canopy.render(scene, size=size, spp=spp, aovs=["albedo", "normal"])
            )
            plain_s = best_of(args.runs, lambda: canopy.render(scene, size=size, spp=spp))[1]
            clean, denoise_s = best_of(
                args.runs,
                lambda: canopy.denoise(noisy, aovs["albedo"], aovs["normal"], prefilter=args.prefilter_guides),
            )
            # Equal time: the undenoised render gets the AOVs' and the denoiser's time as
            # samples.
            equal_spp = max(spp, round(spp * (render_s + denoise_s) / plain_s))
            equal = canopy.render(scene, size=size, spp=equal_spp)
            noisy_err, clean_err = relative_mse(noisy, ref), relative_mse(clean, ref)
            row = {
                "scene": label,
                "spp": spp,
                "noisy_relmse": noisy_err,
                "denoised_relmse": clean_err,
                "noisy_flip": flip(noisy, ref),
                "denoised_flip": flip(clean, ref),
                "equal_time_spp": equal_spp,
                "equal_time_relmse": relative_mse(equal, ref),
                "equal_time_flip": flip(equal, ref),
                "spp_to_match_denoised": samples_to_match(scene, size, spp, clean_err, ref, noisy_err),
                "render_s": render_s,
                "render_without_aovs_s": plain_s,
                "denoise_s": denoise_s,
            }
            rows.append(row)
            print(
                f"  {label:12} {spp:3} spp: relMSE {noisy_err:.5f} -> {clean_err:.5f} denoised, "
                f"{row['equal_time_relmse']:.5f} at equal time ({equal_spp} spp); FLIP "
                f"{row['noisy_flip']:.4f} -> {row['denoised_flip']:.4f}; "
                f"{row['spp_to_match_denoised']} spp to match",
                flush=True,
            )
    per_mp = denoiser_time_per_megapixel(args.runs)

    print()
    guides = "prefiltered" if args.prefilter_guides else "raw"
    print(f"CPU: {cpu_model()}, {threads} threads. {size[0]}x{size[1]} pixels, reference {args.reference_spp} spp, "
          f"{guides} guides.")
    print()
    print("| scene | spp | relMSE noisy | denoised | undenoised at equal time (spp) | FLIP noisy | denoised "
          "| at equal time | spp an undenoised render needs for the denoised relMSE |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['scene']} | {r['spp']} | {r['noisy_relmse']:.5f} | {r['denoised_relmse']:.5f} "
            f"| {r['equal_time_relmse']:.5f} ({r['equal_time_spp']}) | {r['noisy_flip']:.4f} "
            f"| {r['denoised_flip']:.4f} | {r['equal_time_flip']:.4f} | {r['spp_to_match_denoised']} |"
        )
    print()
    print("Denoiser time per megapixel (1024x1024, albedo and normal): "
          + ", ".join(f"{k} {v:.2f} s" for k, v in per_mp.items()))
    record = {"cpu": cpu_model(), "threads": threads, "prefiltered_guides": args.prefilter_guides,
              "size": size, "reference_spp": args.reference_spp,
              "rows": rows, "denoise_seconds_per_megapixel": per_mp}
    results = out / ("results-prefiltered-guides.json" if args.prefilter_guides else "results.json")
    results.write_text(json.dumps(record, indent=2))
    print(f"results: {results}")


if __name__ == "__main__":
    main()
