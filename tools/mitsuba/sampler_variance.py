#!/usr/bin/env python3
"""Per-pixel variance across seeds at equal spp: thinfilm builds against Mitsuba 3.

For each scene, renders N seeds at SIZE² and SPP with Mitsuba (cached as .npy under --cache)
and with each thinfilm build given as LABEL=BINARY[,ENV=VALUE…], then prints, per build, the
mean over pixels of the per-pixel variance across seeds (mean of R, G, B; unbiased) divided by
Mitsuba's: over all pixels, the pixels brighter than luminance 1 in the reference
(tests/references/NAME.exr) and the rest. The spread is the ratio over disjoint groups of
seeds (--groups; the same group of seeds for every renderer). Both renderers use the scene's
own sampler type, or the one given by --sampler (ldsampler in Mitsuba = sobol in thinfilm).
Mitsuba runs `llvm_ad_spectral` (set DRJIT_LIBLLVM_PATH) with thinfilm's BSDFs registered.

    python3 tools/mitsuba/sampler_variance.py --seeds 16 --scene teapot_gold \\
        --build new=target/release/thinfilm
"""

import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
REPO = os.path.abspath(os.path.join(HERE, "..", ".."))


def load_mitsuba():
    import thinfilm_mitsuba

    thinfilm_mitsuba.setup("llvm_ad_spectral")
    import mitsuba as mi

    return mi


def read_exr(mi, path):
    return np.array(mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32), dtype=np.float64)


def mitsuba_stack(mi, name, args, sampler):
    import render_references as rr

    cache = os.path.join(args.cache, f"mitsuba_{name}_{sampler}_{args.size}_{args.spp}.npy")
    have = np.load(cache) if os.path.exists(cache) else np.zeros((0, args.size, args.size, 3))
    if len(have) >= args.seeds:
        return have[: args.seeds]
    scene = mi.load_file(os.path.join(REPO, "scenes", name + ".xml"))
    sensor, _ = rr.make_sensor(mi, scene, args.size, sampler)
    imgs = list(have)
    for seed in range(len(have), args.seeds):
        img, _ = rr.render(mi, scene, sensor, args.spp, seed)
        imgs.append(np.asarray(img, dtype=np.float64))
    stack = np.stack(imgs)
    np.save(cache, stack)
    return stack


def thinfilm_stack(mi, name, args, sampler, binary, env):
    ours = "sobol" if sampler == "ldsampler" else "independent"
    imgs = []
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "o.exr")
        for seed in range(args.seeds):
            cmd = [binary, "render", os.path.join(REPO, "scenes", name + ".xml"), "-o", out,
                   "--quiet", "--spp", str(args.spp), "--seed", str(seed), "--sampler", ours,
                   "--resolution", f"{args.size}x{args.size}", "--threads", str(args.threads)]
            subprocess.run(cmd, check=True, env={**os.environ, **env}, stdout=subprocess.DEVNULL)
            imgs.append(read_exr(mi, out))
    return np.stack(imgs)


def ratios(ours, theirs, masks, groups):
    """Variance ratio per mask, over all seeds and over each of `groups` disjoint seed groups."""
    def var(stack, sel):
        return stack[sel].var(axis=0, ddof=1).mean(axis=-1)

    n = len(ours)
    sets = [np.arange(n)] + [g for g in np.array_split(np.arange(n), groups) if len(g) > 1]
    out = []
    for m in masks:
        if not m.any():
            out.append(None)
            continue
        r = [var(ours, s)[m].mean() / var(theirs, s)[m].mean() for s in sets]
        out.append((r[0], min(r[1:]), max(r[1:])))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", action="append", required=True, help="scene name in scenes/ (repeatable)")
    ap.add_argument("--build", action="append", required=True, help="LABEL=BINARY[,ENV=VALUE…] (repeatable)")
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--groups", type=int, default=4, help="disjoint seed groups for the spread")
    ap.add_argument("--sampler", default=None, help="ldsampler or independent (default: the scene's)")
    ap.add_argument("--cache", default=os.path.join(tempfile.gettempdir(), "sampler_variance"))
    args = ap.parse_args()
    os.makedirs(args.cache, exist_ok=True)
    import render_references as rr

    mi = load_mitsuba()
    print("| scene | sampler | build | seeds | all (groups) | bright (groups) | n bright | rest (groups) |")
    print("|---|---|---|---:|---:|---:|---:|---:|")
    for name in args.scene:
        path = os.path.join(REPO, "scenes", name + ".xml")
        sampler = args.sampler or rr.scene_sampler_type(path)
        theirs = mitsuba_stack(mi, name, args, sampler)
        ref = read_exr(mi, os.path.join(REPO, "tests", "references", name + ".exr"))
        lum = ref @ np.array([0.2126, 0.7152, 0.0722])
        masks = [np.ones_like(lum, dtype=bool), lum > 1.0, lum <= 1.0]
        for build in args.build:
            label, _, spec = build.partition("=")
            binary, *envs = spec.split(",")
            env = dict(e.split("=", 1) for e in envs)
            ours = thinfilm_stack(mi, name, args, sampler, binary, env)
            cells = [f"{c[0]:.2f} ({c[1]:.2f}–{c[2]:.2f})" if c else "–"
                     for c in ratios(ours, theirs, masks, args.groups)]
            print(f"| {name} | {sampler} | {label} | {args.seeds} | {cells[0]} | {cells[1]} | "
                  f"{int(masks[1].sum())} | {cells[2]} |", flush=True)


if __name__ == "__main__":
    main()
