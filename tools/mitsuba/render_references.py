#!/usr/bin/env python3
"""Mitsuba 3 reference renders for thinfilm.

Renders every scene file in `scenes/` (and the estimator-style material scene under
`tests/references/material/`) with Mitsuba 3 and the Python `thinfilm` BSDF plugin
(tools/mitsuba/thinfilm_mitsuba, its reflectance checked against tmm first), at high spp, with a box
pixel filter, into float32 EXRs under `tests/references/`, plus `manifest.json` and
`README.md` recording spp, seed, size, Mitsuba version, variant and the exact command.

Regenerate the committed references (from the repository root):

    export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
    python3 tools/mitsuba/render_references.py --spp 4096 --size 128

Only some scenes (the others stay in the manifest):
    python3 tools/mitsuba/render_references.py --spp 4096 --size 128 --only bubble --only coatings

Scenes in NO_MITSUBA_REFERENCE (prism.xml: dispersion) are skipped with the reason.

Other modes:
    --material path/to/material.xml   also render a material written by `thinfilm estimate`
    --bench SCENE --spp 16,64,256 --out-dir DIR --json [--sampler TYPE] [--repeats N]
                                      timed renders for `thinfilm bench render --mitsuba`
                                      with the scene's sampler type (or TYPE), N per spp
                                      (seeds SEED … SEED + N − 1); prints one JSON object
                                      to stdout.

The sensor of each scene is replaced by an equivalent one (same to_world, horizontal field
of view, clip planes) with a `size`-pixel-wide hdrfilm (height keeps the aspect ratio), a box
reconstruction filter and float32 RGB output; thinfilm's tests render with the same framing.
"""

import argparse
import json
import math
import os
import shlex
import sys
import time
import xml.etree.ElementTree as ET

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import thinfilm_mitsuba  # noqa: E402

REPO = os.path.abspath(os.path.join(HERE, "..", ".."))


def film_size(width, height, size):
    """Output size with the larger side = `size`, keeping the aspect ratio."""
    if width >= height:
        return size, max(1, round(size * height / width))
    return max(1, round(size * width / height)), size


def _scalar(v):
    import numpy as np

    return float(np.array(v, dtype=np.float64).ravel()[0])


def scene_sampler_type(path):
    """The `<sampler type=…>` of the scene file's sensor ("independent" if it has none)."""
    node = ET.parse(path).getroot().find(".//sensor/sampler")
    return node.get("type") if node is not None else "independent"


def make_sensor(mi, scene, size, sampler_type="independent"):
    import numpy as np

    sensor = scene.sensors()[0]
    params = mi.traverse(sensor)
    w, h = (int(v) for v in sensor.film().size())
    ow, oh = film_size(w, h, size)
    return (
        mi.load_dict(
            {
                "type": "perspective",
                "fov_axis": "x",
                "fov": _scalar(params["x_fov"]),
                "near_clip": float(sensor.near_clip()),
                "far_clip": float(sensor.far_clip()),
                "to_world": mi.ScalarTransform4f(
                    np.array(sensor.world_transform().matrix, dtype=np.float64).reshape(4, 4).tolist()
                ),
                "film": {
                    "type": "hdrfilm",
                    "width": ow,
                    "height": oh,
                    "rfilter": {"type": "box"},
                    "pixel_format": "rgb",
                    "component_format": "float32",
                },
                "sampler": {"type": sampler_type},
            }
        ),
        (ow, oh),
    )


def render(mi, scene, sensor, spp, seed):
    """Renders and returns (numpy HxWx3 float32, seconds). Splits high spp into passes of
    at most 1024 spp (different seeds) to bound memory in the llvm variant."""
    import drjit as dr
    import numpy as np

    passes = max(1, math.ceil(spp / 1024))
    per = [spp // passes + (1 if i < spp % passes else 0) for i in range(passes)]
    acc = None
    t0 = time.perf_counter()
    for i, n in enumerate(per):
        img = mi.render(scene, sensor=sensor, spp=n, seed=seed * 1000003 + i)
        dr.eval(img)
        arr = np.array(img, dtype=np.float64) * n
        acc = arr if acc is None else acc + arr
    secs = time.perf_counter() - t0
    return (acc / spp).astype(np.float32), secs


def write_exr(mi, path, arr):
    import numpy as np

    bmp = mi.Bitmap(np.ascontiguousarray(arr, dtype=np.float32), mi.Bitmap.PixelFormat.RGB)
    tmp = path + ".partial.exr"
    bmp.write(tmp)
    os.replace(tmp, path)


def compose_material_scene(material_path, template_path, out_path):
    """Writes `out_path`: the template scene with its placeholder BSDF (id="fitted_material")
    replaced by the `<bsdf type="thinfilm">` of a material.xml written by `thinfilm estimate`.
    File names inside the material are rewritten relative to `out_path`'s directory."""
    mat_dir = os.path.dirname(os.path.abspath(material_path))
    out_dir = os.path.dirname(os.path.abspath(out_path))
    root = ET.parse(material_path).getroot()
    bsdf = root if root.tag == "bsdf" else root.find(".//bsdf")
    if bsdf is None or bsdf.get("type") != "thinfilm":
        raise ValueError(f"{material_path}: no <bsdf type=\"thinfilm\"> element")
    for s in bsdf.iter("string"):
        if s.get("name") == "filename":
            f = os.path.join(mat_dir, s.get("value", ""))
            s.set("value", os.path.relpath(f, out_dir))
    bsdf.set("id", "fitted_material")
    troot = ET.parse(template_path).getroot()
    for parent in troot.iter():
        for i, child in enumerate(list(parent)):
            if child.tag == "bsdf" and child.get("id") == "fitted_material":
                parent.remove(child)
                parent.insert(i, bsdf)
                header = (
                    f"<!-- Generated by tools/mitsuba/render_references.py from "
                    f"{os.path.basename(material_path)} on {os.path.basename(template_path)}; "
                    "do not edit. -->\n"
                )
                tmp = out_path + ".partial"
                with open(tmp, "w") as f:
                    f.write(header + ET.tostring(troot, encoding="unicode") + "\n")
                os.replace(tmp, out_path)
                return out_path
    raise ValueError(f"{template_path}: no <bsdf id=\"fitted_material\"> placeholder")


# Scenes Mitsuba cannot render faithfully, with the reason (printed when skipped).
NO_MITSUBA_REFERENCE = {
    "prism": "dispersive dielectric (Mitsuba's dielectric takes a constant index only)",
}
# Scenes rendered by another script (a polarised variant); their manifest entries are kept.
OTHER_SCRIPT = {
    "polarizer_": "needs a *_polarized variant: tools/mitsuba/render_polarized.py",
}


def scene_list(args):
    """(name, scene file, material file or None); material scenes are composed on the fly."""
    scenes = []
    sdir = os.path.join(REPO, args.scenes_dir)
    if os.path.isdir(sdir):
        for name in sorted(os.listdir(sdir)):
            stem = os.path.splitext(name)[0]
            other = [why for prefix, why in OTHER_SCRIPT.items() if stem.startswith(prefix)]
            if name.endswith(".xml") and other:
                print(f"skipping {name}: {other[0]}", file=sys.stderr)
                continue
            if name.endswith(".xml") and stem in NO_MITSUBA_REFERENCE:
                print(f"skipping {name}: {NO_MITSUBA_REFERENCE[stem]}", file=sys.stderr)
                continue
            if name.endswith(".xml"):
                scenes.append((os.path.splitext(name)[0], os.path.join(sdir, name), None))
    if args.dev_scenes:
        ddir = os.path.join(HERE, "dev_scenes")
        for name in sorted(os.listdir(ddir)):
            if name.endswith(".xml"):
                scenes.append((os.path.splitext(name)[0], os.path.join(ddir, name), None))
    materials = [os.path.abspath(m) for m in args.material]
    default_mat = os.path.join(REPO, "tests", "references", "material", "material.xml")
    if os.path.exists(default_mat) and default_mat not in materials:
        materials.insert(0, default_mat)
    template = os.path.join(HERE, "material_template.xml")
    for i, m in enumerate(materials):
        name = "material" if i == 0 else f"material_{i}"
        # The composed scene lives beside the material (committed for the default one, so
        # thinfilm's tests render exactly the same file).
        out = os.path.join(os.path.dirname(m), "scene.xml")
        compose_material_scene(m, template, out)
        scenes.append((name, out, m))
    if args.only:
        scenes = [s for s in scenes if s[0] in args.only]
    return scenes


def rel(path):
    return os.path.relpath(path, REPO)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variant", default=None, help="Mitsuba variant (default llvm_ad_spectral, else scalar_spectral)")
    ap.add_argument("--spp", default="4096", help="samples per pixel (bench: comma-separated list)")
    ap.add_argument("--size", type=int, default=128, help="output width of the larger side, px")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--scenes-dir", default="scenes")
    ap.add_argument("--dev-scenes", action="store_true", help="also render tools/mitsuba/dev_scenes/*.xml")
    ap.add_argument("--material", action="append", default=[], help="a material.xml to render on the template scene")
    ap.add_argument("--only", action="append", default=[], help="render only these scene names")
    ap.add_argument("--out", default="tests/references")
    ap.add_argument("--bench", help="scene file to time (bench mode)")
    ap.add_argument("--out-dir", help="bench mode: where to write the EXRs")
    ap.add_argument("--json", action="store_true", help="bench mode: print JSON")
    ap.add_argument("--skip-tmm-check", action="store_true")
    ap.add_argument("--sampler", help="bench mode: Mitsuba sampler type (default: the scene's)")
    ap.add_argument("--repeats", type=int, default=1,
                    help="bench mode: renders per spp, run j with seed SEED + j; the fastest "
                         "time is reported, and each run's EXR is written")
    args = ap.parse_args()

    variant = thinfilm_mitsuba.setup(args.variant)
    import mitsuba as mi

    log = (lambda *a: print(*a, file=sys.stderr)) if args.json else print
    if not args.skip_tmm_check:
        log("checking the plugin's Airy reflectance against tmm …")
        thinfilm_mitsuba.check_against_tmm(mi, log=log)

    if args.bench:
        spps = [int(s) for s in args.spp.split(",")]
        scene = mi.load_file(args.bench)
        sampler_type = args.sampler or scene_sampler_type(args.bench)
        sensor, (w, h) = make_sensor(mi, scene, args.size, sampler_type)
        os.makedirs(args.out_dir, exist_ok=True)
        # Warm-up: JIT-compile the kernels once so timings measure rendering.
        render(mi, scene, sensor, min(spps), args.seed + 99)
        results = []
        for spp in spps:
            # Run j uses seed + j: the fastest run is the time, and the error is scored over
            # every run's image (one seed's error is luck where a few pixels hold most of it).
            every, exrs = [], []
            for j in range(args.repeats):
                arr, secs = render(mi, scene, sensor, spp, args.seed + j)
                out = os.path.join(args.out_dir, f"mitsuba_{spp}spp_{j}.exr")
                write_exr(mi, out, arr)
                every.append(secs)
                exrs.append(out)
            secs = min(every)
            results.append({"spp": spp, "seconds": secs, "every_seconds": every, "exrs": exrs})
            log(f"  {spp:5d} spp  {secs:8.3f} s")
        doc = {
            "variant": variant,
            "sampler": sampler_type,
            "mitsuba_version": mi.__version__,
            "width": w,
            "height": h,
            "runs": results,
        }
        print(json.dumps(doc))
        return

    spp = int(args.spp)
    out_dir = os.path.join(REPO, args.out)
    os.makedirs(out_dir, exist_ok=True)
    manifest_path = os.path.join(out_dir, "manifest.json")
    manifest = {"references": {}}
    if os.path.exists(manifest_path):
        with open(manifest_path) as f:
            manifest = json.load(f)
        if not args.only:
            # A full run replaces this script's entries but keeps those another script
            # (render_polarized.py) made.
            manifest["references"] = {
                k: v
                for k, v in manifest["references"].items()
                if any(k.startswith(p) for p in OTHER_SCRIPT)
            }
    command = "python3 " + " ".join(shlex.quote(a) for a in [rel(os.path.abspath(sys.argv[0]))] + sys.argv[1:])
    scenes = scene_list(args)
    if not scenes:
        sys.exit(f"no scenes found in {args.scenes_dir}/ (use --dev-scenes or --material)")
    for name, path, material in scenes:
        log(f"rendering {name} ({rel(path)}) at {spp} spp …")
        scene = mi.load_file(path)
        # The scene's own sampler: with `ldsampler` the reference converges far faster than
        # with independent samples (each 1024-spp pass is an independent randomisation).
        sampler_type = scene_sampler_type(path)
        sensor, (w, h) = make_sensor(mi, scene, args.size, sampler_type)
        arr, secs = render(mi, scene, sensor, spp, args.seed)
        exr = os.path.join(out_dir, f"{name}.exr")
        write_exr(mi, exr, arr)
        log(f"  {w}×{h}, {secs:.1f} s, mean RGB {arr.reshape(-1, 3).mean(0)} → {rel(exr)} ({os.path.getsize(exr) // 1024} KB)")
        manifest["references"][name] = {
            "scene": rel(path),
            "material": rel(material) if material else None,
            "exr": rel(exr),
            "width": w,
            "height": h,
            "spp": spp,
            "sampler": sampler_type,
            "seed": args.seed,
            "rfilter": "box",
            "seconds": round(secs, 2),
        }
    if args.only and "command" in manifest:
        # A partial re-render (--only) keeps the command that regenerates everything.
        command = manifest["command"]
    manifest.update(
        {
            "mitsuba_version": mi.__version__,
            "variant": variant,
            "command": command,
            "plugin": "tools/mitsuba/thinfilm_mitsuba (Airy in float64, checked against tmm)",
        }
    )
    with open(manifest_path + ".partial", "w") as f:
        json.dump(manifest, f, indent=2, sort_keys=True)
    os.replace(manifest_path + ".partial", manifest_path)
    lines = [
        "# Mitsuba 3 reference renders",
        "",
        "Generated by `tools/mitsuba/render_references.py` (header explains every option) with the",
        "Python `thinfilm` BSDF plugin package `tools/mitsuba/thinfilm_mitsuba`. Do not edit by hand.",
        "",
        f"- Mitsuba {mi.__version__}, variant `{variant}`",
        f"- command (from the repository root, with `DRJIT_LIBLLVM_PATH` set): `{command}`",
        "",
        "| name | scene | size | spp | seed | seconds |",
        "|---|---|---|---|---|---|",
    ]
    for name, r in sorted(manifest["references"].items()):
        lines.append(f"| {name} | `{r['scene']}` | {r['width']}×{r['height']} | {r['spp']} | {r['seed']} | {r['seconds']} |")
    with open(os.path.join(out_dir, "README.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    log(f"wrote {rel(manifest_path)}")


if __name__ == "__main__":
    main()
