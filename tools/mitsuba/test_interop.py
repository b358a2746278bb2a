#!/usr/bin/env python3
"""Interop test: a material fitted by `thinfilm estimate` renders the same in Mitsuba 3 (with
the installed `thinfilm_mitsuba` package) as in `thinfilm render`.

1. `thinfilm simulate --preset sample3` (ZnS on PET, the seed paper's hard case) and
   `thinfilm estimate` write fit/material.xml and fit/thickness.exr;
2. the material is put on the plane of scenes/plane_thickness_map.xml (its `<bsdf>` replaced
   by the fitted one, as written), the scene saved next to the fit;
3. the scene is rendered by `thinfilm render` and by Mitsuba 3 (llvm_ad_spectral, or
   scalar_spectral where LLVM is missing), both with the scene's box filter and sampler;
4. `thinfilm compare` must report mean ΔE00 ≤ 1 (the two renders' own noise is ~0.1).

Opt-in (not part of `cargo test`; needs Mitsuba 3 and the package). From the repository root:

    pip install mitsuba ./tools/mitsuba
    cargo build --release
    python3 tools/mitsuba/test_interop.py            # --keep DIR keeps the files

The package is imported as installed (this script's own folder is taken off sys.path), so the
test checks the packaging too. Exit status 0 = pass.
"""

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.abspath(os.path.join(HERE, "..", ".."))
# Test the installed package, not the source folder beside this script.
sys.path = [p for p in sys.path if os.path.abspath(p or ".") != HERE]


def run(cmd, **kw):
    print("$", " ".join(cmd), flush=True)
    return subprocess.run(cmd, check=True, **kw)


def fitted_scene(fit_dir):
    """plane_thickness_map.xml with its BSDF replaced by fit_dir/material.xml."""
    with open(os.path.join(REPO, "scenes", "plane_thickness_map.xml")) as f:
        scene = f.read()
    with open(os.path.join(fit_dir, "material.xml")) as f:
        material = f.read()
    material = re.sub(r"<!--.*?-->", "", material, flags=re.S).strip()
    scene, count = re.subn(r'<bsdf type="thinfilm">.*?</bsdf>', lambda _: material, scene, flags=re.S)
    assert count == 1, "scenes/plane_thickness_map.xml has no <bsdf type=\"thinfilm\"> to replace"
    textures = os.path.join(REPO, "scenes", "textures")
    scene = scene.replace('value="textures/', f'value="{textures}/')
    path = os.path.join(fit_dir, "scene.xml")
    with open(path, "w") as f:
        f.write(scene)
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--thinfilm", default=os.path.join(REPO, "target", "release", "thinfilm"),
                    help="the thinfilm binary (default: target/release/thinfilm)")
    ap.add_argument("--res", type=int, default=64, help="image width and height")
    ap.add_argument("--spp", type=int, default=1024, help="samples per pixel, both renderers")
    ap.add_argument("--max-delta-e", type=float, default=1.0, help="pass threshold (mean ΔE00)")
    ap.add_argument("--keep", help="work in this folder and keep it")
    args = ap.parse_args()

    try:
        import thinfilm_mitsuba
    except ImportError:
        sys.exit("the thinfilm_mitsuba package is not installed: pip install ./tools/mitsuba")
    print("plugin package:", os.path.dirname(thinfilm_mitsuba.__file__))
    variant = thinfilm_mitsuba.setup()
    import mitsuba as mi

    work = args.keep or tempfile.mkdtemp(prefix="thinfilm-interop-")
    os.makedirs(work, exist_ok=True)
    tf = args.thinfilm
    cap, fit = os.path.join(work, "capture"), os.path.join(work, "fit")
    run([tf, "simulate", "--preset", "sample3", "--size", "64x48", "--noise", "0.004",
         "--out", cap, "--quiet"])
    run([tf, "estimate", cap, "--out", fit, "--quiet"])
    scene = fitted_scene(fit)
    ours = os.path.join(work, "thinfilm.exr")
    run([tf, "render", scene, "-o", ours, "--spp", str(args.spp), "-D", f"res={args.res}",
         "--quiet"])

    print(f"Mitsuba {mi.__version__} ({variant}) renders {scene} …", flush=True)
    loaded = mi.load_file(scene, res=args.res, spp=args.spp)
    image = mi.render(loaded, spp=args.spp, seed=0)
    theirs = os.path.join(work, "mitsuba.exr")
    mi.Bitmap(image, pixel_format=mi.Bitmap.PixelFormat.RGB).write(theirs)

    out = run([tf, "compare", ours, theirs, "--json", "--figure",
               os.path.join(work, "compare.png")], capture_output=True, text=True)
    metrics = json.loads(out.stdout)["metrics"]
    de = metrics["delta_e00_mean"]
    ok = de <= args.max_delta_e
    print(f"thinfilm render vs Mitsuba 3 + thinfilm_mitsuba: mean ΔE00 {de:.3f} "
          f"(95th pct {metrics['delta_e00_p95']:.3f}, RMSE {metrics['rmse']:.5f}) "
          f"-> {'PASS' if ok else 'FAIL'} (threshold {args.max_delta_e}); files in {work}")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
