#!/usr/bin/env bash
# Runs every hostile-input case of tests/hostile/cases.txt through the thinfilm binary, each
# under a wall-clock limit and an address-space limit, and reports per case and in total:
#
#   ok        refused with exit status 1 (2 for a command-line value clap rejects) and a
#             message naming the culprit (or, for an `ok` case, succeeded)
#   PANIC     exit status 101 or "panicked" on stderr
#   CRASH     killed by a signal (abort, segfault, out of memory)
#   HANG      still running after the time limit
#   MEMORY    peak resident memory above the limit
#   ACCEPTED  exit status 0 where a refusal was expected
#   REFUSED   a non-zero exit where success was expected
#   VAGUE     refused, but the message does not name the file / key / option
#
# Usage: tools/hostile/run.sh [BINARY] [FILTER]
#   BINARY  default target/release/thinfilm (build it first: cargo build --release)
#   FILTER  only cases whose id contains this text
# Environment: HOSTILE_TIMEOUT (seconds, default 20), HOSTILE_MEMORY (bytes, default 2 GiB),
# HOSTILE_VERBOSE=1 prints every case's stderr tail.
set -u
cd "$(dirname "$0")/../.."
BIN=$(realpath "${1:-target/release/thinfilm}")
FILTER=${2:-}
TIMEOUT=${HOSTILE_TIMEOUT:-20}
MEMORY=${HOSTILE_MEMORY:-$((2 * 1024 * 1024 * 1024))}
[ -x "$BIN" ] || { echo "no binary at $BIN (cargo build --release)"; exit 2; }
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
cp -r tests/hostile/corpus "$WORK/corpus"
CORPUS="$WORK/corpus"
declare -A COUNT
TOTAL=0
FAILED=()
while IFS= read -r line; do
    case "$line" in
        '#'* | '') continue ;;
        '@sparse '*)
            read -r _ rel bytes <<<"$line"
            truncate -s "$bytes" "$CORPUS/$rel"
            continue
            ;;
    esac
    IFS=$'\t' read -r id expect args <<<"$line"
    [[ -n "$FILTER" && "$id" != *"$FILTER"* ]] && continue
    out="$WORK/out/$id"
    mkdir -p "$out"
    args=${args//\{C\}/$CORPUS}
    args=${args//\{O\}/$out}
    # shellcheck disable=SC2086
    RAYON_NUM_THREADS=2 /usr/bin/time -f '%M' -o "$WORK/rss" \
        timeout -s KILL "$TIMEOUT" prlimit --as="$MEMORY" -- "$BIN" $args \
        >"$WORK/stdout" 2>"$WORK/stderr"
    status=$?
    rss_kb=$(tail -n 1 "$WORK/rss" 2>/dev/null | grep -Eo '^[0-9]+$' || echo 0)
    err=$(tr -d '\0' <"$WORK/stderr")
    verdict=ok
    if [ "$status" -eq 101 ] || grep -q 'panicked' "$WORK/stderr"; then
        verdict=PANIC
    elif [ "$status" -eq 137 ] || [ "$status" -eq 124 ]; then
        verdict=HANG
    elif [ "$status" -gt 128 ] || grep -q 'memory allocation of' "$WORK/stderr"; then
        verdict=CRASH
    elif [ "$rss_kb" -gt $((MEMORY / 1024)) ]; then
        verdict=MEMORY
    elif [ "$expect" = ok ]; then
        [ "$status" -ne 0 ] && verdict=REFUSED
    elif [ "$status" -eq 0 ]; then
        verdict=ACCEPTED
    elif [ "$status" -ne 1 ] && [ "$status" -ne 2 ]; then
        verdict=CRASH
    else
        IFS='|' read -ra needles <<<"${expect#fail:}"
        for n in "${needles[@]}"; do
            [ -z "$n" ] && continue
            if ! grep -qiF -- "$n" <<<"$err"; then verdict=VAGUE; fi
        done
    fi
    COUNT[$verdict]=$((${COUNT[$verdict]:-0} + 1))
    TOTAL=$((TOTAL + 1))
    if [ "$verdict" != ok ]; then
        FAILED+=("$id")
        printf '%-9s %-44s exit %3s  %6d MB  %s\n' "$verdict" "$id" "$status" $((rss_kb / 1024)) \
            "$(tail -n 1 <<<"$err" | cut -c1-150)"
    elif [ -n "${HOSTILE_VERBOSE:-}" ]; then
        printf '%-9s %-44s exit %3s  %6d MB  %s\n' ok "$id" "$status" $((rss_kb / 1024)) \
            "$(tail -n 1 <<<"$err" | cut -c1-150)"
    fi
    rm -rf "$out"
done <tests/hostile/cases.txt
echo "---"
printf '%d cases:' "$TOTAL"
for k in ok PANIC CRASH HANG MEMORY ACCEPTED REFUSED VAGUE; do
    printf ' %s %d' "$k" "${COUNT[$k]:-0}"
done
echo
[ ${#FAILED[@]} -eq 0 ]
