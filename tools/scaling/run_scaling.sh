#!/bin/sh
# Scaling tables of docs/performance.md: whole-process time, set-up, render stage and peak
# memory of `thinfilm render` against triangle count (Newell's teapot subdivided, written by
# `cargo run --release --example teapot_ply`, in the teapot_diffuse scene: studio
# environment, diffuse), beside the `mitsuba` command line on the same files; then
# resolution, threads and max depth on the 100k-triangle teapot.
# Usage: tools/scaling/run_scaling.sh [THINFILM] [OUTDIR] (from the repository root; MITSUBA=
# empty skips the Mitsuba column).
set -eu
BIN=${1:-target/release/thinfilm}
OUT=${2:-/tmp/thinfilm-scaling}
MITSUBA=${MITSUBA-mitsuba}
export DRJIT_LIBLLVM_PATH=${DRJIT_LIBLLVM_PATH:-/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1}
mkdir -p "$OUT"
cargo build --release --quiet --example teapot_ply
ROOT=$(pwd)

# One render: prints "wall_s cpu_s setup_s render_s peak_MB". Uniform sample counts: these
# tables measure throughput per sample, not where the samples go.
run() {
    /usr/bin/time -f "TIME %e %U %S %M" "$BIN" render "$@" --uniform-samples -o "$OUT/out.exr" >"$OUT/log" 2>&1
    awk '/^rendered/ { for (i = 1; i <= NF; i++) { if ($i == "in") r = $(i + 1); if ($i ~ /^\(\+/) { s = substr($i, 3) } } }
         /^TIME/ { printf "%.2f %.2f %s %s %.0f\n", $2, $3 + $4, s, r, $5 / 1024 }' "$OUT/log"
}

# The teapot scene with an N-subdivision teapot: $OUT/tN/scene.xml.
teapot() {
    d="$OUT/t$1"
    if [ ! -f "$d/meshes/teapot.ply" ]; then
        mkdir -p "$d/meshes"
        target/release/examples/teapot_ply "$1" "$d/meshes/teapot.ply" >/dev/null
        cp scenes/teapot_diffuse.xml "$d/scene.xml"
        ln -sfn "$ROOT/scenes/textures" "$d/textures"
    fi
    echo "$d/scene.xml"
}

echo "| triangles | wall s | CPU s | set-up s | render s | peak MiB | bytes / triangle | Mitsuba wall s | Mitsuba peak MiB |"
echo "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
# 32·2·N² − 8·N triangles: 992, 10,712, 102,080, 999,000, 2,003,640, 5,015,360.
for n in 4 13 40 125 177 280; do
    s=$(teapot $n)
    tris=$((64 * n * n - 8 * n))
    set -- $(run "$s" --spp 4)
    m="– | –"
    if [ -n "$MITSUBA" ]; then
        m=$( (cd "$(dirname "$s")" && /usr/bin/time -f "TIME %e %M" "$MITSUBA" scene.xml -D spp=4 -o "$OUT/m.exr" 2>&1 >/dev/null) |
            awk '/^TIME/ { printf "%.2f | %.0f", $2, $3 / 1024 }')
    fi
    echo "| $tris | $1 | $2 | $3 | $4 | $5 | $(awk "BEGIN { printf \"%.0f\", $5 * 1048576 / $tris }") | $m |"
done

S=$(teapot 40)
echo
echo "| resolution (100k triangles, 16 spp) | wall s | render s | µs / sample |"
echo "|---|---:|---:|---:|"
for r in 128 256 512 1024; do
    set -- $(run "$S" --spp 16 --resolution ${r}x$r)
    echo "| ${r}² | $1 | $4 | $(awk "BEGIN { printf \"%.3f\", $4 * 1e6 / ($r * $r * 16) }") |"
done

echo
echo "| threads (100k triangles, 512², 16 spp) | render s | speed-up |"
echo "|---:|---:|---:|"
one=""
for t in 1 2; do
    set -- $(run "$S" --spp 16 --resolution 512x512 --threads $t)
    [ -z "$one" ] && one=$4
    echo "| $t | $4 | $(awk "BEGIN { printf \"%.2f\", $one / $4 }") |"
done

echo
echo "| max depth (100k triangles, 256², 16 spp) | render s |"
echo "|---:|---:|"
for d in 1 2 4 8 16; do
    set -- $(run "$S" --spp 16 --max-depth $d)
    echo "| $d | $4 |"
done
