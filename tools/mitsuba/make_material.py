#!/usr/bin/env python3
"""Writes an estimator-style material (tests/references/material/material.xml + thickness.exr):
a `<bsdf type="thinfilm">` whose thickness is a bitmap texture in nanometres, in the format
`thinfilm estimate` writes (material.xml). The map is a smooth 64×64 field,
250–650 nm, so the reference render shows bands of interference colour.

Rerun (from the repository root): python3 tools/mitsuba/make_material.py
"""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import thinfilm_mitsuba  # noqa: E402

OUT = os.path.join(HERE, "..", "..", "tests", "references", "material")

thinfilm_mitsuba.setup("scalar_spectral")
import mitsuba as mi  # noqa: E402

n = 64
y, x = np.mgrid[0:n, 0:n] / (n - 1)
thickness_nm = 250.0 + 300.0 * x + 100.0 * np.exp(-((x - 0.6) ** 2 + (y - 0.4) ** 2) / 0.04)
os.makedirs(OUT, exist_ok=True)
bmp = mi.Bitmap(thickness_nm.astype(np.float32)[:, :, None], mi.Bitmap.PixelFormat.Y)
bmp.write(os.path.join(OUT, "thickness.exr"))
with open(os.path.join(OUT, "material.xml"), "w") as f:
    f.write(
        """<!-- Estimator-style thin-film material (written by tools/mitsuba/make_material.py). -->
<bsdf type="thinfilm">
    <float name="film_ior" value="1.38"/>
    <texture type="bitmap" name="thickness">
        <string name="filename" value="thickness.exr"/>
        <boolean name="raw" value="true"/>
    </texture>
    <float name="substrate_ior" value="1.52"/>
    <float name="substrate_k" value="0"/>
</bsdf>
"""
    )
print("wrote", os.path.relpath(OUT))
