#!/bin/sh
# Renders every Khronos sample with KHR_materials_iridescence at 240×240, 32 spp, from a
# checkout of KhronosGroup/glTF-Sample-Assets given as the first argument, into the
# directory given as the second (default ./khronos-iridescence), and lists the warnings.
# Those files are not part of this repository (licences: CC0 and CC BY 4.0, see each
# sample's LICENSE.md). Run from the repository root.
set -e
assets=${1:?usage: tools/gltf/khronos_iridescence.sh GLTF_SAMPLE_ASSETS_DIR [OUT_DIR]}
out=${2:-khronos-iridescence}
mkdir -p "$out"
cargo build --release --quiet
for m in IridescenceSuzanne IridescenceMetallicSpheres IridescenceDielectricSpheres \
    IridescenceAbalone IridescenceLamp IridescentDishWithOlives; do
    echo "== $m"
    ./target/release/thinfilm render "$assets/Models/$m/glTF/$m.gltf" --spp 32 \
        --resolution 240x240 --quiet -o "$out/$m.exr" 2>&1 | grep -i "warning" || true
done
echo "wrote $out/*.png; compare with $assets/Models/*/screenshot/"
