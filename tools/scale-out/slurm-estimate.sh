#!/bin/bash
# Fits a capture too large for one job, in two phases (see docs/scale-out.md):
#   1. the film index from one band of rows (ROWS, e.g. 480:544: a band of typical film),
#      into OUT_DIR/index;
#   2. every one of N row bands with that index, as a job array (with a known index a band's
#      thickness equals the same rows of a single fit, bit for bit) into OUT_DIR/bands, then
#      a merge job that makes the whole fit folder OUT_DIR/fit (fit.json, thickness.exr,
#      material.xml, material.gltf).
#
#   tools/scale-out/slurm-estimate.sh CAPTURE ROWS N OUT_DIR [estimate options]
#
# Phase 2 is submitted by a small job that starts when phase 1 has succeeded (it needs the
# index). THINFILM and SBATCH_OPTS as in slurm-render.sh.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
capture=$1 rows=$2 n=$3 out=$4
shift 4
thinfilm=${THINFILM:-thinfilm}
extra="$*"
mkdir -p "$out"
# shellcheck disable=SC2086
index=$(sbatch --parsable ${SBATCH_OPTS:-} --job-name=thinfilm-index --output="$out/%x-%j.log" \
    --wrap "$thinfilm estimate $capture --rows $rows --out $out/index --quiet $extra")
bands=$(for ((k = 0; k < n; k++)); do printf '%s ' "$out/bands/band-$k"; done)
# The index is fit.json's "film_ior" (written with full precision).
phase2="set -eu
film_ior=\$(sed -n 's/^ *\"film_ior\": *\([-0-9.eE+]*\),*\$/\1/p' $out/index/fit.json)
array=\$(sbatch --parsable ${SBATCH_OPTS:-} --array=0-$((n - 1)) --output=$out/%x-%A_%a.log \
    --export=ALL,THINFILM=$thinfilm $here/estimate-array.sbatch $capture \$film_ior $out/bands $extra)
sbatch --parsable ${SBATCH_OPTS:-} --job-name=thinfilm-merge --output=$out/%x-%j.log \
    --dependency=afterok:\$array --wrap '$thinfilm merge $bands-o $out/fit'"
# shellcheck disable=SC2086
submit=$(sbatch --parsable ${SBATCH_OPTS:-} --job-name=thinfilm-bands --output="$out/%x-%j.log" \
    --dependency=afterok:"$index" --wrap "$phase2")
echo "index job $index, band submission job $submit -> $out/fit"
