#!/usr/bin/env python3
"""Mitsuba 3 reference for thinfilm's `bumpmap` BSDF (tests/bumpmap.rs, `matches_mitsuba`).

Writes the height bitmap `tests/references/bumpmap/height.exr` (32×32, one Y channel:
h = 0.02·x − 0.015·y + 0.06·sin(2πx/16)·cos(2πy/8) over texel indices x, y — slopes in both u
and v, so a flipped or swapped axis shows), then renders `tests/references/bumpmap/NAME.xml` for
NAME = `bumpmap` (a bump-mapped diffuse plane), `sphere` (the same on a sphere: its dp/du
and dp/dv magnitudes matter; `flip_invalid_normals` and `use_shadowing_function` false) and
`sphere_defaults` (that sphere with Mitsuba's defaults, both true), under a directional light, with Mitsuba 3 into `NAME.exr`
(float32 RGB), and records spp, variant and version in `manifest.json` there.

Regenerate (from the repository root):

    export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
    python3 tools/mitsuba/render_bumpmap_reference.py --spp 4096 [--names sphere_defaults]
"""

import argparse
import json
import os

REPO = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
DIR = os.path.join(REPO, "tests", "references", "bumpmap")
NAMES = ["bumpmap", "sphere", "sphere_defaults"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--variant", default="scalar_spectral")
    ap.add_argument("--names", nargs="+", default=NAMES, choices=NAMES, help="scenes to render")
    args = ap.parse_args()

    import mitsuba as mi
    import numpy as np

    mi.set_variant(args.variant)
    y, x = np.mgrid[0:32, 0:32].astype(np.float64)
    h = 0.02 * x - 0.015 * y + 0.06 * np.sin(2 * np.pi * x / 16) * np.cos(2 * np.pi * y / 8)
    height = np.ascontiguousarray(h.astype(np.float32)[:, :, None])
    mi.Bitmap(height, mi.Bitmap.PixelFormat.Y).write(os.path.join(DIR, "height.exr"))

    path = os.path.join(DIR, "manifest.json")
    manifest = json.load(open(path)) if os.path.exists(path) else {}
    for name in args.names:
        scene = mi.load_file(os.path.join(DIR, name + ".xml"))
        arr = np.array(mi.render(scene, spp=args.spp, seed=11), dtype=np.float32)
        out = os.path.join(DIR, name + ".exr")
        mi.Bitmap(np.ascontiguousarray(arr), mi.Bitmap.PixelFormat.RGB).write(out)
        print(f"{name}: {arr.shape[1]}x{arr.shape[0]}, mean {arr.mean(axis=(0, 1))}")
        manifest[name] = {
            "spp": args.spp,
            "variant": args.variant,
            "mitsuba": mi.__version__,
            "command": "python3 tools/mitsuba/render_bumpmap_reference.py --spp %d --names %s"
            % (args.spp, name),
        }
    with open(path, "w") as f:
        json.dump(manifest, f, indent=2, sort_keys=True)
        f.write("\n")


if __name__ == "__main__":
    main()
