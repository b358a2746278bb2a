#!/bin/bash
# Renders SCENE at SPP samples per pixel as a Slurm job array of N tasks, then merges the
# parts into IMAGE.exr with a job that runs once every task has succeeded (see
# docs/scale-out.md). Bit-identical to one render when SPP and N are powers of two.
#
#   tools/scale-out/slurm-render.sh SCENE SPP N IMAGE.exr [render options, e.g. -D res=512]
#
# THINFILM: the thinfilm binary (default: thinfilm on PATH). SBATCH_OPTS: extra sbatch
# options, e.g. SBATCH_OPTS="--partition=cpu --time=02:00:00 --cpus-per-task=32".
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
scene=$1 spp=$2 n=$3 image=$4
shift 4
thinfilm=${THINFILM:-thinfilm}
parts="${image%.exr}.parts"
mkdir -p "$parts"
# shellcheck disable=SC2086
array=$(sbatch --parsable ${SBATCH_OPTS:-} --array=0-$((n - 1)) --output="$parts/%x-%A_%a.log" \
    --export=ALL,THINFILM="$thinfilm" "$here/render-array.sbatch" "$scene" "$spp" "$parts" "$@")
pieces=$(for ((k = 0; k < n; k++)); do printf '%s ' "$parts/part-$k.exr"; done)
# shellcheck disable=SC2086
merge=$(sbatch --parsable ${SBATCH_OPTS:-} --job-name=thinfilm-merge --output="$parts/%x-%j.log" \
    --dependency=afterok:"$array" --wrap "$thinfilm merge $pieces-o $image")
echo "render array $array, merge job $merge -> $image"
