"""canopy's glTF metallic-roughness BRDF against Mitsuba 3's, evaluated independently.

Mitsuba 3 (``scalar_rgb``) evaluates two BSDFs whose metal lobe is the same model:
- ``roughconductor`` with ``material = "none"`` (Fresnel 1): GGX's D and masking, and the
  visible-normal sampling density, against canopy's white metal;
- ``principled`` with ``metallic = 1``: also Schlick's Fresnel of the base colour.

Mitsuba's masking-shadowing is Smith's separable G1(wo)·G1(wi); canopy's is the
height-correlated G2 the glTF specification asks for. Values are compared after scaling
Mitsuba's by G2 / (G1·G1) (closed forms of Smith's Λ, here in numpy); densities need no
correction (both are D_wo(h) / (4 wo·h)). The dielectric half (metallic < 1) is not
compared: Mitsuba's principled BSDF has Disney's diffuse and an exact dielectric Fresnel
term where glTF has Lambert and Schlick.

Directions: half of the pairs uniform over the upper hemisphere, half drawn by Mitsuba's
own sampling (where the lobe is). Prints the worst relative error of values above 1e-3 of
the lobe's peak and of densities, per model and roughness.
"""

import argparse
import sys

import numpy as np
import mitsuba as mi

import canopy_rt as canopy

mi.set_variant("scalar_rgb")


def hemisphere(rng, n):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    return v[v[:, 2] > 0.02][: n]


def lam(alpha, w):
    cos2 = w[:, 2] ** 2
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * (1.0 - cos2) / cos2) - 1.0)


def pairs_and_mitsuba(bsdf, rng, n):
    ctx = mi.BSDFContext()
    wo_all, wi_all, values, pdfs = [], [], [], []
    wos = hemisphere(rng, 4 * n)
    k = 0
    while len(wo_all) < n:
        wo = wos[k]
        k += 1
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*wo)
        if k % 2 == 0:
            wi = hemisphere(rng, 4)[0]
        else:
            sample, _ = bsdf.sample(ctx, si, rng.random(), mi.Point2f(rng.random(), rng.random()))
            wi = np.array(sample.wo)
            if wi[2] <= 1e-3:
                continue
        wi = wi / np.linalg.norm(wi)
        wo_all.append(wo)
        wi_all.append(wi)
        values.append(np.array(bsdf.eval(ctx, si, mi.Vector3f(*wi))))
        pdfs.append(bsdf.pdf(ctx, si, mi.Vector3f(*wi)))
    return np.array(wo_all), np.array(wi_all), np.array(values), np.array(pdfs)


def compare(name, bsdf, material, alpha, rng, n):
    wo, wi, m_value, m_pdf = pairs_and_mitsuba(bsdf, rng, n)
    masking = (1 + lam(alpha, wo)) * (1 + lam(alpha, wi)) / (1 + lam(alpha, wo) + lam(alpha, wi))
    expected = m_value * masking[:, None]
    c_value, c_pdf = canopy.eval_material(material, wo, wi)
    peak = expected.max()
    big = expected > 1e-3 * peak
    value_error = np.abs(c_value - expected)[big] / expected[big]
    pdf_big = m_pdf > 1e-3 * m_pdf.max()
    pdf_error = np.abs(c_pdf - m_pdf)[pdf_big] / m_pdf[pdf_big]
    uncorrected = np.abs(c_value - m_value)[big] / m_value[big]
    print(
        f"{name:<34} pairs {len(wo):>6}  value: worst {value_error.max():.2e} median {np.median(value_error):.1e}"
        f"  pdf: worst {pdf_error.max():.2e}  (masking models differ by up to {uncorrected.max():.1%})"
    )
    return value_error.max(), pdf_error.max(), (wo, wi, m_value, m_pdf)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--pairs", type=int, default=10_000, help="direction pairs per model and roughness")
    parser.add_argument("--tolerance", type=float, default=2e-3, help="largest relative error allowed")
    parser.add_argument("--write-reference", metavar="CSV", help="also keep 24 pairs per case for canopy's Rust test")
    args = parser.parse_args()
    rng = np.random.default_rng(2026)
    worst = 0.0
    rows = []
    base = [0.9, 0.55, 0.12]
    for roughness in [0.1, 0.3, 0.5, 0.75, 1.0]:
        alpha = max(roughness * roughness, 1e-3)
        cases = [
            ("roughconductor", [1.0, 1.0, 1.0], mi.load_dict({"type": "roughconductor", "material": "none", "alpha": alpha, "distribution": "ggx"})),
            ("principled metallic=1", base, mi.load_dict({"type": "principled", "base_color": {"type": "rgb", "value": base}, "metallic": 1.0, "roughness": roughness})),
        ]
        for name, colour, bsdf in cases:
            material = canopy.pbr(colour, metallic=1.0, roughness=roughness)
            v, p, (wo, wi, m_value, m_pdf) = compare(f"{name}, roughness {roughness}", bsdf, material, alpha, rng, args.pairs)
            worst = max(worst, v, p)
            for k in range(24):
                rows.append([roughness, *colour, *wo[k], *wi[k], *m_value[k], m_pdf[k]])
    print(f"worst relative error {worst:.2e} (tolerance {args.tolerance:.0e})")
    if args.write_reference:
        header = "roughness,base_r,base_g,base_b,wo_x,wo_y,wo_z,wi_x,wi_y,wi_z,mitsuba_r,mitsuba_g,mitsuba_b,mitsuba_pdf"
        np.savetxt(args.write_reference, np.array(rows), delimiter=",", header=header, comments="# Mitsuba 3 scalar_rgb (separable masking), from bench/brdf_compare.py\n# ", fmt="%.9g")
    return 0 if worst <= args.tolerance else 1


if __name__ == "__main__":
    sys.exit(main())
