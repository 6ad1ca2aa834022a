#!/usr/bin/env bash
# A long determinism soak, outside CI (README.md, "Checking determinism yourself"):
#
#   1. `soda verify` on every built-in scene and every rollback mode, virtual executor only,
#      SCHEDULES schedule seeds in all (default 100,000), cut into pieces run in parallel;
#   2. FUZZ_SECONDS of the `sync_order` fuzz target (default 3,600; needs cargo-fuzz, which
#      this script installs if missing).
#
# It prints the executions, the divergences (must be 0) and the wall time of each part, and
# exits 1 if anything diverged or crashed. Logs go to $SOAK_OUT (default target/soak).
#
#   scripts/soak.sh                  # the full soak: 100,000 schedules + 1 hour of fuzzing
#   scripts/soak.sh 2000 60          # a short one: 2,000 schedules, 1 minute of fuzzing
#
# Environment: SOAK_JOBS (parallel verify processes, default: the cores), SOAK_STEPS (steps
# per run, default 60), SOAK_CHUNK (seeds per verify process and mode, default 200),
# SOAK_SCENES (default: every built-in), SOAK_SODA (a `soda` binary to use instead of building
# one, e.g. a copy so that rebuilding meanwhile does not change what is soaked), SOAK_FRESH=1 (start over; by default a piece whose
# log in $SOAK_OUT already ends in "all ... runs committed" is kept and not run again, so an
# interrupted soak resumes where it stopped — with the same SCHEDULES, SOAK_STEPS and SOAK_CHUNK).
set -euo pipefail

schedules=${1:-100000}
fuzz_seconds=${2:-3600}
root=$(cd "$(dirname "$0")/.." && pwd)
out=${SOAK_OUT:-$root/target/soak}
jobs=${SOAK_JOBS:-$(nproc)}
steps=${SOAK_STEPS:-60}
chunk=${SOAK_CHUNK:-200}
scenes=${SOAK_SCENES:-"falling-cubes sparse-gas dense-pile skewed chain peak"}
modes=3

mkdir -p "$out"
cd "$root"
if [ -n "${SOAK_SODA:-}" ]; then
    soda=$SOAK_SODA
else
    cargo build --release --bin soda
    soda=${CARGO_TARGET_DIR:-$root/target}/release/soda
fi

# 1. Virtual-executor schedules: each verify process checks `chunk` seeds in each of the
#    three modes; seeds are split evenly between the scenes.
status=0
if [ "$schedules" -gt 0 ]; then
    nscenes=$(wc -w <<<"$scenes")
    per_scene=$(((schedules + nscenes * modes - 1) / (nscenes * modes)))
    if [ "${SOAK_FRESH:-0}" = 1 ]; then
        rm -f "$out"/verify-*.log "$out/verify-wall.txt"
    fi
    jobs_file="$out/verify-jobs.txt"
    : >"$jobs_file"
    kept=0
    for scene in $scenes; do
        for ((first = 0; first < per_scene; first += chunk)); do
            n=$((per_scene - first < chunk ? per_scene - first : chunk))
            log="$out/verify-$scene-$first.log"
            if [ -f "$log" ] && grep -q "^all $((n * modes)) runs committed" "$log"; then
                kept=$((kept + 1))
                continue
            fi
            echo "$scene $first $n $steps $out" >>"$jobs_file"
        done
    done
    echo "soak: $((per_scene * nscenes * modes)) virtual runs ($per_scene seeds x $modes modes x $nscenes scenes, $steps steps each); $(wc -l <"$jobs_file") pieces to run on $jobs processes, $kept already complete"
    start=$(date +%s)
    # A diverging piece exits 1; keep going and count from the logs.
    xargs -r -P "$jobs" -L 1 sh -c '
        "$0" verify --scene "$1" --first-schedule "$2" --schedules "$3" --repeats 0 --steps "$4" \
            >"$5/verify-$1-$2.log" 2>&1 || true
    ' "$soda" <"$jobs_file"
    verify_seconds=$(($(date +%s) - start))
    # Wall time summed over every invocation that added pieces to this soak.
    echo "$verify_seconds" >>"$out/verify-wall.txt"
    verify_seconds=$(awk '{ s += $1 } END { print s }' "$out/verify-wall.txt")
    runs=$(cat "$out"/verify-*.log | grep -c '^ok ' || true)
    diverged=$(cat "$out"/verify-*.log | grep -c '^DIVERGED' || true)
    failed=$(grep -L '^all .* runs committed' "$out"/verify-*.log | wc -l)
    echo "verify: $runs runs matched, $diverged diverged, $failed pieces failed, ${verify_seconds} s wall"
    if [ "$diverged" -ne 0 ] || [ "$failed" -ne 0 ]; then
        grep -h -A1 '^DIVERGED' "$out"/verify-*.log | head -20
        status=1
    fi
fi

# 2. Fuzzing the synchronisation order.
if [ "$fuzz_seconds" -gt 0 ]; then
    if ! cargo fuzz --help >/dev/null 2>&1; then
        cargo install cargo-fuzz --locked
    fi
    mkdir -p fuzz/corpus/sync_order
    # The fuzz crate builds into fuzz/target with its own flags, never into the main target.
    (cd fuzz && env -u CARGO_TARGET_DIR cargo fuzz build --sanitizer none sync_order)
    start=$(date +%s)
    fuzz_status=0
    (cd fuzz && env -u CARGO_TARGET_DIR cargo fuzz run --sanitizer none sync_order \
        corpus/sync_order regressions/sync_order \
        -- -max_total_time="$fuzz_seconds" -print_final_stats=1) >"$out/fuzz.log" 2>&1 || fuzz_status=$?
    fuzz_seconds_run=$(($(date +%s) - start))
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$out/fuzz.log" | grep -o '[0-9]*$' | tail -1)
    echo "fuzz: ${execs:-?} sync_order executions, exit status $fuzz_status, ${fuzz_seconds_run} s wall"
    if [ "$fuzz_status" -ne 0 ]; then
        grep -E 'divergen|panicked|SUMMARY' "$out/fuzz.log" | head -10
        status=1
    fi
fi
exit $status
