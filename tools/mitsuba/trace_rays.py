#!/usr/bin/env python3
"""Mitsuba 3's ray queries on the rays `examples/trace_rays.rs` wrote: closest hit
(`ray_intersect_preliminary`) and any hit (`ray_test`), Embree in the LLVM variants, all
cores, wall time per ray, median of five runs after a warm-up (JIT compilation). Each run
shifts the rays' maxt by a different amount far beyond the scene, so that Dr.Jit cannot
reuse an earlier run's result.

    cargo run --release --example trace_rays -- scenes/teapot_diffuse.xml /tmp/rays.f32
    export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
    python3 tools/mitsuba/trace_rays.py scenes/teapot_diffuse.xml /tmp/rays.f32
"""

import argparse
import os
import sys
import time

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("rays", help="RAYS.f32 from examples/trace_rays.rs")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    args = ap.parse_args()
    if not os.path.isfile(args.rays):
        sys.exit(f"{args.rays}: no such file (write it with examples/trace_rays.rs)")
    raw = np.fromfile(args.rays, dtype=np.float32)
    if raw.size == 0 or raw.size % 6:
        sys.exit(f"{args.rays}: {raw.size} floats, not a whole number of rays (6 floats each)")
    a = raw.reshape(-1, 6)
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(args.variant)
    scene = mi.load_file(args.scene)
    n = len(a)
    o = mi.Point3f(*[mi.Float(a[:, i]) for i in range(3)])
    d = mi.Vector3f(*[mi.Float(a[:, i]) for i in range(3, 6)])

    def timed(query, k):
        ray = mi.Ray3f(o, d)
        ray.maxt = mi.Float(1e30 + 1e27 * k)
        dr.eval(ray)
        dr.sync_thread()
        t = time.perf_counter()
        count = dr.count(query(ray))
        dr.eval(count)
        dr.sync_thread()
        return (time.perf_counter() - t) * 1e9 / n, int(count[0] if hasattr(count, "__len__") else count)

    results = {}
    for name, query in (
        ("closest hit", lambda r: scene.ray_intersect_preliminary(r).is_valid()),
        ("any hit", lambda r: scene.ray_test(r)),
    ):
        timed(query, 0)
        runs = sorted(timed(query, k) for k in range(1, 6))
        results[name] = runs[2]
    print(
        f"Mitsuba {mi.__version__} {args.variant} ({dr.thread_count()} threads): "
        + ", ".join(f"{k} {t:.1f} ns/ray ({c} {'hits' if k == 'closest hit' else 'blocked'})" for k, (t, c) in results.items())
        + f", {n} rays"
    )


if __name__ == "__main__":
    main()
