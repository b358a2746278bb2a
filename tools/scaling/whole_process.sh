#!/bin/sh
# Whole `thinfilm render` process (start, load, set-up, render, EXR + PNG) against Mitsuba's
# warm render call (tools/mitsuba/render_references.py --bench: JIT warmed, render only), same
# scene, spp, size and independent sampler, REPEATS runs each. Printed per binary: the median
# process against Mitsuba's median warm call, and the fastest against the fastest (the
# machine is shared: like statistics on both sides, medians first).
# Usage: tools/scaling/whole_process.sh "BIN_A BIN_B ..." [SPP] [SIZE] [REPEATS] SCENE...
# OURS_SPP=N renders ours at N spp against Mitsuba's SPP (time at equal error, where
# `bench render --mitsuba --sampler independent` shows ours at N spp no noisier).
set -eu
BINS=$1; SPP=${2:-64}; SIZE=${3:-256}; REP=${4:-3}; shift 4
OURS_SPP=${OURS_SPP:-$SPP}
export DRJIT_LIBLLVM_PATH=${DRJIT_LIBLLVM_PATH:-/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1}
T=$(mktemp -d)
median() { sort -n | awk '{ a[NR] = $1 } END { print a[int((NR + 1) / 2)] }'; }
for scene in "$@"; do
    python3 tools/mitsuba/render_references.py --bench "$scene" --spp "$SPP" --size "$SIZE" \
        --sampler independent --repeats "$REP" --json --skip-tmm-check --out-dir "$T" 2>/dev/null |
        grep '^{' | tail -1 |
        python3 -c 'import json,sys; [print(s) for s in json.load(sys.stdin)["runs"][0]["every_seconds"]]' > "$T/mits"
    m_med=$(median < "$T/mits")
    m_min=$(sort -n "$T/mits" | head -1)
    line="$(basename "$scene" .xml) | Mitsuba median $m_med s, fastest $m_min s"
    for b in $BINS; do
        for i in $(seq "$REP"); do
            start=$(date +%s%N)
            "$b" render "$scene" --sampler independent --spp "$OURS_SPP" \
                --resolution "${SIZE}x$SIZE" --quiet -o "$T/o.exr" >/dev/null
            awk "BEGIN { printf \"%.3f\\n\", ($(date +%s%N) - $start) / 1e9 }"
        done > "$T/times"
        t=$(median < "$T/times")
        t_min=$(sort -n "$T/times" | head -1)
        line="$line | $b median $t s ($(awk "BEGIN { printf \"%.2f\", $t / $m_med }")×), fastest $t_min s ($(awk "BEGIN { printf \"%.2f\", $t_min / $m_min }")×)"
    done
    echo "$line"
done
rm -rf "$T"
