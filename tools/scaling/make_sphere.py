#!/usr/bin/env python3
"""Writes a UV sphere of about N triangles as a binary PLY (positions + normals, float32;
`uchar int` triangle lists) and a Mitsuba 3 scene that renders it in the studio environment,
for the scaling tables of docs/performance.md:

    python3 tools/scaling/make_sphere.py --triangles 2000000 --out /tmp/sphere2m
    thinfilm render /tmp/sphere2m/scene.xml -o /tmp/sphere2m.exr
    mitsuba /tmp/sphere2m/scene.xml   # same scene, same spp

Only numpy is needed. The scene references the repository's studio.exr by absolute path.
"""
import argparse
import math
import os

import numpy as np


def sphere(n_tris):
    # 2·nu·(nv − 1) triangles with nv ≈ nu / 2 rings (poles as degenerate-free fans).
    nu = max(4, int(round(math.sqrt(n_tris))))
    nv = max(3, nu // 2 + 1)
    theta = np.linspace(0.0, math.pi, nv + 1)[1:-1]  # inner rings
    phi = np.linspace(0.0, 2.0 * math.pi, nu, endpoint=False)
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring = np.stack(
        [st * np.cos(phi)[None, :], ct * np.ones_like(phi)[None, :], st * np.sin(phi)[None, :]],
        axis=-1,
    ).reshape(-1, 3)
    pos = np.concatenate([[[0.0, 1.0, 0.0]], ring, [[0.0, -1.0, 0.0]]]).astype(np.float32)
    rings = nv - 1
    idx = []
    j = np.arange(nu)
    j1 = (j + 1) % nu
    first = 1
    idx.append(np.stack([np.zeros(nu, dtype=np.int64), first + j1, first + j], axis=-1))
    for r in range(rings - 1):
        a, b = first + r * nu, first + (r + 1) * nu
        idx.append(np.stack([a + j, a + j1, b + j], axis=-1))
        idx.append(np.stack([a + j1, b + j1, b + j], axis=-1))
    last = len(pos) - 1
    a = first + (rings - 1) * nu
    idx.append(np.stack([a + j, a + j1, np.full(nu, last)], axis=-1))
    return pos, np.concatenate(idx).astype(np.int32)


def write_ply(path, pos, tris):
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(pos)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        f"element face {len(tris)}\n"
        "property list uchar int vertex_indices\nend_header\n"
    )
    verts = np.concatenate([pos, pos], axis=1).astype("<f4")  # unit sphere: n = p
    faces = np.zeros(len(tris), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"] = 3
    faces["i"] = tris
    with open(path, "wb") as f:
        f.write(header.encode())
        f.write(verts.tobytes())
        f.write(faces.tobytes())


SCENE = """<scene version="3.0.0">
    <default name="spp" value="{spp}"/>
    <default name="res" value="{res}"/>
    <integrator type="path"><integer name="max_depth" value="8"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="35"/>
        <transform name="to_world"><lookat origin="0, 1, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="$res"/><integer name="height" value="$res"/>
            <string name="pixel_format" value="rgb"/><rfilter type="box"/>
        </film>
    </sensor>
    <emitter type="envmap"><string name="filename" value="{env}"/></emitter>
    <shape type="ply">
        <string name="filename" value="sphere.ply"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.75, 0.45, 0.2"/></bsdf>
    </shape>
</scene>
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--triangles", type=int, default=2_000_000)
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--res", type=int, default=256)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    pos, tris = sphere(a.triangles)
    write_ply(os.path.join(a.out, "sphere.ply"), pos, tris)
    env = os.path.abspath(os.path.join(os.path.dirname(__file__), "../../scenes/textures/studio.exr"))
    with open(os.path.join(a.out, "scene.xml"), "w") as f:
        f.write(SCENE.format(spp=a.spp, res=a.res, env=env))
    print(f"{len(tris)} triangles, {len(pos)} vertices -> {a.out}")


if __name__ == "__main__":
    main()
