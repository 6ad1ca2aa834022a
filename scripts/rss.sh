#!/usr/bin/env bash
# Memory under a long run (issue 18): runs `soda run ARGS...` and samples its resident set
# (VmRSS in /proc/PID/status) every INTERVAL seconds, then prints the samples, the first and
# last after warm-up, and the peak (VmHWM).
#
#   scripts/rss.sh -- --scene sparse-gas --steps 100000
#   RSS_INTERVAL=2 scripts/rss.sh -- --scene sparse-gas --steps 100000 --executor threaded --threads 2
#
# Environment: RSS_INTERVAL (seconds between samples, default 5), RSS_LOG (default
# target/rss.log).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
interval=${RSS_INTERVAL:-5}
log=${RSS_LOG:-$root/target/rss.log}
[ "${1:-}" = "--" ] && shift
cd "$root"
cargo build --release --bin soda
soda=${CARGO_TARGET_DIR:-$root/target}/release/soda

"$soda" run "$@" >"$log.out" 2>&1 &
pid=$!
start=$(date +%s)
: >"$log"
peak=0
while kill -0 "$pid" 2>/dev/null; do
    rss=$(awk '/^VmRSS/ {print $2}' "/proc/$pid/status" 2>/dev/null || true)
    hwm=$(awk '/^VmHWM/ {print $2}' "/proc/$pid/status" 2>/dev/null || true)
    [ -n "$rss" ] && echo "$(($(date +%s) - start)) s  VmRSS ${rss} kB  VmHWM ${hwm} kB" | tee -a "$log"
    [ -n "$hwm" ] && peak=$hwm
    sleep "$interval"
done
wait "$pid" || { echo "soda run failed:"; cat "$log.out"; exit 1; }
echo "---"
grep -E '^(steps|wall time|hash)' "$log.out"
first=$(sed -n 2p "$log" | awk '{print $4}')
last=$(tail -1 "$log" | awk '{print $4}')
echo "RSS: ${first:-?} kB at the second sample, ${last:-?} kB at the last, peak ${peak} kB"
