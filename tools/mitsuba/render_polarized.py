#!/usr/bin/env python3
"""Mitsuba 3 polarised reference renders for thinfilm.

Renders the polariser scenes `scenes/polarizer_*.xml` with Mitsuba's polarised spectral
variant (llvm_ad_spectral_polarized, else scalar_spectral_polarized) — the same XML thinfilm
renders — into float32 EXRs under `tests/references/`, and adds/updates their entries in
`tests/references/manifest.json` (spp, seed, size, variant, Mitsuba version, command),
leaving the other entries alone. Sensor, film and splitting into passes are exactly those of
`render_references.py` (imported), so framing and pixel filter match thinfilm's tests.

These scenes need a *polarised* variant: `render_references.py` (unpolarised variant) would
treat the polariser as a neutral 50 % filter, so do not regenerate them with that script.

Regenerate the committed references (from the repository root):

    export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
    python3 tools/mitsuba/render_polarized.py --spp 4096 --size 128

Options: --only NAME (scene file stem), --define KEY=VALUE (scene parameters, e.g. theta=120;
the output is then named NAME_KEY-VALUE), --variant, --seed, --out.
"""

import argparse
import json
import os
import shlex
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import render_references as rr  # noqa: E402

REPO = rr.REPO
DEFAULT_LLVM = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"


def setup(variant):
    if "DRJIT_LIBLLVM_PATH" not in os.environ and os.path.exists(DEFAULT_LLVM):
        os.environ["DRJIT_LIBLLVM_PATH"] = DEFAULT_LLVM
    import mitsuba as mi

    tried = [variant] if variant else ["llvm_ad_spectral_polarized", "scalar_spectral_polarized"]
    last = None
    for v in tried:
        try:
            mi.set_variant(v)
            if v.startswith("llvm"):
                import drjit as dr

                dr.eval(mi.Float(1.0) + 1.0)
            return mi, v
        except Exception as e:  # noqa: BLE001 - report and fall back
            last = e
    raise RuntimeError(f"no usable polarised Mitsuba variant among {tried}: {last}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variant", default=None)
    ap.add_argument("--spp", type=int, default=4096)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", action="append", default=[])
    ap.add_argument("--define", action="append", default=[], help="KEY=VALUE scene parameter")
    ap.add_argument("--out", default="tests/references")
    args = ap.parse_args()

    mi, variant = setup(args.variant)
    if not mi.variant().endswith("polarized"):
        sys.exit(f"variant {mi.variant()} is not polarised")
    params = dict(kv.split("=", 1) for kv in args.define)
    suffix = "".join(f"_{k}-{v}" for k, v in sorted(params.items()))
    sdir = os.path.join(REPO, "scenes")
    scenes = sorted(f for f in os.listdir(sdir) if f.startswith("polarizer_") and f.endswith(".xml"))
    if args.only:
        scenes = [f for f in scenes if os.path.splitext(f)[0] in args.only]
    if not scenes:
        sys.exit("no scenes/polarizer_*.xml matched")
    out_dir = os.path.join(REPO, args.out)
    os.makedirs(out_dir, exist_ok=True)
    manifest_path = os.path.join(out_dir, "manifest.json")
    manifest = {"references": {}}
    if os.path.exists(manifest_path):
        with open(manifest_path) as f:
            manifest = json.load(f)
    command = "python3 " + " ".join(
        shlex.quote(a) for a in [rr.rel(os.path.abspath(sys.argv[0]))] + sys.argv[1:]
    )
    for fname in scenes:
        name = os.path.splitext(fname)[0] + suffix
        path = os.path.join(sdir, fname)
        print(f"rendering {name} ({rr.rel(path)}) with {variant} at {args.spp} spp …")
        scene = mi.load_file(path, **params)
        sampler_type = rr.scene_sampler_type(path)
        sensor, (w, h) = rr.make_sensor(mi, scene, args.size, sampler_type)
        arr, secs = rr.render(mi, scene, sensor, args.spp, args.seed)
        exr = os.path.join(out_dir, f"{name}.exr")
        rr.write_exr(mi, exr, arr)
        print(f"  {w}×{h}, {secs:.1f} s, mean RGB {arr.reshape(-1, 3).mean(0)} → {rr.rel(exr)}")
        manifest["references"][name] = {
            "scene": rr.rel(path),
            "defines": params,
            "material": None,
            "exr": rr.rel(exr),
            "width": w,
            "height": h,
            "spp": args.spp,
            "sampler": sampler_type,
            "seed": args.seed,
            "rfilter": "box",
            "seconds": round(secs, 2),
            "variant": variant,
            "mitsuba_version": mi.__version__,
            "command": command,
        }
    with open(manifest_path + ".partial", "w") as f:
        json.dump(manifest, f, indent=2, sort_keys=True)
    os.replace(manifest_path + ".partial", manifest_path)
    print(f"updated {rr.rel(manifest_path)}")


if __name__ == "__main__":
    main()
