#!/usr/bin/env python3
"""Mitsuba 3 references for thinfilm's emitters and sensors (tests/lights_reference.rs).

Renders every scene `tests/references/lights/NAME.xml` (spot, directional, thinlens,
orthographic, ...) with Mitsuba 3 into `tests/references/lights/NAME.exr` (float32 RGB, the
scene's own 64×48 film with a box filter) and records spp, variant and Mitsuba version in
`tests/references/lights/manifest.json`.

Regenerate (from the repository root):

    export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
    python3 tools/mitsuba/render_light_references.py --spp 4096

Only some scenes:  --only spot --only thinlens
Another directory of scenes (with its own manifest): --dir tests/references/projector

Mitsuba's own noise at a test's sample count (--noise-spp 256): two more renders at that spp
with different seeds, compared as the tests compare (largest relative difference of a
channel's image mean, and of a bright 8x8 block's sum), recorded in the manifest as
`noise_<N>spp` — the tests' tolerances are justified from these. The participating-media
references (tests/scene_media.rs):

    python3 tools/mitsuba/render_light_references.py --dir tests/references/media \
        --spp 4096 --noise-spp 256
"""

import argparse
import glob
import json
import os
import time

REPO = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
DIR = os.path.join(REPO, "tests", "references", "lights")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spp", type=int, default=4096)
    ap.add_argument("--variant", default="llvm_ad_spectral")
    ap.add_argument("--only", action="append", default=[])
    ap.add_argument("--dir", default=DIR, help="directory of NAME.xml scenes")
    ap.add_argument("--noise-spp", type=int, default=0,
                    help="also measure Mitsuba's seed-to-seed noise at this spp")
    args = ap.parse_args()
    scene_dir = os.path.abspath(args.dir)

    import mitsuba as mi
    import numpy as np

    mi.set_variant(args.variant)
    manifest_path = os.path.join(scene_dir, "manifest.json")
    manifest = {}
    if os.path.exists(manifest_path):
        with open(manifest_path) as f:
            manifest = json.load(f)
    for xml in sorted(glob.glob(os.path.join(scene_dir, "*.xml"))):
        name = os.path.splitext(os.path.basename(xml))[0]
        if args.only and name not in args.only:
            continue
        scene = mi.load_file(xml)
        t0 = time.perf_counter()
        # Passes of at most 1024 spp (different seeds) bound the llvm variant's memory.
        passes = max(1, -(-args.spp // 1024))
        acc = None
        for i in range(passes):
            n = args.spp // passes + (1 if i < args.spp % passes else 0)
            img = np.array(mi.render(scene, spp=n, seed=17 + i), dtype=np.float64) * n
            acc = img if acc is None else acc + img
        arr = (acc / args.spp).astype(np.float32)
        out = os.path.join(scene_dir, name + ".exr")
        mi.Bitmap(np.ascontiguousarray(arr), mi.Bitmap.PixelFormat.RGB).write(out + ".partial.exr")
        os.replace(out + ".partial.exr", out)
        secs = time.perf_counter() - t0
        print(f"{name}: {arr.shape[1]}x{arr.shape[0]}, mean {arr.mean(axis=(0, 1))}, {secs:.1f} s")
        manifest[name] = {
            "spp": args.spp,
            "variant": args.variant,
            "mitsuba": mi.__version__,
            "command": "python3 tools/mitsuba/render_light_references.py --spp %d%s%s" % (
                args.spp, "" if scene_dir == DIR else " --dir " + os.path.relpath(scene_dir, REPO),
                " --noise-spp %d" % args.noise_spp if args.noise_spp else ""),
        }
        if args.noise_spp:
            a, b = (np.array(mi.render(scene, spp=args.noise_spp, seed=s), dtype=np.float64)
                    for s in (101, 102))
            manifest[name]["noise_%dspp" % args.noise_spp] = seed_noise(a, b)
            print(f"  noise at {args.noise_spp} spp: {manifest[name]['noise_%dspp' % args.noise_spp]}")
    with open(manifest_path, "w") as f:
        json.dump(manifest, f, indent=2, sort_keys=True)
        f.write("\n")


def seed_noise(a, b):
    """How two renders of one scene with different seeds differ, measured as the tests
    measure thinfilm against the reference: per-channel image means, and the sums of the
    8x8 blocks brighter than a quarter of the average block."""
    means = [abs(a[..., c].mean() / b[..., c].mean() - 1) for c in range(3)]
    h, w = a.shape[:2]
    blocks = []
    avg = b.sum(axis=2).mean() * 64
    for y in range(0, h, 8):
        for x in range(0, w, 8):
            sa, sb = a[y:y + 8, x:x + 8].sum(), b[y:y + 8, x:x + 8].sum()
            if sb > 0.25 * avg:
                blocks.append(abs(sa / sb - 1))
    return {"max_channel_mean_rel": round(max(means), 4),
            "max_bright_block_rel": round(max(blocks), 4)}


if __name__ == "__main__":
    main()
