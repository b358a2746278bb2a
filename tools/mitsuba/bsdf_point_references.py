#!/usr/bin/env python3
"""Point references of Mitsuba 3's microfacet BSDFs for src/render/bsdf/tests.rs.

Evaluates Mitsuba's `roughconductor`, `roughplastic` and `roughdielectric` (scalar_rgb
variant, grey constant parameters so every channel is equal) at pairs of local directions near
their lobes, and writes f·cos θo (`eval`) and the sampling pdf (`pdf`) with the plugin's
parameters to tests/references/bsdf_points.json:

    python3 tools/mitsuba/bsdf_point_references.py

Mitsuba's Beckmann G1 is a rational fit of the exact form thinfilm uses (≤ 0.35 % apart), so
the test allows 1 %.

It also writes tests/references/bsdf_spectral_points.json for tests/scene_bsdf_points.rs:
BSDFs given as XML text (RGB `eta`/`k` of conductors, `specular_reflectance` /
`specular_transmittance` ≠ 1), loaded by Mitsuba's `scalar_spectral` variant and evaluated at
four fixed wavelengths, so that the test can load the very same XML into thinfilm and compare
per wavelength — the check of Mitsuba's spectral upsampling of RGB indices (clamped to [0, 1])
and of where the factors apply. tests/references/bsdf_mueller_points.json holds the Mueller
matrices of the polarised cases (`pplastic`) from `scalar_spectral_polarized`, for the same test.
"""

import json
import math
import os

import mitsuba as mi

mi.set_variant("scalar_rgb", "scalar_spectral", "scalar_spectral_polarized")

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "..", "tests", "references", "bsdf_points.json")
OUT_SPECTRAL = os.path.join(HERE, "..", "..", "tests", "references", "bsdf_spectral_points.json")
OUT_MUELLER = os.path.join(HERE, "..", "..", "tests", "references", "bsdf_mueller_points.json")
WAVELENGTHS = [420.0, 500.0, 580.0, 660.0]

# Veach's MIS scene (as converted for Mitsuba 3 by users): RGB indices with components > 1,
# which Mitsuba clamps to [0, 1] before upsampling.
VEACH_ETA = '<rgb name="eta" value="0.200438, 0.924033, 1.10221"/><rgb name="k" value="3.91295, 2.45285, 2.14219"/>'
SPECTRAL_CASES = [
    ('<bsdf type="roughconductor"><float name="alpha" value="0.1"/>'
     '<string name="distribution" value="beckmann"/><rgb name="specular_reflectance" value="0.3, 0.3, 0.3"/>'
     + VEACH_ETA + '</bsdf>'),
    ('<bsdf type="roughconductor"><float name="alpha" value="0.25"/><string name="distribution" value="ggx"/>'
     '<rgb name="eta" value="0.2, 0.6, 0.9"/><rgb name="k" value="0.9, 0.5, 0.3"/>'
     '<rgb name="specular_reflectance" value="0.9, 0.6, 0.3"/></bsdf>'),
    ('<bsdf type="roughdielectric"><float name="alpha" value="0.2"/><float name="int_ior" value="1.5"/>'
     '<float name="ext_ior" value="1.0"/><float name="specular_reflectance" value="0.5"/>'
     '<rgb name="specular_transmittance" value="0.2, 0.5, 0.8"/></bsdf>'),
    ('<bsdf type="roughplastic"><float name="alpha" value="0.2"/><rgb name="diffuse_reflectance" value="0.2, 0.4, 0.6"/>'
     '<float name="specular_reflectance" value="0.4"/></bsdf>'),
    # Conductor materials from Mitsuba's own tables (thinfilm's library lacks them).
    '<bsdf type="roughconductor"><float name="alpha" value="0.2"/><string name="material" value="a-C"/></bsdf>',
    '<bsdf type="roughconductor"><float name="alpha" value="0.15"/><string name="material" value="Cr"/></bsdf>',
] + [
    # Polarised plastic (Baek et al. 2018): both distributions, anisotropy, a specular factor.
    '<bsdf type="pplastic"><rgb name="diffuse_reflectance" value="0.05, 0.03, 0.1"/><float name="alpha" value="0.06"/></bsdf>',
    ('<bsdf type="pplastic"><rgb name="diffuse_reflectance" value="0.2, 0.4, 0.6"/><float name="alpha" value="0.3"/>'
     '<string name="distribution" value="ggx"/><float name="int_ior" value="1.6"/><float name="specular_reflectance" value="0.5"/></bsdf>'),
    ('<bsdf type="pplastic"><float name="diffuse_reflectance" value="0.8"/><float name="alpha_u" value="0.05"/>'
     '<float name="alpha_v" value="0.3"/><float name="eta" value="1.33"/></bsdf>'),
]

# BSDFs whose Mueller matrices (scalar_spectral_polarized) are compared: their first cases.
MUELLER_CASES = [xml for xml in SPECTRAL_CASES if "pplastic" in xml]


def direction(theta_deg, phi_deg):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)]


def refract_dir(wi, eta):
    """Smooth refraction of local wi through the z = 0 interface (eta = n_int/n_ext)."""
    e = 1 / eta if wi[2] > 0 else eta
    s2 = e * e * (1 - wi[2] ** 2)
    ct = math.sqrt(max(0.0, 1 - s2))
    return [-e * wi[0], -e * wi[1], -ct if wi[2] > 0 else ct]


def perturb(w, dtheta, dphi):
    r = math.sqrt(w[0] ** 2 + w[1] ** 2)
    theta = math.degrees(math.atan2(r, abs(w[2])))
    phi = math.degrees(math.atan2(w[1], w[0]))
    d = direction(min(89.0, max(0.0, theta + dtheta)), phi + dphi)
    return [d[0], d[1], d[2] if w[2] >= 0 else -d[2]]


CASES = [
    {"type": "roughconductor", "eta": 0.2, "k": 3.9},
    {"type": "roughconductor", "eta": 0.2, "k": 3.9, "distribution": "ggx", "alpha": 0.3},
    {"type": "roughconductor", "eta": 1.5, "k": 2.0, "alpha_u": 0.05, "alpha_v": 0.3},
    {"type": "roughconductor", "eta": 1.5, "k": 2.0, "distribution": "ggx", "alpha_u": 0.3, "alpha_v": 0.08},
    {"type": "roughplastic", "alpha": 0.2, "int_ior": 1.49, "ext_ior": 1.0},
    {"type": "roughplastic", "distribution": "ggx", "alpha": 0.01, "int_ior": 1.5046, "ext_ior": 1.000277},
    {"type": "roughplastic", "distribution": "ggx", "alpha": 0.4, "int_ior": 1.5046, "ext_ior": 1.000277},
    {"type": "roughplastic", "distribution": "ggx", "alpha": 1.0, "int_ior": 1.5046, "ext_ior": 1.000277, "nonlinear": True},
    {"type": "roughdielectric", "alpha": 0.2, "int_ior": 1.5, "ext_ior": 1.0},
    {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.3, "int_ior": 1.33, "ext_ior": 1.0},
    {"type": "roughdielectric", "distribution": "ggx", "alpha_u": 0.1, "alpha_v": 0.4, "int_ior": 1.5, "ext_ior": 1.0},
]


def mitsuba_dict(case):
    d = dict(case)
    if case["type"] == "roughplastic":
        d["diffuse_reflectance"] = {"type": "rgb", "value": [0.5, 0.5, 0.5]}
    return d


def pairs(case):
    out = []
    for theta_i, phi_i in [(20.0, 30.0), (60.0, 200.0)]:
        for below in [False, True] if case["type"] == "roughdielectric" else [False]:
            wi = direction(theta_i, phi_i)
            if below:
                wi[2] = -wi[2]
            mirror = [-wi[0], -wi[1], wi[2]]
            targets = [mirror]
            if case["type"] == "roughdielectric":
                targets.append(refract_dir(wi, case["int_ior"] / case["ext_ior"]))
            for t in targets:
                for dt, dp in [(0.0, 0.0), (6.0, 10.0), (-8.0, -25.0)]:
                    out.append((wi, perturb(t, dt, dp)))
    return out


def spectral_points(polarized=False):
    """Per-wavelength eval and pdf of the XML cases (scalar_spectral); with `polarized`, the
    Mueller matrices of MUELLER_CASES (scalar_spectral_polarized: rows, columns, wavelengths,
    in Mitsuba's implicit Stokes bases, stokes_basis(-wo) in and stokes_basis(wi) out)."""
    mi.set_variant("scalar_spectral_polarized" if polarized else "scalar_spectral")
    ctx = mi.BSDFContext()
    rows = []
    for xml in MUELLER_CASES if polarized else SPECTRAL_CASES:
        bsdf = mi.load_string(xml.replace("<bsdf ", '<bsdf version="3.0.0" ', 1))
        eta = 1.5 if "roughdielectric" in xml else None
        for theta_i, phi_i in [(20.0, 30.0), (60.0, 200.0)]:
            wi = direction(theta_i, phi_i)
            targets = [[-wi[0], -wi[1], wi[2]]]
            if eta:
                targets.append(refract_dir(wi, eta))
            for t in targets:
                for dt, dp in [(0.0, 0.0), (6.0, 10.0)]:
                    wo = perturb(t, dt, dp)
                    si = mi.SurfaceInteraction3f()
                    si.n = [0, 0, 1]
                    si.sh_frame = mi.Frame3f([1, 0, 0], [0, 1, 0], [0, 0, 1])
                    si.wi = wi
                    si.wavelengths = WAVELENGTHS
                    v = bsdf.eval(ctx, si, mi.Vector3f(wo))
                    if polarized:
                        value = [[[float(v[i][j][k]) for k in range(4)] for j in range(4)] for i in range(4)]
                    else:
                        value = [float(x) for x in v]
                    pdf = float(bsdf.pdf(ctx, si, mi.Vector3f(wo)))
                    rows.append({"xml": xml, "wi": wi, "wo": wo, "eval": value, "pdf": pdf})
    doc = {
        "about": ("Mitsuba 3 scalar_spectral_polarized eval (Mueller matrix [row][column][wavelength] of f·cos θo)"
                  if polarized else "Mitsuba 3 scalar_spectral eval (f·cos θo at `wavelengths`) and pdf")
        + " of BSDFs given as XML, at local direction pairs; made by tools/mitsuba/bsdf_point_references.py",
        "mitsuba": mi.__version__,
        "wavelengths": WAVELENGTHS,
        "points": rows,
    }
    out = OUT_MUELLER if polarized else OUT_SPECTRAL
    with open(out, "w") as f:
        json.dump(doc, f, indent=None if polarized else 1)
    print(f"{len(rows)} points -> {out}")


def main():
    mi.set_variant("scalar_rgb")
    ctx = mi.BSDFContext()
    rows = []
    for case in CASES:
        bsdf = mi.load_dict(mitsuba_dict(case))
        for wi, wo in pairs(case):
            si = mi.SurfaceInteraction3f()
            si.n = [0, 0, 1]
            si.sh_frame = mi.Frame3f([1, 0, 0], [0, 1, 0], [0, 0, 1])
            si.wi = wi
            value = float(bsdf.eval(ctx, si, mi.Vector3f(wo))[0])
            pdf = float(bsdf.pdf(ctx, si, mi.Vector3f(wo)))
            rows.append({"bsdf": case, "wi": wi, "wo": wo, "eval": value, "pdf": pdf})
    doc = {
        "about": "Mitsuba 3 scalar_rgb eval (f·cos θo) and pdf at local direction pairs; made by tools/mitsuba/bsdf_point_references.py",
        "mitsuba": mi.__version__,
        "points": rows,
    }
    with open(OUT, "w") as f:
        json.dump(doc, f, indent=1)
    print(f"{len(rows)} points -> {OUT}")


if __name__ == "__main__":
    main()
    spectral_points()
    spectral_points(polarized=True)
