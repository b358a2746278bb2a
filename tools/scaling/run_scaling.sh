#!/bin/sh
# Scaling tables of docs/performance.md: whole-process time, set-up, render stage and peak
# memory of `thinfilm render` against triangle count (UV spheres from make_sphere.py),
# resolution, threads and max depth. Usage: tools/scaling/run_scaling.sh [THINFILM] [OUTDIR]
set -eu
BIN=${1:-target/release/thinfilm}
OUT=${2:-/tmp/thinfilm-scaling}
HERE=$(dirname "$0")
mkdir -p "$OUT"

# One render: prints "wall_s cpu_s setup_s render_s peak_MB".
run() {
    /usr/bin/time -f "TIME %e %U %S %M" "$BIN" render "$@" -o "$OUT/out.exr" >"$OUT/log" 2>&1
    awk '/^rendered/ { for (i = 1; i <= NF; i++) { if ($i == "in") r = $(i + 1); if ($i ~ /^\(\+/) { s = substr($i, 3) } } }
         /^TIME/ { printf "%.2f %.2f %s %s %.0f\n", $2, $3 + $4, s, r, $5 / 1024 }' "$OUT/log"
}

echo "| triangles | wall s | CPU s | set-up s | render s | peak MB | bytes / triangle |"
echo "|---:|---:|---:|---:|---:|---:|---:|"
for n in 1000 10000 100000 1000000 5000000; do
    python3 "$HERE/make_sphere.py" --triangles $n --out "$OUT/s$n" >/dev/null
    set -- $(run "$OUT/s$n/scene.xml" --spp 4)
    echo "| $n | $1 | $2 | $3 | $4 | $5 | $(awk "BEGIN { printf \"%.0f\", $5 * 1048576 / $n }") |"
done

S="$OUT/s100000/scene.xml"
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
