#!/usr/bin/env python3
"""Check thinfilm's sRGB rgb2spec table against the one Mitsuba 3 ships (check only: Mitsuba's
file is never copied into the repository).

Rerun from the repository root (needs numpy, mitsuba):

    python3 tools/rgb2spec/compare_with_mitsuba.py

Both tables are read from their "SPEC" files and looked up with the same numpy port of
rgb2spec_fetch (Mitsuba's ext/rgb2spec/rgb2spec.c), then the upsampled spectra are compared on
the 10×10×10 grid k/9 and 20,000 random linear-sRGB colours, and each is integrated under D65
(1 nm, spectra/*.csv) back to linear sRGB to compare the round-trip errors. Finally every one
of the 3·64³ table nodes of each file is evaluated on its own (5 nm quadrature) and its
round-trip error reported.
"""

import os

import numpy as np

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
LAMBDA = np.arange(360, 831, 1).astype(np.float64)


def load_spec(path):
    raw = open(path, "rb").read()
    assert raw[:4] == b"SPEC", path
    res = int(np.frombuffer(raw[4:8], "<u4")[0])
    scale = np.frombuffer(raw[8:8 + 4 * res], "<f4")
    n = 9 * res ** 3
    data = np.frombuffer(raw[8 + 4 * res: 8 + 4 * res + 4 * n], "<f4").reshape(3, res, res, res, 3)
    return res, scale.astype(np.float64), data.astype(np.float64), len(raw)


def fetch(table, rgb):
    res, scale, data, _ = table
    rgb = np.clip(np.asarray(rgb, float), 0, 1)
    i = 0
    for j in (1, 2):
        if rgb[j] >= rgb[i]:
            i = j
    z = rgb[i]
    if z <= 0:
        return np.array([0.0, 0.0, -np.inf])
    s = (res - 1) / z
    x, y = rgb[(i + 1) % 3] * s, rgb[(i + 2) % 3] * s
    xi, yi = min(int(x), res - 2), min(int(y), res - 2)
    zi = min(max(np.searchsorted(scale, z, side="right") - 1, 0), res - 2)
    x1, y1 = x - xi, y - yi
    z1 = (z - scale[zi]) / (scale[zi + 1] - scale[zi])
    c = np.zeros(3)
    for dz, wz in ((0, 1 - z1), (1, z1)):
        for dy, wy in ((0, 1 - y1), (1, y1)):
            for dx, wx in ((0, 1 - x1), (1, x1)):
                c += wz * wy * wx * data[i, zi + dz, yi + dy, xi + dx]
    return c


def sigmoid_poly(c, lam):
    x = (c[0] * lam + c[1]) * lam + c[2]
    with np.errstate(invalid="ignore"):
        return np.where(np.isinf(x), (np.sign(x) + 1) / 2, 0.5 + x / (2 * np.sqrt(1 + x * x)))


def load_csv(name):
    with open(os.path.join(ROOT, "spectra", name)) as f:
        lines = [l for l in f if l.strip() and not l.startswith("#")]
    return np.array([[float(v) for v in l.split(",")] for l in lines[1:]])


def main():
    import mitsuba

    mitsuba_path = os.path.join(os.path.dirname(mitsuba.__file__), "data", "srgb.coeff")
    ours = load_spec(os.path.join(ROOT, "spectra", "srgb_rgb2spec_64.coeff"))
    theirs = load_spec(mitsuba_path)
    print(f"ours: res {ours[0]}, {ours[3]} bytes; Mitsuba {mitsuba.__version__}: res {theirs[0]}, {theirs[3]} bytes")
    assert ours[0] == theirs[0]
    print("z-node max |Δ|:", np.max(np.abs(ours[1] - theirs[1])))

    cmf = load_csv("cie1931_2deg_cmf_1nm.csv")[:, 1:]
    d65 = load_csv("cie_d65_1nm.csv")[:, 1]
    k = 1.0 / np.sum(d65 * cmf[:, 1])
    P = np.array([[x / y, 1.0, (1 - x - y) / y] for x, y in [(0.64, 0.33), (0.30, 0.60), (0.15, 0.06)]]).T
    m_rgb2xyz = P * np.linalg.solve(P, np.array([0.95047, 1.0, 1.08883]))
    m_xyz2rgb = np.linalg.inv(m_rgb2xyz)

    def round_trip(spec):
        return m_xyz2rgb @ (k * np.sum((spec * d65)[:, None] * cmf, axis=0))

    rng = np.random.default_rng(1)
    grid = [np.array([r, g, b]) / 9.0 for r in range(10) for g in range(10) for b in range(10)]
    for label, colours in (("10x10x10 grid k/9", grid), ("20000 random", list(rng.random((20000, 3))))):
        d_spec = d_rt = rt_ours = rt_theirs = 0.0
        for rgb in colours:
            if rgb.max() <= 0:
                continue
            so = sigmoid_poly(fetch(ours, rgb), LAMBDA)
            st = sigmoid_poly(fetch(theirs, rgb), LAMBDA)
            d_spec = max(d_spec, np.max(np.abs(so - st)))
            ro, rt = round_trip(so), round_trip(st)
            d_rt = max(d_rt, np.max(np.abs(ro - rt)))
            rt_ours = max(rt_ours, np.max(np.abs(ro - rgb)))
            rt_theirs = max(rt_theirs, np.max(np.abs(rt - rgb)))
        print(f"{label}: max |spectrum ours - Mitsuba| = {d_spec:.3e}; "
              f"max |round trip ours - Mitsuba| = {d_rt:.3e}; "
              f"max round-trip error ours {rt_ours:.3e}, Mitsuba {rt_theirs:.3e}")

    w5 = (d65 * k)[::5, None] * cmf[::5] * 5.0
    for label, table in (("ours", ours), ("Mitsuba", theirs)):
        e = node_errors(table, w5, m_xyz2rgb)
        print(f"{label} table nodes: max round-trip error {e.max():.3e}, "
              f"{int((e > 2e-3).sum())} of {e.size} above 2e-3")


def node_errors(table, w5, m_xyz2rgb):
    """Max |rgb round trip − node rgb| of every table node (5 nm quadrature)."""
    res, scale, data, _ = table
    lam = LAMBDA[::5]
    errs = np.zeros((3, res, res, res))
    j, i = np.meshgrid(np.arange(res), np.arange(res), indexing="ij")
    for l in range(3):
        for k in range(res):
            cc = data[l, k].reshape(-1, 3)
            x = (cc[:, 0:1] * lam + cc[:, 1:2]) * lam + cc[:, 2:3]
            spec = 0.5 + x / (2 * np.sqrt(1 + x * x))
            rgb = (spec @ w5) @ m_xyz2rgb.T
            tgt = np.zeros((res * res, 3))
            tgt[:, l] = scale[k]
            tgt[:, (l + 1) % 3] = i.ravel() / (res - 1) * scale[k]
            tgt[:, (l + 2) % 3] = j.ravel() / (res - 1) * scale[k]
            errs[l, k] = np.max(np.abs(rgb - tgt), axis=1).reshape(res, res)
    return errs


if __name__ == "__main__":
    main()
