#!/bin/bash
# Opt-in test of the scale-out recipes (not part of `cargo test`): starts a one-node Slurm
# cluster on this machine (munged, slurmctld and slurmd with a throw-away configuration in
# a temporary folder; nothing in /etc is touched), then
#   1. renders a scene as a 4-task job array + merge job (slurm-render.sh) and checks the
#      merged image against a single render, bit for bit;
#   2. fits a capture in two phases (slurm-estimate.sh: index from a band, 4 row bands with
#      it, merge) and checks the thickness map against a single fit with that index, bit for
#      bit;
#   3. the same render split with GNU parallel instead of Slurm.
# Stops the daemons it started and removes its folder (KEEP=1 keeps it).
#
# Needs: root (slurmd runs jobs as their user), `apt-get install slurm-wlm parallel`, and a
# built binary (`cargo build --release`; THINFILM overrides target/release/thinfilm).
#
#   tools/scale-out/test-slurm.sh        # exit status 0 = pass
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
here="$repo/tools/scale-out"
thinfilm=${THINFILM:-$repo/target/release/thinfilm}
for tool in munged slurmctld slurmd sbatch squeue sinfo parallel; do
    command -v "$tool" > /dev/null || { echo "missing $tool: apt-get install slurm-wlm parallel" >&2; exit 2; }
done
[ -x "$thinfilm" ] || { echo "no thinfilm binary at $thinfilm: cargo build --release" >&2; exit 2; }
[ "$(id -u)" = 0 ] || { echo "run as root (slurmd must start jobs)" >&2; exit 2; }

work=$(mktemp -d /tmp/thinfilm-slurm.XXXXXX)
daemons=()
cleanup() {
    status=$?
    for pid in "${daemons[@]}"; do kill "$pid" 2> /dev/null || true; done
    for pid in "${daemons[@]}"; do
        while kill -0 "$pid" 2> /dev/null; do sleep 0.2; done
    done
    if [ -n "${KEEP:-}" ] || [ "$status" != 0 ]; then
        echo "files kept in $work"
    else
        rm -rf "$work"
    fi
}
trap cleanup EXIT
log() { echo "[$(date +%T)] $*"; }

# --- a one-node cluster ---------------------------------------------------------------------
host=$(hostname -s)
mkdir -p "$work/munge" "$work/state" "$work/spool"
chmod 711 "$work/munge"
head -c 1024 /dev/urandom > "$work/munge/munge.key"
chmod 400 "$work/munge/munge.key"
socket="$work/munge/munge.socket"
munged --foreground --force --key-file="$work/munge/munge.key" --socket="$socket" \
    --pid-file="$work/munge/munged.pid" --log-file="$work/munge/munged.log" \
    --seed-file="$work/munge/munged.seed" > "$work/munge/munged.out" 2>&1 &
daemons+=($!)
# Ports away from a real cluster's defaults (6817/6818).
port=$((20000 + RANDOM % 20000))
cat > "$work/slurm.conf" << EOF
ClusterName=thinfilm-test
SlurmctldHost=$host
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
AuthType=auth/munge
AuthInfo=socket=$socket
CredType=cred/munge
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
DependencyParameters=kill_invalid_depend
ReturnToService=2
MpiDefault=none
NodeName=$host CPUs=$(nproc) State=UNKNOWN
PartitionName=test Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF="$work/slurm.conf"
sleep 1
slurmctld -D -c -f "$SLURM_CONF" > "$work/slurmctld.out" 2>&1 &
daemons+=($!)
sleep 2
slurmd -D -f "$SLURM_CONF" > "$work/slurmd.out" 2>&1 &
daemons+=($!)
for _ in $(seq 60); do
    state=$(sinfo -h -o %T 2> /dev/null || true)
    [ "$state" = idle ] && break
    sleep 1
done
[ "$state" = idle ] || { echo "the node did not come up (state '$state'); see $work/*.log" >&2; exit 1; }
log "one-node cluster up: $host, $(nproc) CPUs"

# Waits until the queue is empty (jobs whose dependency failed are cancelled by Slurm).
wait_for_queue() {
    for _ in $(seq 900); do
        [ -z "$(squeue -h)" ] && return 0
        sleep 1
    done
    echo "jobs still queued after 15 min:" >&2
    squeue >&2
    return 1
}
identical() { # A B: bit-identical pixels? (grep reads all: with -q it could close the
    # pipe before compare has written everything, and pipefail would fail on that)
    "$thinfilm" compare "$1" "$2" --json | grep '"identical": true' > /dev/null
}

# --- 1. a render split by sample ranges -------------------------------------------------------
scene="$repo/scenes/teapot_mgf2_400.xml"
export THINFILM="$thinfilm"
"$here/slurm-render.sh" "$scene" 64 4 "$work/render/teapot.exr" -D res=48
wait_for_queue
[ -f "$work/render/teapot.exr" ] || { echo "the merge job wrote nothing; logs in $work/render/teapot.parts" >&2; exit 1; }
"$thinfilm" render "$scene" --spp 64 -D res=48 -o "$work/render/single.exr" --quiet > /dev/null
identical "$work/render/teapot.exr" "$work/render/single.exr" ||
    { echo "FAIL: the merged Slurm render differs from the single render" >&2; exit 1; }
log "PASS render: 4 Slurm array tasks merged = single render, bit for bit"

# --- 2. a fit in two phases ------------------------------------------------------------------
cap="$work/capture"
"$thinfilm" simulate --preset sample3 --size 96x64 --noise 0.004 --out "$cap" --quiet
"$here/slurm-estimate.sh" "$cap" 24:40 4 "$work/estimate"
wait_for_queue
wait_for_queue # phase 2 was submitted by a job of phase 1's queue
[ -f "$work/estimate/fit/thickness.exr" ] || { echo "no merged fit; logs in $work/estimate" >&2; exit 1; }
film_ior=$(sed -n 's/^ *"film_ior": *\([-0-9.eE+]*\),*$/\1/p' "$work/estimate/index/fit.json")
"$thinfilm" estimate "$cap" --film-ior "$film_ior" --out "$work/estimate/single" --quiet > /dev/null
identical "$work/estimate/fit/thickness.exr" "$work/estimate/single/thickness.exr" ||
    { echo "FAIL: the stitched thickness differs from the single fit" >&2; exit 1; }
log "PASS estimate: index $film_ior from rows 24:40, 4 Slurm bands merged = single fit, bit for bit"

# --- 3. the render with GNU parallel ---------------------------------------------------------
mkdir -p "$work/parallel"
parallel -j 2 "$thinfilm" render "$scene" --spp 64 -D res=48 --part {}/4 \
    -o "$work/parallel/part-{}.exr" --quiet ::: 0 1 2 3 > /dev/null
"$thinfilm" merge "$work"/parallel/part-{0,1,2,3}.exr -o "$work/parallel/teapot.exr" --quiet > /dev/null
identical "$work/parallel/teapot.exr" "$work/render/single.exr" ||
    { echo "FAIL: the GNU parallel render differs from the single render" >&2; exit 1; }
log "PASS GNU parallel: 4 parts merged = single render, bit for bit"
