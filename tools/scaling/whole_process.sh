#!/bin/sh
# Whole `thinfilm render` process (start, load, set-up, render, EXR + PNG) against Mitsuba's
# warm render call (tools/mitsuba/render_references.py --bench: JIT warmed, render only), same
# scene, spp, size and independent sampler, one after the other, REPEATS runs each (Mitsuba:
# fastest warm call; ours: median process).
# Usage: tools/scaling/whole_process.sh "BIN_A BIN_B ..." [SPP] [SIZE] [REPEATS] SCENE...
set -eu
BINS=$1; SPP=${2:-64}; SIZE=${3:-256}; REP=${4:-3}; shift 4
export DRJIT_LIBLLVM_PATH=${DRJIT_LIBLLVM_PATH:-/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1}
T=$(mktemp -d)
median() { sort -n | awk '{ a[NR] = $1 } END { print a[int((NR + 1) / 2)] }'; }
for scene in "$@"; do
    mits=$(python3 tools/mitsuba/render_references.py --bench "$scene" --spp "$SPP" --size "$SIZE" \
        --sampler independent --repeats "$REP" --json --skip-tmm-check --out-dir "$T" 2>/dev/null |
        grep '^{' | tail -1 | python3 -c 'import json,sys; print(min(r["seconds"] for r in json.load(sys.stdin)["runs"]))')
    line="$(basename "$scene" .xml) | Mitsuba $mits s"
    for b in $BINS; do
        for i in $(seq "$REP"); do
            /usr/bin/time -f "%e" "$b" render "$scene" --sampler independent --spp "$SPP" \
                --resolution "${SIZE}x$SIZE" --quiet -o "$T/o.exr" 2>&1 >/dev/null | tail -1
        done > "$T/times"
        t=$(median < "$T/times")
        line="$line | $b $t s ($(awk "BEGIN { printf \"%.2f\", $t / $mits }")×)"
    done
    echo "$line"
done
rm -rf "$T"
