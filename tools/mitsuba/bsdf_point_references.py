#!/usr/bin/env python3
"""Point references of Mitsuba 3's microfacet BSDFs for src/render/bsdf/tests.rs.

Evaluates Mitsuba's `roughconductor`, `roughplastic` and `roughdielectric` (scalar_rgb
variant, grey constant parameters so every channel is equal) at pairs of local directions near
their lobes, and writes f·cos θo (`eval`) and the sampling pdf (`pdf`) with the plugin's
parameters to tests/references/bsdf_points.json:

    python3 tools/mitsuba/bsdf_point_references.py

Mitsuba's Beckmann G1 is a rational fit of the exact form thinfilm uses (≤ 0.35 % apart), so
the test allows 1 %.
"""

import json
import math
import os

import mitsuba as mi

mi.set_variant("scalar_rgb")

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "..", "tests", "references", "bsdf_points.json")


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


def main():
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
