"""canopy against Mitsuba 3 (llvm_ad_rgb) on the same scene, in one process.

The canopy scene is exported to a Mitsuba scene dict (spheres, cuboids and triangles,
the materials, the sky or a constant background), both render it at the same size,
depth and thread count in turns (best of N each), and the script prints

    ratio <scene> <threads>: X.XX            canopy's speed over Mitsuba's at equal spp
    ratio-equal-error <scene> <threads>: X.XX  the same at equal noise, against the
                                               Mitsuba sampler that is best on the scene

A user who compares renderers gives each its best sampler, and the best one depends on
the scene. So Mitsuba renders with each of its samplers (`--mitsuba-samplers`, default
independent, stratified, multijitter, orthogonal and ldsampler), each at the sample count
nearest to `--spp` that it takes exactly (orthogonal takes squares of primes, stratified
and ldsampler squares and powers of two: 64 and 256 suit all but orthogonal). canopy
renders with its scene's sampler (scrambled Sobol points unless the scene says) or
`--sampler`.

Noise is measured, not guessed: each renderer renders twice with two seeds, and a pixel's
standard deviation is |a - b| / sqrt(2) (RMS over the image). A renderer's efficiency is
1 / (sigma^2 t): at equal noise a renderer needs time in proportion to sigma^2 t, so the
equal-error ratio is (sigma_mitsuba^2 t_mitsuba) / (sigma_canopy^2 t_canopy), valid
across sample counts (for low-discrepancy points, whose error falls faster than 1/spp,
the one with more samples is slightly favoured). The equal-spp ratio compares times with
the fastest Mitsuba sampler that takes exactly canopy's spp.

The mean images must agree within noise (tile by tile); where the two models differ the
mapping is stated: canopy's fuzzed metal (a sphere of radius `fuzz` about the mirror
direction) becomes a GGX rough conductor of alpha = fuzz / 2, and canopy's dielectric
uses Schlick's Fresnel where Mitsuba's is exact, so those tiles may differ slightly.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time

import numpy as np

import canopy_rt as canopy


def sky_bitmap(width: int = 64, height: int = 256) -> np.ndarray:
    """canopy's sky (white at the horizon to light blue overhead, a function of the
    direction's y only) as a latitude-longitude map, row 0 straight up."""
    theta = (np.arange(height) + 0.5) / height * np.pi
    a = 0.5 * (np.cos(theta) + 1.0)
    row = (1.0 - a)[:, None] * np.ones(3) + a[:, None] * np.array([0.5, 0.7, 1.0])
    return np.ascontiguousarray(np.repeat(row[:, None, :], width, axis=1), dtype=np.float32)


def cuboid_triangles(lo, hi, rotation, translation) -> np.ndarray:
    """The 12 triangles of a box (local corners, turned and moved), outward wound.

    A flat box (a quad light) is seen from both sides in canopy; Mitsuba's area lights
    emit on their front only, and its two coincident faces would shadow each other, so
    each flat side is moved out by a hair (1e-5 of the box's size): a ray from either
    side then meets the face that looks its way."""
    lo, hi = np.array(lo, np.float64), np.array(hi, np.float64)
    hair = 1e-5 * max(float(np.max(hi - lo)), 1.0)
    flat = hi - lo <= 0
    lo, hi = np.where(flat, lo - hair, lo), np.where(flat, hi + hair, hi)
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    c = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], np.float32)
    c = c @ np.asarray(rotation, np.float32).T + np.asarray(translation, np.float32)
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5), (0, 4, 7, 3)]
    tris = []
    for a, b, cc, d in quads:
        tris += [(a, b, cc), (a, cc, d)]
    return c[np.array(tris)]


def write_ply(path: str, vertices: np.ndarray, normals: np.ndarray | None) -> None:
    """Triangles (n, 3, 3) as a binary PLY, three unshared corners each."""
    n = len(vertices)
    v = vertices.reshape(-1, 3).astype("<f4")
    props = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else [])
    data = v if normals is None else np.hstack([v, normals.reshape(-1, 3).astype("<f4")])
    faces = np.empty(n, dtype=[("k", "u1"), ("i", "<i4", 3)])
    faces["k"] = 3
    faces["i"] = np.arange(3 * n, dtype="<i4").reshape(n, 3)
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {3 * n}"]
    header += [f"property float {p}" for p in props]
    header += [f"element face {n}", "property list uchar int vertex_indices", "end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode())
        f.write(np.ascontiguousarray(data, "<f4").tobytes())
        f.write(faces.tobytes())


def bsdf(material: dict) -> dict:
    kind = material["type"]
    rgb = lambda c: {"type": "rgb", "value": [float(x) for x in c]}
    if kind == "lambertian":
        return {"type": "diffuse", "reflectance": rgb(material["albedo"])}
    if kind == "metal":
        if material["fuzz"] == 0:
            return {"type": "conductor", "material": "none",
                    "specular_reflectance": rgb(material["albedo"])}
        return {"type": "roughconductor", "material": "none", "distribution": "ggx",
                "alpha": max(0.5 * material["fuzz"], 1e-3),
                "specular_reflectance": rgb(material["albedo"])}
    if kind == "dielectric":
        return {"type": "dielectric", "int_ior": float(material["ior"]), "ext_ior": 1.0}
    if kind == "pbr":
        return {"type": "principled", "base_color": rgb(material["base_color"]),
                "metallic": float(material["metallic"]), "roughness": float(material["roughness"]),
                "specular": 0.5}
    if kind == "emissive":
        return {"type": "diffuse", "reflectance": rgb([0, 0, 0])}
    raise ValueError(f"no Mitsuba BSDF for a {kind} material")


def mitsuba_scene(mi, info, width: int, height: int, depth: int, workdir: str,
                  sampler: str = "independent", spp: int = 64) -> dict:
    """The Mitsuba scene dict of a canopy scene."""
    contents = info.contents()
    if contents["punctual_lights"] or contents["textured_materials"]:
        raise ValueError("the exporter takes no punctual lights or textures yet")
    materials = contents["materials"]
    cam = contents["camera"]
    look_from, look_at = np.array(cam["look_from"]), np.array(cam["look_at"])
    sensor = {
        "type": "perspective", "fov": float(cam["vfov"]), "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(origin=cam["look_from"], target=cam["look_at"],
                                                   up=cam["up"]),
        "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"},
                 "pixel_format": "rgb"},
        "sampler": {"type": sampler, "sample_count": spp},
    }
    if cam["aperture"] > 0:
        sensor["type"] = "thinlens"
        sensor["aperture_radius"] = 0.5 * float(cam["aperture"])
        focus = cam["focus_distance"] or float(np.linalg.norm(look_at - look_from))
        sensor["focus_distance"] = float(focus)
    scene = {"type": "scene", "integrator": {"type": "path", "max_depth": depth, "rr_depth": 3},
             "sensor": sensor}
    background = contents["background"]
    if background["type"] == "sky":
        scene["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(sky_bitmap())}
    elif background["type"] == "constant":
        if any(background["radiance"]):
            scene["sky"] = {"type": "constant",
                            "radiance": {"type": "rgb", "value": background["radiance"]}}
    else:
        raise ValueError("the exporter takes the sky or a constant background, not a map")

    def with_material(shape: dict, index: int) -> dict:
        m = materials[index]
        shape["bsdf"] = bsdf(m)
        if m["type"] == "emissive":
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": m["radiance"]}}
        return shape

    spheres = contents["spheres"]
    for i, (c, r, m) in enumerate(zip(spheres["centers"], spheres["radii"], spheres["materials"])):
        scene[f"sphere{i}"] = with_material(
            {"type": "sphere", "center": [float(v) for v in c], "radius": float(r)}, int(m))

    tris = contents["triangles"]
    vertices, normals, smooth, tri_materials = (tris["vertices"], tris["normals"], tris["smooth"],
                                                tris["materials"])
    boxes = contents["cuboids"]
    for lo, hi, rot, t, m in zip(boxes["min"], boxes["max"], boxes["rotation"],
                                 boxes["translation"], boxes["materials"]):
        box = cuboid_triangles(lo, hi, rot, t)
        vertices = np.concatenate([vertices, box])
        normals = np.concatenate([normals, np.zeros_like(box)])
        smooth = np.concatenate([smooth, np.zeros(12, bool)])
        tri_materials = np.concatenate([tri_materials, np.full(12, m, tri_materials.dtype)])
    for m in np.unique(tri_materials):
        for is_smooth in (False, True):
            pick = (tri_materials == m) & (smooth == is_smooth)
            if not pick.any():
                continue
            path = os.path.join(workdir, f"mesh-{m}-{int(is_smooth)}.ply")
            write_ply(path, vertices[pick], normals[pick] if is_smooth else None)
            scene[f"mesh{m}_{int(is_smooth)}"] = with_material(
                {"type": "ply", "filename": path, "face_normals": not is_smooth}, int(m))
    return scene


def sigma(a: np.ndarray, b: np.ndarray) -> float:
    """RMS over the image of the per-pixel standard deviation of one render, from two
    renders with different seeds."""
    return float(np.sqrt(np.mean((a - b) ** 2) / 2.0))


def tiles_agree(a, b, sa, sb, tile: int = 32) -> float:
    """Share of tiles whose mean colour differs by less than 4 standard errors, each
    tile's error from the two renders' noise (per-pixel sigma maps)."""
    h, w, _ = a.shape
    good = total = 0
    for y in range(0, h - tile + 1, tile):
        for x in range(0, w - tile + 1, tile):
            s = np.s_[y:y + tile, x:x + tile]
            diff = np.abs(a[s].mean(axis=(0, 1)) - b[s].mean(axis=(0, 1)))
            err = np.sqrt((sa[s] ** 2).mean(axis=(0, 1)) + (sb[s] ** 2).mean(axis=(0, 1))) / tile
            good += bool(np.all(diff <= 4 * err + 1e-3))
            total += 1
    return good / max(total, 1)


def accepted_spp(mi, sampler: str, wanted: int) -> int:
    """The sample count nearest to `wanted` that Mitsuba's `sampler` takes as it is (the
    samplers round other counts up, some to squares of primes)."""
    def taken(n: int) -> int:
        return mi.load_dict({"type": sampler, "sample_count": n}).sample_count()

    level = mi.log_level()
    mi.set_log_level(mi.LogLevel.Error)  # each rounding logs a warning
    try:
        up = taken(wanted)
        down = next((n for n in range(wanted, max(wanted // 2, 1) - 1, -1) if taken(n) == n), None)
    finally:
        mi.set_log_level(level)
    if down is None or up - wanted < wanted - down:
        return up
    return down


def efficiency_ratio(canopy_run: dict, mitsuba_run: dict) -> float:
    """canopy's speed over Mitsuba's at equal noise: (sigma^2 t) of Mitsuba's over canopy's."""
    return (mitsuba_run["sigma"] ** 2 * mitsuba_run["time"]) / (
        canopy_run["sigma"] ** 2 * canopy_run["time"])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="*", default=["paper-1"])
    # The bench scenes read meshes beside the repository (the lit dragon): allowed here.
    shared = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "assets")
    parser.add_argument("--allow-path", action="append",
                        default=[shared] if os.path.isdir(shared) else [],
                        help="a folder the scenes may read files from, beside their own")
    parser.add_argument("--spp", type=int, default=64,
                        help="canopy's spp; each Mitsuba sampler takes the nearest it accepts")
    parser.add_argument("--size", default="480x480")
    parser.add_argument("--depth", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--turns", type=int, default=3, help="best of this many, each side")
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--schedule", default=None, help="canopy's schedule: wavefront or depth")
    parser.add_argument("--images", help="write both mean images here as EXR")
    parser.add_argument("--sampler", default=None, help="canopy's sampler: sobol or independent")
    parser.add_argument("--mitsuba-samplers", nargs="+",
                        default=["independent", "stratified", "multijitter", "orthogonal",
                                 "ldsampler"],
                        help="Mitsuba's samplers to try; the best on each scene is compared")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))

    import mitsuba as mi
    import drjit as dr
    mi.set_variant(args.variant)
    dr.set_thread_count(args.threads)
    sampler_spp = {s: accepted_spp(mi, s, args.spp) for s in args.mitsuba_samplers}
    print(f"mitsuba {mi.__version__} ({args.variant}), canopy {canopy.__version__}; "
          f"{width}x{height}, depth {args.depth}, {args.threads} threads; canopy "
          f"{args.spp} spp with {args.sampler or 'the scene sampler (sobol unless it says)'}; "
          "mitsuba " + ", ".join(f"{s} {n} spp" for s, n in sampler_spp.items()))

    for name in args.scenes:
        info = canopy.load_scene(name, allow_paths=args.allow_path)
        with tempfile.TemporaryDirectory() as workdir:
            def mitsuba_runner(sampler: str):
                spp = sampler_spp[sampler]
                scene = mi.load_dict(mitsuba_scene(mi, info, width, height, args.depth, workdir,
                                                   sampler, spp))

                def run(seed: int) -> np.ndarray:
                    image = mi.render(scene, spp=spp, seed=seed)
                    return np.array(image, dtype=np.float32)[:, :, :3]
                return run

            def run_canopy(seed: int) -> np.ndarray:
                options = dict(spp=args.spp, size=(width, height), max_depth=args.depth,
                               seed=seed, threads=args.threads)
                if args.schedule:
                    options["schedule"] = args.schedule
                if args.sampler:
                    options["sampler"] = args.sampler
                return canopy.render(name, allow_paths=args.allow_path, **options)

            runners = {f"mitsuba {s}": mitsuba_runner(s) for s in args.mitsuba_samplers}
            runners["canopy"] = run_canopy
            times = {side: [] for side in runners}
            images = {side: [] for side in runners}
            for turn in range(max(args.turns, 2)):
                for side, run in runners.items():
                    if turn >= args.turns and len(images[side]) >= 2:
                        continue
                    start = time.perf_counter()
                    image = run(turn % 2)
                    times[side].append(time.perf_counter() - start)
                    if turn < 2:
                        images[side].append(image)
        runs = {side: {"time": min(times[side]), "sigma": sigma(*images[side]),
                       "mean": 0.5 * (images[side][0] + images[side][1]),
                       "pixel_sigma": np.abs(images[side][0] - images[side][1]) / math.sqrt(2)}
                for side in runners}
        ours = runs["canopy"]
        print(f"{name}: canopy {ours['time']:.2f} s (sigma {ours['sigma']:.4f}, "
              f"mean {float(ours['mean'].mean()):.4f})")
        for s in args.mitsuba_samplers:
            theirs = runs[f"mitsuba {s}"]
            print(f"  mitsuba {s:<12} {sampler_spp[s]:>4} spp {theirs['time']:7.2f} s "
                  f"(sigma {theirs['sigma']:.4f}, mean {float(theirs['mean'].mean()):.4f}): "
                  f"canopy {efficiency_ratio(ours, theirs):.2f}x at equal error")
        best = max(args.mitsuba_samplers,
                   key=lambda s: 1.0 / (runs[f"mitsuba {s}"]["sigma"] ** 2
                                        * runs[f"mitsuba {s}"]["time"]))
        exact = [s for s in args.mitsuba_samplers if sampler_spp[s] == args.spp]
        theirs = runs[f"mitsuba {best}"]
        agree = tiles_agree(ours["mean"], theirs["mean"], ours["pixel_sigma"] / math.sqrt(2),
                            theirs["pixel_sigma"] / math.sqrt(2))
        print(f"  against mitsuba {best}: {100 * agree:.0f}% of 32x32 tiles agree within noise")
        if exact:
            fastest = min(exact, key=lambda s: runs[f"mitsuba {s}"]["time"])
            speed = runs[f"mitsuba {fastest}"]["time"] / ours["time"]
            print(f"ratio {name} {args.threads}: {speed:.2f} (mitsuba {fastest}, {args.spp} spp)")
        print(f"ratio-equal-error {name} {args.threads}: {efficiency_ratio(ours, theirs):.2f} "
              f"(mitsuba {best}, its best sampler here)")
        if args.images:
            os.makedirs(args.images, exist_ok=True)
            canopy.write_image(os.path.join(args.images, f"{name}-canopy.exr"), ours["mean"])
            canopy.write_image(os.path.join(args.images, f"{name}-mitsuba-{best}.exr"),
                               theirs["mean"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
