#!/usr/bin/env python3
"""ENVI interoperability fixtures with Spectral Python (PyPI `spectral`, tested with 0.25).

Two jobs, one formula:

  python3 tools/spy_fixtures.py write   # SPy writes tests/fixtures/envi/spy/*.hdr/.img
  python3 tools/spy_fixtures.py check   # SPy reads tests/fixtures/envi/ours/*.hdr (written
                                        # by `cargo test --test capture_envi -- --ignored
                                        # write_fixtures_for_spy`) and checks every sample

Cubes are 4 lines x 5 samples x 6 bands; the value of (line y, sample x, band b) is
`expected(kind, y, x, b)` below, mirrored in tests/capture_envi.rs (`expected`).
Run from the repository root. Outputs are tiny and committed; no Python runs at test time.
"""
import glob
import os
import sys

import numpy as np
import spectral.io.envi as envi

LINES, SAMPLES, BANDS = 4, 5, 6
WAVELENGTHS_NM = [400.0 + 20.0 * b for b in range(BANDS)]
FWHM_NM = [5.0] * BANDS
ROOT = os.path.join("tests", "fixtures", "envi")


def expected(kind, y, x, b):
    if kind == "float32" or kind == "float64":
        return (b * 100 + y * 10 + x) * 0.25 - 3.5
    if kind == "uint16":
        if (y, x, b) == (3, 4, 5):
            return 65535  # saturated sample
        return b * 10000 + y * 100 + x * 7 + 3
    if kind == "int16":
        return b * 1000 + y * 100 + x * 7 - 3000
    raise ValueError(kind)


def cube(kind):
    a = np.zeros((LINES, SAMPLES, BANDS), dtype=np.float64)
    for y in range(LINES):
        for x in range(SAMPLES):
            for b in range(BANDS):
                a[y, x, b] = expected(kind, y, x, b)
    return a


def write():
    out = os.path.join(ROOT, "spy")
    os.makedirs(out, exist_ok=True)
    for kind in ["float32", "uint16", "int16"]:
        for interleave in ["bsq", "bil", "bip"]:
            # Exercise both byte orders and both wavelength units across the set.
            byteorder = 1 if (kind, interleave) in [("float32", "bsq"), ("int16", "bil"), ("uint16", "bip")] else 0
            meta = {"fwhm": FWHM_NM, "wavelength": WAVELENGTHS_NM, "wavelength units": "nm"}
            if kind == "uint16":
                meta["wavelength"] = [w / 1000.0 for w in WAVELENGTHS_NM]
                meta["fwhm"] = [w / 1000.0 for w in FWHM_NM]
                meta["wavelength units"] = "micrometers"
            if kind == "int16":
                meta["data ignore value"] = -3000
            path = os.path.join(out, f"{kind}_{interleave}.hdr")
            envi.save_image(path, cube(kind).astype(kind), dtype=kind, interleave=interleave,
                            byteorder=byteorder, metadata=meta, ext=".img", force=True)
            print("wrote", path, "byte order", byteorder)


def check():
    files = sorted(glob.glob(os.path.join(ROOT, "ours", "*.hdr")))
    if not files:
        sys.exit("no files in tests/fixtures/envi/ours; run the ignored Rust test first")
    failures = 0
    for path in files:
        kind, interleave = os.path.basename(path)[:-4].split("_")
        img = envi.open(path)
        data = np.asarray(img.load(), dtype=np.float64)
        want = cube(kind)
        ok = data.shape == want.shape and np.array_equal(data, want)
        ok &= img.metadata["interleave"] == interleave
        ok &= np.dtype(img.dtype).name == kind
        wl = [float(w) for w in img.metadata.get("wavelength", [])]
        ok &= wl == WAVELENGTHS_NM
        fw = [float(w) for w in img.metadata.get("fwhm", [])]
        ok &= fw == FWHM_NM
        failures += not ok
        print(f"{path}: {'OK' if ok else 'MISMATCH'} shape={data.shape} dtype={np.dtype(img.dtype).name} "
              f"interleave={img.metadata['interleave']} byte order={img.metadata['byte order']}")
    print(f"{len(files) - failures}/{len(files)} cubes read by SPy equal the expected values")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    if len(sys.argv) != 2 or sys.argv[1] not in ("write", "check"):
        sys.exit(__doc__)
    {"write": write, "check": check}[sys.argv[1]]()
