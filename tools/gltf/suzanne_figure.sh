#!/bin/sh
# Regenerates docs/img/gltf_suzanne_thinfilm.png, thinfilm's render of Khronos'
# IridescenceSuzanne (CC0) for the README beside the glTF Sample Viewer's golden image
# (docs/img/gltf_suzanne_sample_viewer.png, the Khronos render-fidelity thumbnail, 512×205).
# Run from the repository root.
set -e
out=$(mktemp -d)
cargo run --release --quiet -- render scenes/gltf/IridescenceSuzanne/IridescenceSuzanne.gltf \
    --spp 256 --resolution 512x205 --quiet -o "$out/suzanne.exr"
cp "$out/suzanne.png" docs/img/gltf_suzanne_thinfilm.png
rm -r "$out"
echo "wrote docs/img/gltf_suzanne_thinfilm.png"
