#!/usr/bin/env bash
# The server figures of docs/performance.md ("Load held, bytes per
# subscriber, admission"): gmr-server pinned to CPU 0 serving one motion,
# gmr-load on CPU 1.
#   bench/load_grid.sh [BUILD_DIR] [MOTION_FILE]    (default: build, CMU 01_01)
# 1. bytes per subscriber: the server's RSS with 1,000 float32 subscribers
#    at 30 Hz (own streams, then one shared stream) over its idle RSS;
# 2. 120 Hz over TCP, 100-1,000 subscribers on own streams and 100-400 on
#    one shared stream, 10 s each: frames, latency, gaps, skipped ticks.
# No send budget (--send-budget 0): the grid means to find the knee. Takes
# about three minutes and both cores; not a CI step.
set -euo pipefail
build=${1:-build}
motion_file=${2:-../shared/data/bvh/cmu/01_01.bvh}
bin="$build/bin"
[ -f "$motion_file" ] || { echo "load_grid: no $motion_file" >&2; exit 1; }
library=$(mktemp -d)
ln -s "$(realpath "$motion_file")" "$library/"
motion=$(basename "$motion_file"); motion=${motion%.*}
port_file="$library/port"
spid=""
start_server() {
  rm -f "$port_file"
  taskset -c 0 "$bin/gmr-server" --library "$library" --port 0 --port-file "$port_file" --max-connections 4096 \
    --max-connections-per-address 0 --send-budget 0 --log-level warn >/dev/null 2>&1 &
  spid=$!
  for _ in $(seq 100); do [ -s "$port_file" ] && return; sleep 0.1; done
  echo "load_grid: gmr-server did not start" >&2; exit 1
}
stop_server() { [ -n "$spid" ] && kill -INT "$spid" 2>/dev/null && wait "$spid" 2>/dev/null; spid=""; }
cleanup() { stop_server || true; rm -rf "$library"; }
trap cleanup EXIT
rss_kb() { awk '/VmRSS/ {print $2}' "/proc/$spid/status"; }

for mode in own shared; do
  start_server
  sleep 0.5
  idle=$(rss_kb)
  flags=()
  [ "$mode" = shared ] && flags=(--shared)
  taskset -c 1 "$bin/gmr-load" --port "$(cat "$port_file")" --clients 1000 --rate 30 --seconds 4 --warmup 1 \
    --motion "$motion" "${flags[@]}" >"$library/load.txt" 2>&1 &
  load=$!
  peak=$idle
  while kill -0 "$load" 2>/dev/null; do r=$(rss_kb); [ "$r" -gt "$peak" ] && peak=$r; sleep 0.2; done
  wait "$load"
  echo "bytes per subscriber: server RSS $idle kB idle, $peak kB with 1000 subscribers ($mode streams) at 30 Hz:" \
       "$(( (peak - idle) * 1024 / 1000 )) bytes each"
  stop_server
done

for mode in own shared; do
  sizes=(100 200 300 400)
  [ "$mode" = own ] && sizes+=(600 800 1000)
  for n in "${sizes[@]}"; do
    start_server
    flags=()
    [ "$mode" = shared ] && flags=(--shared)
    taskset -c 1 "$bin/gmr-load" --port "$(cat "$port_file")" --clients "$n" --rate 120 --seconds 10 \
      --motion "$motion" --server-pid "$spid" "${flags[@]}" >"$library/load.txt" 2>&1
    echo "TCP $mode, $n subscribers at 120 Hz:"
    grep -E "^(delivered|lost|latency|  in the server|server, window|server CPU)" "$library/load.txt" | sed 's/^/  /'
    stop_server
  done
done
