#!/usr/bin/env bash
# Runs `ident demo` and `ident nightly` on the simulated stand RUNS times each while HOGS
# CPU-bound processes run (default: one per core), and prints each run's exit code and wall time
# and the pass counts. A measurement (docs/daq-serial.md, "The simulated device's clock"), not a
# test.
#
#   tools/sim-under-load.sh [RUNS] [HOGS] [demo|nightly|both]
#
# Run it from anywhere after `cargo build --release --workspace`. Environment: IDENT (the binary;
# default target/release/ident, or $CARGO_TARGET_DIR/release/ident), KEEP=1 keeps the scratch
# folder (every run's output is in its logs).
set -u
runs=${1:-20}
hogs=${2:-$(nproc)}
which=${3:-both}
root=$(cd "$(dirname "$0")/.." && pwd)
ident=${IDENT:-${CARGO_TARGET_DIR:-$root/target}/release/ident}
[ -x "$ident" ] || { echo "no $ident: run cargo build --release --workspace first" >&2; exit 2; }
scratch=$(mktemp -d)
pids=()
cleanup() {
    for p in "${pids[@]}"; do kill "$p" 2>/dev/null; done
    if [ "${KEEP:-0}" = 1 ]; then echo "scratch kept: $scratch"; else rm -rf "$scratch"; fi
}
trap cleanup EXIT
for _ in $(seq "$hogs"); do
    python3 -c 'while True: pass' &
    pids+=($!)
done
echo "$hogs CPU-bound processes on $(nproc) cores; load average $(cut -d' ' -f1-3 /proc/loadavg)"

cat >"$scratch/nightly.toml" <<JOB
name = "simulated stand under load"
measure = "sweep"
stand = "$root/configs/stands/fwd32j-model-sim.toml"
model = "$root/configs/models/fwd32j-no-actuator.toml"
variables = "$root/configs/identification/fwd32j-no-actuator.toml"
sessions = "sessions"
reports = "reports"
log = "nightly.log"
lock = "nightly.lock"
JOB

# Runs one job; passes when its exit code is at most $2 (the nightly's 1 is a drift alarm, a
# judgement on the identified parameters rather than a failure of the stand).
series() { # name, largest passing exit code
    local name=$1 ok=$2 pass=0 i log start code secs
    for i in $(seq "$runs"); do
        log="$scratch/$name-$i.log"
        start=$(date +%s.%N)
        if [ "$name" = demo ]; then
            "$ident" demo --quiet --out "$scratch/demo-$i" >"$log" 2>&1
        else
            "$ident" nightly "$scratch/nightly.toml" >"$log" 2>&1
        fi
        code=$?
        secs=$(echo "$(date +%s.%N) - $start" | bc)
        printf '%s %2d: exit %d, %.1f s, load average %s\n' "$name" "$i" "$code" "$secs" \
            "$(cut -d' ' -f1 /proc/loadavg)"
        if [ "$code" -le "$ok" ]; then pass=$((pass + 1)); else tail -n 5 "$log"; fi
        rm -rf "$scratch/demo-$i"
    done
    echo "$name: $pass of $runs passed"
}

case "$which" in
demo) series demo 0 ;;
nightly) series nightly 1 ;;
*) series demo 0; series nightly 1 ;;
esac
