"""canopy against Mitsuba 3 (llvm_ad_rgb) on the same scene, in one process.

The canopy scene is exported to a Mitsuba scene dict (spheres, cuboids and triangles,
the materials, the sky or a constant background), both render it at the same size, spp,
depth and thread count in turns (best of N each), and the script prints

    ratio <scene> <threads>: X.XX            canopy's speed over Mitsuba's at equal spp
    ratio-equal-error <scene> <threads>: X.XX  the same at equal noise

Each renderer draws its random numbers with its own default unless told: canopy's
scrambled Sobol points (`--sampler`), Mitsuba's independent sampler (`--mitsuba-sampler`;
`ldsampler` is its low-discrepancy counterpart to canopy's).

Noise is measured, not guessed: each renderer renders twice with two seeds, and a pixel's
standard deviation is |a - b| / sqrt(2) (RMS over the image). At equal noise a renderer
needs spp proportional to its variance, so the equal-error ratio is the equal-spp ratio
times (sigma_mitsuba / sigma_canopy)^2.

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
                  sampler: str = "independent") -> dict:
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
        "sampler": {"type": sampler},
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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="*", default=["paper-1"])
    # The bench scenes read meshes beside the repository (the lit dragon): allowed here.
    shared = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "assets")
    parser.add_argument("--allow-path", action="append",
                        default=[shared] if os.path.isdir(shared) else [],
                        help="a folder the scenes may read files from, beside their own")
    parser.add_argument("--spp", type=int, default=128)
    parser.add_argument("--size", default="480x480")
    parser.add_argument("--depth", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--turns", type=int, default=3, help="best of this many, each side")
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--schedule", default=None, help="canopy's schedule: wavefront or depth")
    parser.add_argument("--images", help="write both mean images here as EXR")
    parser.add_argument("--sampler", default=None, help="canopy's sampler: sobol or independent")
    parser.add_argument("--mitsuba-sampler", default="independent",
                        help="Mitsuba's sampler: independent, ldsampler, multijitter, ...")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))

    import mitsuba as mi
    import drjit as dr
    mi.set_variant(args.variant)
    dr.set_thread_count(args.threads)
    print(f"mitsuba {mi.__version__} ({args.variant}), canopy {canopy.__version__}; "
          f"{width}x{height}, {args.spp} spp, depth {args.depth}, {args.threads} threads; "
          f"samplers: canopy {args.sampler or 'the scene default'}, mitsuba {args.mitsuba_sampler}")

    for name in args.scenes:
        info = canopy.load_scene(name, allow_paths=args.allow_path)
        with tempfile.TemporaryDirectory() as workdir:
            scene = mi.load_dict(mitsuba_scene(mi, info, width, height, args.depth, workdir,
                                               args.mitsuba_sampler))

            def run_mitsuba(seed: int) -> np.ndarray:
                image = mi.render(scene, spp=args.spp, seed=seed)
                return np.array(image, dtype=np.float32)[:, :, :3]

            def run_canopy(seed: int) -> np.ndarray:
                options = dict(spp=args.spp, size=(width, height), max_depth=args.depth,
                               seed=seed, threads=args.threads)
                if args.schedule:
                    options["schedule"] = args.schedule
                if args.sampler:
                    options["sampler"] = args.sampler
                return canopy.render(name, allow_paths=args.allow_path, **options)

            times = {"canopy": [], "mitsuba": []}
            images = {"canopy": [], "mitsuba": []}
            for turn in range(args.turns):
                for side, run in (("mitsuba", run_mitsuba), ("canopy", run_canopy)):
                    start = time.perf_counter()
                    image = run(turn % 2)
                    times[side].append(time.perf_counter() - start)
                    if turn < 2:
                        images[side].append(image)
            if args.turns < 2:
                for side, run in (("mitsuba", run_mitsuba), ("canopy", run_canopy)):
                    images[side].append(run(1))
        best = {side: min(t) for side, t in times.items()}
        noise = {side: sigma(*images[side]) for side in images}
        means = {side: 0.5 * (images[side][0] + images[side][1]) for side in images}
        pixel_sigma = {side: np.abs(images[side][0] - images[side][1]) / math.sqrt(2)
                       for side in images}
        agree = tiles_agree(means["canopy"], means["mitsuba"],
                            pixel_sigma["canopy"] / math.sqrt(2), pixel_sigma["mitsuba"] / math.sqrt(2))
        lum = {side: float(means[side].mean()) for side in means}
        speed = best["mitsuba"] / best["canopy"]
        equal_error = speed * (noise["mitsuba"] / noise["canopy"]) ** 2
        print(f"{name}: canopy {best['canopy']:.2f} s (sigma {noise['canopy']:.4f}), "
              f"mitsuba {best['mitsuba']:.2f} s (sigma {noise['mitsuba']:.4f}); "
              f"mean {lum['canopy']:.4f} vs {lum['mitsuba']:.4f}, "
              f"{100 * agree:.0f}% of 32x32 tiles agree within noise")
        print(f"ratio {name} {args.threads}: {speed:.2f}")
        print(f"ratio-equal-error {name} {args.threads}: {equal_error:.2f}")
        if args.images:
            os.makedirs(args.images, exist_ok=True)
            for side in means:
                canopy.write_image(os.path.join(args.images, f"{name}-{side}.exr"), means[side])
    return 0


if __name__ == "__main__":
    sys.exit(main())
