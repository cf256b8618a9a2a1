#!/usr/bin/env bash
# What a retargeted subscription costs the server (docs/performance.md,
# "Retargeted subscriptions"): N subscribers of a library motion and of a
# live source, each with its own view, plain and retargeted onto a rig
# (gmr-load --retarget), on a freshly started gmr-server pinned to CPU 0 with
# gmr-load (and the live source's publisher) on CPU 1. Modes: plain; retarget
# (every client the same rig: a live source's views share one replay a
# frame); own-rigs (each client a rig of its own, gmr-load --own-rigs: one
# replay a frame per view, the worst case). Prints the server's CPU per
# delivered frame for each case, each repeat and the median.
#
#   bench/server/retarget.sh [BUILD_DIR] [OUT_DIR]
#     SUBSCRIBERS=100  REPEATS=3  SECONDS_PER_POINT=10  KINDS="library live"  MODES="plain retarget own-rigs"
#     MOTION_FILE=../shared/data/bvh/cmu/02_01.bvh  RIG_FILE=../shared/data/bvh/mixamo/Beta_jump.bvh
#
# A benchmark, not a CI step: about 40 s per run (kind x mode x repeat).
set -euo pipefail
build=${1:-build}
out=${2:-bench/server/results-retarget}
n=${SUBSCRIBERS:-100}
repeats=${REPEATS:-3}
seconds=${SECONDS_PER_POINT:-10}
motion_file=${MOTION_FILE:-../shared/data/bvh/cmu/02_01.bvh}
rig_file=${RIG_FILE:-../shared/data/bvh/mixamo/Beta_jump.bvh}
bin="$build/bin"

for f in gmr-server gmr-load gmr; do
  [ -x "$bin/$f" ] || { echo "retarget bench: build $f in $build first" >&2; exit 1; }
done
for f in "$motion_file" "$rig_file"; do
  [ -f "$f" ] || { echo "retarget bench: no $f (../shared/data, or set MOTION_FILE / RIG_FILE)" >&2; exit 1; }
done
[ "$(nproc)" -ge 2 ] || { echo "retarget bench: needs two CPUs (server on 0, clients on 1)" >&2; exit 1; }

mkdir -p "$out"
library=$(mktemp -d)
mkdir "$library/rigs"
ln -s "$(realpath "$motion_file")" "$library/"
ln -s "$(realpath "$rig_file")" "$library/rigs/"
motion=$(basename "$motion_file"); motion=${motion%.*}
rig=rigs/$(basename "$rig_file"); rig=${rig%.*}
spid=""; ppid_=""
start_server() {
  rm -f "$library/port"
  taskset -c 0 "$bin/gmr-server" --library "$library" --port 0 --port-file "$library/port" --http-port -1 \
    --max-connections-per-address 0 --send-budget 0 --anonymous publish --log-level warn >"$library/server.log" 2>&1 &
  spid=$!
  for _ in $(seq 200); do [ -s "$library/port" ] && return; sleep 0.1; done
  echo "retarget bench: gmr-server did not start:" >&2; cat "$library/server.log" >&2; exit 1
}
stop() {
  if [ -n "$ppid_" ]; then kill "$ppid_" 2>/dev/null || true; wait "$ppid_" 2>/dev/null || true; fi
  if [ -n "$spid" ]; then kill -INT "$spid" 2>/dev/null || true; wait "$spid" 2>/dev/null || true; fi
  ppid_=""; spid=""
}
cleanup() { stop || true; rm -rf "$library"; }
trap cleanup EXIT

# ns per delivered frame, from gmr-load's report.
per_frame() { sed -n 's/^server CPU .*, \([0-9]*\) ns per delivered frame.*/\1/p' "$1"; }

for kind in ${KINDS:-library live}; do
  for mode in ${MODES:-plain retarget own-rigs}; do
    figures=()
    for rep in $(seq "$repeats"); do
      name="$kind-$mode-$n-$rep"
      start_server
      port=$(cat "$library/port")
      source=$motion
      if [ "$kind" = live ]; then
        source=live
        taskset -c 1 "$bin/gmr" publish "$motion_file" --name live --loop --port "$port" >"$out/$name.publish.txt" 2>&1 &
        ppid_=$!
        for _ in $(seq 100); do "$bin/gmr" ls --port "$port" 2>/dev/null | grep -q '^live' && break; sleep 0.1; done
      fi
      flags=()
      [ "$mode" != plain ] && flags+=(--retarget "$rig")
      [ "$mode" = own-rigs ] && flags+=(--own-rigs)
      taskset -c 1 "$bin/gmr-load" --port "$port" --clients "$n" --motion "$source" --seconds "$seconds" \
        --warmup 2 --threads 1 --server-pid "$spid" "${flags[@]}" --json "$out/$name.json" >"$out/$name.txt" 2>&1 ||
        { echo "retarget bench: $name failed:" >&2; cat "$out/$name.txt" >&2; }
      stop
      figures+=("$(per_frame "$out/$name.txt")")
      echo "$name: $(per_frame "$out/$name.txt") ns per delivered frame; $(grep -E '^delivered' "$out/$name.txt" || true)"
    done
    median=$(printf '%s\n' "${figures[@]}" | sort -n | awk '{a[NR]=$1} END{print a[int((NR+1)/2)]}')
    echo "$kind $mode: median $median ns per delivered frame (${figures[*]})" | tee -a "$out/summary.txt"
  done
done
