#!/bin/sh
# Regenerates docs/img/gltf_suzanne_thinfilm.png, thinfilm's render of Khronos'
# IridescenceSuzanne (CC0) for the README beside the glTF Sample Viewer's golden image
# (docs/img/gltf_suzanne_sample_viewer.png, the Khronos render-fidelity thumbnail, 512×205).
# The file has no camera: the model is framed for the default 512×512 film (a film of
# another shape given by --resolution keeps that framing's vertical field of view), so the
# square render is cropped to the golden image's 512×205 band. Needs python3 with Pillow.
# Run from the repository root.
set -e
out=$(mktemp -d)
cargo run --release --quiet -- render scenes/gltf/IridescenceSuzanne/IridescenceSuzanne.gltf \
    --spp 256 --quiet -o "$out/suzanne.exr"
python3 -c "
import sys
from PIL import Image
im = Image.open(sys.argv[1])
top = (im.height - 205) // 2
im.crop((0, top, 512, top + 205)).save(sys.argv[2])
" "$out/suzanne.png" docs/img/gltf_suzanne_thinfilm.png
rm -r "$out"
echo "wrote docs/img/gltf_suzanne_thinfilm.png"
