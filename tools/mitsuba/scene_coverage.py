#!/usr/bin/env python3
"""Scene coverage: does `thinfilm render` draw real Mitsuba 3 scenes as Mitsuba 3 draws them?

For every scene of a corpus of real Mitsuba 3 scenes written by others
(tools/mitsuba/scene_corpus.json: Mitsuba's documentation and test scenes, its tutorials,
users' copies of Benedikt Bitterli's scenes), this script

1. renders the scene *unchanged* with Mitsuba 3 (variant llvm_ad_spectral) at 64 spp and
   128 px wide (height keeps the film's aspect ratio), twice, with seeds 0 and 1 — the only
   edits are the film's width/height and the sample count, made on Mitsuba's parsed scene
   graph, so the scene's own camera, filter, sampler type and integrator are used;
2. renders it with `thinfilm render SCENE --spp 64 --resolution WxH --seed 0` (same -D
   parameters);
3. compares: mean ΔE00 (`thinfilm compare`) of thinfilm against Mitsuba seed 0, next to
   Mitsuba seed 1 against seed 0 (Mitsuba's own seed-to-seed noise at this spp), and the
   ratio of mean luminances (Rec. 709 Y).

A scene **agrees** when ΔE00(thinfilm, Mitsuba) ≤ ΔE00(Mitsuba seed 1, seed 0) + 0.3 and its
mean luminance is within 2 % of Mitsuba's (the report also shows Mitsuba's own seed-to-seed
luminance difference, which for scenes lit by small bright lights can exceed 2 % at 64 spp).

Per scene it reports: loads? renders? the first error thinfilm printed (the blocker), the
metrics; then the blockers tallied by number of scenes, and the Mitsuba plugins used by the
scenes that do not render (what is left to implement).

Set-up (clone the corpus sources at the commits in scene_corpus.json, under one root whose
sub-directory names are the source keys):

    mkdir -p ~/mitsuba-corpus && cd ~/mitsuba-corpus
    git clone https://github.com/mitsuba-renderer/mitsuba-data
    git clone https://github.com/mitsuba-renderer/mitsuba-tutorials
    git clone https://github.com/takkasila/practical_path_guiding_lab
    (then `git -C NAME checkout COMMIT` for each, as listed in the JSON)

Run (from the repository root, after `cargo build --release`):

    export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
    python3 tools/mitsuba/scene_coverage.py --corpus-root ~/mitsuba-corpus \\
        --out target/scene_coverage --report target/scene_coverage/report.md

Mitsuba's renders are cached in --out (keyed by scene, size, spp and seed); --rerender-mitsuba
redoes them. --only NAME (repeatable, substring match) restricts the corpus.

Reference mode (the committed CI references of tests/scene_coverage.rs):

    python3 tools/mitsuba/scene_coverage.py --references tests/scenes_real \\
        --ref-spp 4096 --width 64

renders every scene listed in tests/scenes_real/manifest.json with Mitsuba 3 at that width
and spp (seed 0) into tests/scenes_real/references/NAME.exr and records the command,
Mitsuba's version and the timings in the manifest.
"""

import argparse
import json
import math
import os
import re
import shlex
import subprocess
import sys
import time
from collections import Counter

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.abspath(os.path.join(HERE, "..", ".."))
VARIANT = "llvm_ad_spectral"
DELTA_E_MARGIN = 0.3
LUMINANCE_TOLERANCE = 0.02


def setup_mitsuba():
    os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")
    import mitsuba as mi

    mi.set_variant(VARIANT)
    return mi


# ------------------------------------------------------------------------------ Mitsuba side


def parse_scene(mi, path, params):
    """Mitsuba's parsed scene graph of `path` (its directory on the file resolver, as
    mi.load_file does), or raises."""
    cfg = mi.parser.ParserConfig(mi.variant())
    state = mi.parser.parse_file(cfg, path, **params)
    return cfg, state


def film_node(mi, state):
    for node in state.nodes:
        if node.type == mi.ObjectType.Film:
            return node
    return None


def output_size(mi, state, width):
    """(W, H): `width` px wide, height keeping the film's aspect ratio (Mitsuba's hdrfilm
    defaults to 768×576)."""
    film = film_node(mi, state)
    fw, fh = 768, 576
    if film is not None:
        props = film.props
        if "width" in props:
            fw = int(props["width"])
        if "height" in props:
            fh = int(props["height"])
    return width, max(1, round(width * fh / fw))


def plugins_used(mi, state):
    """Sorted 'kind:plugin' names of every object in the parsed scene (includes resolved)."""
    out = set()
    for node in state.nodes:
        name = node.props.plugin_name()
        if node.type == mi.ObjectType.Scene or not name:
            continue
        kind = str(node.type).split(".")[-1].lower()
        out.add(f"{kind}:{name}")
    return sorted(out)


def with_resolver(mi, path, fn):
    fr_backup = mi.file_resolver()
    fr = mi.FileResolver(fr_backup)
    fr.prepend(os.path.dirname(os.path.abspath(path)))
    mi.set_file_resolver(fr)
    try:
        return fn()
    finally:
        mi.set_file_resolver(fr_backup)


def mitsuba_render(mi, path, params, size, spp, seeds):
    """Renders the scene unchanged except for film size and sample count. Returns a list
    of H×W×3 float32 arrays, one per seed, and the seconds per render."""
    import drjit as dr
    import numpy as np

    def run():
        cfg, state = parse_scene(mi, path, params)
        film = film_node(mi, state)
        if film is None:
            raise RuntimeError("the scene has no film (Mitsuba renders nothing without a sensor)")
        film.props["width"] = size[0]
        film.props["height"] = size[1]
        mi.parser.transform_all(cfg, state)
        scene = mi.parser.instantiate(cfg, state)
        images, secs = [], []
        for seed in seeds:
            t0 = time.perf_counter()
            img = mi.render(scene, spp=spp, seed=seed)
            dr.eval(img)
            arr = np.array(img, dtype=np.float32)
            secs.append(time.perf_counter() - t0)
            if arr.ndim == 2:
                arr = arr[:, :, None]
            if arr.shape[2] == 1:
                arr = np.repeat(arr, 3, axis=2)
            images.append(np.ascontiguousarray(arr[:, :, :3]))
        return images, secs

    return with_resolver(mi, path, run)


def write_exr(mi, path, arr):
    import numpy as np

    bmp = mi.Bitmap(np.ascontiguousarray(arr, dtype=np.float32), mi.Bitmap.PixelFormat.RGB)
    tmp = path + ".partial.exr"
    bmp.write(tmp)
    os.replace(tmp, path)


def read_exr(mi, path):
    import numpy as np

    return np.array(mi.Bitmap(path), dtype=np.float64)[:, :, :3]


def luminance(arr):
    return float((arr[:, :, 0] * 0.2126 + arr[:, :, 1] * 0.7152 + arr[:, :, 2] * 0.0722).mean())


# ------------------------------------------------------------------------------ thinfilm side


def thinfilm_render(exe, path, params, size, spp, seed, out, timeout):
    """Runs `thinfilm render`; returns (ok, seconds, first error line, full stderr)."""
    cmd = [exe, "render", path, "--spp", str(spp), "--seed", str(seed),
           "--resolution", f"{size[0]}x{size[1]}", "-o", out]
    for k, v in params.items():
        cmd += ["-D", f"{k}={v}"]
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return False, timeout, f"timed out after {timeout} s", ""
    secs = time.perf_counter() - t0
    if p.returncode == 0 and os.path.exists(out):
        return True, secs, "", p.stderr
    lines = [ln.strip() for ln in p.stderr.splitlines() if ln.strip()]
    err = next((ln for ln in lines if ln.lower().startswith("error")), lines[-1] if lines else "")
    return False, secs, err, p.stderr


def thinfilm_delta_e(exe, a, b):
    p = subprocess.run([exe, "compare", "--json", a, b], capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(p.stderr.strip())
    return json.loads(p.stdout)["metrics"]["delta_e00_mean"]


# Blocker names from thinfilm's messages; the first matching pattern names the blocker.
BLOCKER_PATTERNS = [
    (r'unsupported element <(\w+)>', lambda m: f"<{m.group(1)}>"),
    (r'unsupported (\w+) plugin "([\w.]+)"', lambda m: f'{m.group(1)} "{m.group(2)}"'),
    (r"unknown parameter '(\w+)' \((\w+)\) for (\w+) plugin \"(\w+)\"",
     lambda m: f"{m.group(1)} on {m.group(3)} \"{m.group(4)}\""),
    (r"unsupported value for '(\w+)' of (\w+) plugin \"(\w+)\"",
     lambda m: f"{m.group(1)} ≠ default on {m.group(2)} \"{m.group(3)}\""),
    (r'(\w+) "(\w+)": the Beckmann microfacet distribution',
     lambda m: f'Beckmann distribution on {m.group(1)} "{m.group(2)}"'),
    (r'(\w+) "(\w+)": anisotropic roughness', lambda m: f'anisotropic {m.group(1)} "{m.group(2)}"'),
    (r"'(\w+)' of (\w+) \"(\w+)\" must be a number or a <spectrum>.*not rgb",
     lambda m: f'RGB {m.group(1)} on {m.group(2)} "{m.group(3)}"'),
    (r'is not supported|unsupported', lambda m: None),
]


def blocker_name(err):
    for pat, name in BLOCKER_PATTERNS:
        m = re.search(pat, err)
        if m:
            n = name(m)
            if n:
                return n
            break
    # Keep what follows the last location "file.xml:line:col: <elem>: " (or the
    # "rendering FILE: " prefix of a render-time error).
    short = re.sub(r"^error:\s*", "", err, flags=re.I)
    short = re.split(r"\S+\.xml:\d+:\d+:\s*(?:<[^>]*>:\s*)?", short)[-1]
    short = re.sub(r"^rendering \S+:\s*(BSDF \d+:\s*)?", "", short)
    return short[:90]


# ------------------------------------------------------------------------------ coverage


def scene_name(entry):
    src = entry["source"]
    p = entry["path"]
    p = re.sub(r"^(docs/scenes|tests/scenes|scenes)/", "", p)
    return f"{src}/{os.path.splitext(p)[0]}"


def evaluate(args, mi, exe, entry, out_dir):
    name = scene_name(entry)
    path = os.path.join(args.corpus_root, entry["source"], entry["path"])
    params = entry.get("params", {})
    rec = {"name": name, "scene": f"{entry['source']}:{entry['path']}", "params": params}
    safe = re.sub(r"[^\w.-]+", "_", name)
    # Scenes with a polariser are compared with Mitsuba's polarised variant: thinfilm renders
    # every scene holding a polariser with its polarised integrator (the intensity S0).
    variant = entry.get("variant", VARIANT)
    mi.set_variant(variant)
    if variant != VARIANT:
        rec["variant"] = variant
        safe += "." + variant
    # Mitsuba: parse for the size and plugin inventory, then render (cached).
    try:
        _, state = with_resolver(mi, path, lambda: parse_scene(mi, path, params))
        size = output_size(mi, state, args.width)
        rec["plugins"] = plugins_used(mi, state)
    except Exception as e:  # noqa: BLE001 — reported, not fatal
        rec["mitsuba_error"] = str(e).splitlines()[0][:300]
        return rec
    rec["size"] = list(size)
    seeds = [0, 1]
    mi_exr = [os.path.join(out_dir, f"{safe}.mitsuba.{size[0]}x{size[1]}.{args.spp}spp.seed{s}.exr") for s in seeds]
    if args.rerender_mitsuba or not all(os.path.exists(p) for p in mi_exr):
        try:
            images, secs = mitsuba_render(mi, path, params, size, args.spp, seeds)
        except Exception as e:  # noqa: BLE001
            rec["mitsuba_error"] = str(e).splitlines()[0][:300]
            return rec
        for p, img in zip(mi_exr, images):
            write_exr(mi, p, img)
        rec["mitsuba_seconds"] = round(min(secs), 2)
    ours = os.path.join(out_dir, f"{safe}.thinfilm.exr")
    if os.path.exists(ours):
        os.remove(ours)
    ok, secs, err, stderr = thinfilm_render(exe, path, params, size, args.spp, 0, ours, args.timeout)
    rec["thinfilm_seconds"] = round(secs, 2)
    rec["loads"] = ok or not re.search(r"\.xml:\d+:\d+|scene file|reading|malformed|unsupported|unknown", err)
    rec["renders"] = ok
    warnings = sorted({ln.strip() for ln in stderr.splitlines() if ln.strip().lower().startswith("warning")})
    rec["warnings"] = warnings[:8]
    if not ok:
        rec["error"] = err
        rec["blocker"] = blocker_name(err)
        return rec
    a, b = read_exr(mi, mi_exr[0]), read_exr(mi, mi_exr[1])
    t = read_exr(mi, ours)
    rec["delta_e"] = round(thinfilm_delta_e(exe, ours, mi_exr[0]), 3)
    rec["delta_e_noise"] = round(thinfilm_delta_e(exe, mi_exr[1], mi_exr[0]), 3)
    la, lb, lt = luminance(a), luminance(b), luminance(t)
    rec["lum_ratio"] = round(lt / la, 4) if la > 0 else (1.0 if lt == 0 else math.inf)
    rec["lum_ratio_noise"] = round(lb / la, 4) if la > 0 else 1.0
    rec["agrees_delta_e"] = rec["delta_e"] <= rec["delta_e_noise"] + DELTA_E_MARGIN
    rec["agrees_lum"] = abs(rec["lum_ratio"] - 1) <= LUMINANCE_TOLERANCE
    rec["agrees"] = rec["agrees_delta_e"] and rec["agrees_lum"]
    return rec


def report(results, args):
    with_ref = [r for r in results if "mitsuba_error" not in r]
    rendered = [r for r in with_ref if r.get("renders")]
    agree = [r for r in rendered if r.get("agrees")]
    agree_noise_lum = [r for r in rendered if r["agrees_delta_e"]
                       and abs(r["lum_ratio"] - 1) <= LUMINANCE_TOLERANCE + abs(r["lum_ratio_noise"] - 1)]
    lines = [
        "# Mitsuba 3 scene coverage",
        "",
        f"`tools/mitsuba/scene_coverage.py`: Mitsuba 3 `{VARIANT}` vs `thinfilm render`, {args.spp} spp, "
        f"{args.width} px wide, Mitsuba seeds 0 and 1.",
        "",
        f"- scenes in the corpus: {len(results)}; Mitsuba renders {len(with_ref)}",
        f"- thinfilm renders unchanged: **{len(rendered)} / {len(with_ref)}**",
        f"- of those, agree with Mitsuba (ΔE00 ≤ noise + {DELTA_E_MARGIN}, luminance within "
        f"{LUMINANCE_TOLERANCE:.0%}): **{len(agree)} / {len(rendered)}**"
        + (f" ({100 * len(agree) / len(rendered):.0f} %)" if rendered else ""),
        f"- with the luminance tolerance widened by Mitsuba's own seed-to-seed difference: "
        f"{len(agree_noise_lum)} / {len(rendered)}",
        "",
        "| scene | renders | ΔE00 | noise ΔE00 | lum ratio | noise lum ratio | agrees | blocker / note |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        if "mitsuba_error" in r:
            lines.append(f"| {r['name']} | – | | | | | | Mitsuba fails: {r['mitsuba_error'][:80]} |")
        elif not r["renders"]:
            lines.append(f"| {r['name']} | no | | | | | | {r['blocker']} |")
        else:
            note = "; ".join(w[:70] for w in r["warnings"][:2])
            lines.append(
                f"| {r['name']} | yes | {r['delta_e']:.2f} | {r['delta_e_noise']:.2f} | {r['lum_ratio']:.3f} "
                f"| {r['lum_ratio_noise']:.3f} | {'yes' if r['agrees'] else '**no**'} | {note} |"
            )
    blockers = Counter(r["blocker"] for r in with_ref if not r.get("renders"))
    lines += ["", "## First blocker, by number of scenes", "", "| blocker | scenes |", "|---|---|"]
    lines += [f"| {b} | {n} |" for b, n in blockers.most_common()]
    failing_plugins = Counter(p for r in with_ref if not r.get("renders") for p in r.get("plugins", []))
    ok_plugins = {p for r in rendered for p in r.get("plugins", [])}
    lines += ["", "## Plugins used by scenes that do not render (and by none that does)", "",
              "| plugin | scenes |", "|---|---|"]
    lines += [f"| {p} | {n} |" for p, n in failing_plugins.most_common() if p not in ok_plugins]
    return "\n".join(lines) + "\n"


def coverage(args):
    mi = setup_mitsuba()
    with open(args.corpus) as f:
        corpus = json.load(f)
    entries = corpus["scenes"]
    if args.only:
        entries = [e for e in entries if any(o in scene_name(e) for o in args.only)]
    os.makedirs(args.out, exist_ok=True)
    exe = os.path.abspath(args.thinfilm)
    results = []
    for i, entry in enumerate(entries):
        rec = evaluate(args, mi, exe, entry, args.out)
        results.append(rec)
        status = ("MITSUBA FAILS" if "mitsuba_error" in rec else
                  "agrees" if rec.get("agrees") else
                  "differs" if rec.get("renders") else f"blocked: {rec.get('blocker')}")
        extra = (f" ΔE {rec['delta_e']:.2f} (noise {rec['delta_e_noise']:.2f}), lum {rec['lum_ratio']:.3f}"
                 if rec.get("renders") else "")
        print(f"[{i + 1}/{len(entries)}] {rec['name']}: {status}{extra}", file=sys.stderr, flush=True)
    with open(os.path.join(args.out, "coverage.json"), "w") as f:
        json.dump(results, f, indent=1)
    text = report(results, args)
    if args.report:
        with open(args.report, "w") as f:
            f.write(text)
    print(text)


# ------------------------------------------------------------------------------ CI references


def references(args):
    """Renders the Mitsuba references of the committed real scenes (reference mode)."""
    mi = setup_mitsuba()
    root = os.path.abspath(args.references)
    manifest_path = os.path.join(root, "manifest.json")
    with open(manifest_path) as f:
        manifest = json.load(f)
    os.makedirs(os.path.join(root, "references"), exist_ok=True)
    command = "python3 " + " ".join(shlex.quote(a) for a in
                                     [os.path.relpath(os.path.abspath(sys.argv[0]), REPO)] + sys.argv[1:])
    for name, entry in sorted(manifest["scenes"].items()):
        if args.only and not any(o in name for o in args.only):
            continue
        path = os.path.join(root, entry["scene"])
        params = entry.get("params", {})
        _, state = with_resolver(mi, path, lambda: parse_scene(mi, path, params))
        size = output_size(mi, state, args.width)
        print(f"rendering {name} at {size[0]}×{size[1]}, {args.ref_spp} spp …", file=sys.stderr, flush=True)
        # At most 1024 spp per pass (memory of the llvm variant), each pass its own seed.
        passes = max(1, math.ceil(args.ref_spp / 1024))
        acc, secs = None, 0.0
        for i in range(passes):
            n = args.ref_spp // passes + (1 if i < args.ref_spp % passes else 0)
            (img,), (s,) = mitsuba_render(mi, path, params, size, n, [1000003 * i])
            acc = img.astype("float64") * n if acc is None else acc + img * n
            secs += s
        exr = os.path.join(root, "references", f"{name}.exr")
        write_exr(mi, exr, (acc / args.ref_spp).astype("float32"))
        entry.update({"reference": os.path.relpath(exr, root), "width": size[0], "height": size[1],
                      "spp": args.ref_spp, "seconds": round(secs, 1)})
    if args.only and "command" in manifest:
        command = manifest["command"]  # a partial re-render keeps the full command
    manifest.update({"mitsuba_version": mi.__version__, "variant": VARIANT, "command": command})
    with open(manifest_path + ".partial", "w") as f:
        json.dump(manifest, f, indent=2, sort_keys=True)
        f.write("\n")
    os.replace(manifest_path + ".partial", manifest_path)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", default=os.path.join(HERE, "scene_corpus.json"))
    ap.add_argument("--corpus-root", help="directory holding one clone per corpus source")
    ap.add_argument("--out", default=os.path.join(REPO, "target", "scene_coverage"))
    ap.add_argument("--report", help="write the Markdown report here too")
    ap.add_argument("--thinfilm", default=os.path.join(REPO, "target", "release", "thinfilm"))
    ap.add_argument("--width", type=int, default=128, help="image width, px")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--timeout", type=int, default=600, help="seconds per thinfilm render")
    ap.add_argument("--only", action="append", default=[], help="scene name substring (repeatable)")
    ap.add_argument("--rerender-mitsuba", action="store_true", help="ignore cached Mitsuba renders")
    ap.add_argument("--report-only", action="store_true",
                    help="rewrite the report from --out's coverage.json (no rendering)")
    ap.add_argument("--references", help="reference mode: a directory with manifest.json")
    ap.add_argument("--ref-spp", type=int, default=4096, help="reference mode: samples per pixel")
    args = ap.parse_args()
    if args.references:
        references(args)
    elif args.report_only:
        with open(os.path.join(args.out, "coverage.json")) as f:
            results = json.load(f)
        for r in results:
            if r.get("error"):
                r["blocker"] = blocker_name(r["error"])
        text = report(results, args)
        if args.report:
            with open(args.report, "w") as f:
                f.write(text)
        print(text)
    elif args.corpus_root:
        coverage(args)
    else:
        ap.error("give --corpus-root (coverage) or --references (CI references)")


if __name__ == "__main__":
    main()
