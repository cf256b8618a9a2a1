#!/usr/bin/env bash
# Admission against the grid (docs/performance.md, "Admission against the
# grid"): for every point of a grid CSV (docs/server-grid.csv unless GRID
# says), a fresh gmr-server with its default send budget (calibrated at
# start), pinned to CPU 0 as in the grid, and gmr-load asking for that
# point's subscriptions on CPU 1: how many the server admits. A point the
# grid held (every frame delivered) should be admitted whole; the first point
# past saturation (frames lost) should be refused in part.
#
#   bench/server/admission.sh [BUILD_DIR] [OUT_DIR]
#     GRID=docs/server-grid.csv  STARTS=3  RATE=120  SETTLE=0
#     MOTION_FILE=../shared/data/bvh/cmu/01_01.bvh
#
# SETTLE=S asks S seconds after the server started, once it has measured its
# budget again (1, 2, 4 ... 32 s after start; S=8 sees three).
#
# Writes OUT_DIR/admission.csv: one row per point and start (the budget when
# asked and the one the start calibrated, subscriptions asked and admitted,
# what the grid delivered there, and the verdict). A few minutes (and 33
# times SETTLE); a benchmark, not a CI step.
set -euo pipefail
build=${1:-build}
out=${2:-bench/server/results}
grid=${GRID:-docs/server-grid.csv}
starts=${STARTS:-3}
settle=${SETTLE:-0}
rate=${RATE:-120}
motion_file=${MOTION_FILE:-../shared/data/bvh/cmu/01_01.bvh}
bin="$build/bin"

[ -x "$bin/gmr-server" ] && [ -x "$bin/gmr-load" ] ||
  { echo "admission bench: build gmr-server and gmr-load in $build first" >&2; exit 1; }
[ -f "$grid" ] || { echo "admission bench: no grid CSV at $grid (bench/server/run.sh writes one)" >&2; exit 1; }
[ -f "$motion_file" ] || { echo "admission bench: no $motion_file (../shared/data, or set MOTION_FILE)" >&2; exit 1; }
[ "$(nproc)" -ge 2 ] || { echo "admission bench: needs two CPUs (server on 0, load on 1)" >&2; exit 1; }
ulimit -n "$(ulimit -Hn)"

mkdir -p "$out"
bench_name="admission bench"
# shellcheck source=bench/server/common.sh
. "$(dirname "$0")/common.sh"

csv="$out/admission.csv"
echo "transport,stream,subscribers,start,budget_fps,asked,admitted,grid_delivered_pct,verdict,start_budget_fps" >"$csv"
# The grid's points, by transport and stream in subscriber order: each one's
# delivered share, and whether it is the first past saturation.
saturated=""
while IFS=, read -r transport stream n expected delivered _; do
  pct=$(python3 -c "print(f'{min(100.0, 100.0 * $delivered / $expected):.1f}')")
  key="$transport-$stream"
  held=$(python3 -c "print(int($delivered >= 0.995 * $expected))")
  past=0
  if [ "$held" = 0 ] && [ "$saturated" != "$key" ]; then past=1; saturated=$key; fi
  [ "$held" = 1 ] || [ "$past" = 1 ] || continue  # beyond the first point past saturation: nothing to say
  for s in $(seq "$starts"); do
    start_server 0 --http-port -1 --max-connections 30000 --max-connections-per-address 0 \
      --max-pending-handshakes 30000 --log-level info
    [ "$settle" = 0 ] || sleep "$settle"
    start_budget=$(sed -n 's/.*send budget \([0-9]*\) frames\/s.*/\1/p' "$library/server.log" | head -1)
    budget=$(sed -n 's/.*send budget raised from [0-9]* to \([0-9]*\) frames\/s.*/\1/p' "$library/server.log" | tail -1)
    budget=${budget:-$start_budget}
    flags=()
    [ "$transport" = udp ] && flags+=(--udp)
    [ "$stream" = shared ] && flags+=(--shared)
    report=$(taskset -c 1 "$bin/gmr-load" --port "$(cat "$library/port")" --clients "$n" --rate "$rate" \
      --seconds 1 --warmup 0 --threads 1 --motion "$motion" "${flags[@]}" 2>&1 || true)
    stop_server
    admitted=$(sed -n 's/.*the server admitted \([0-9]*\) of.*/\1/p' <<<"$report" | head -1)
    if [ -z "$admitted" ]; then
      grep -q "^delivered" <<<"$report" ||
        { echo "admission bench: gmr-load failed at $key-$n:" >&2; echo "$report" >&2; exit 1; }
      admitted=$n
    fi
    if [ "$held" = 1 ]; then verdict=$([ "$admitted" = "$n" ] && echo "held, admitted" || echo "held, REFUSED IN PART")
    else verdict=$([ "$admitted" -lt "$n" ] && echo "past saturation, refused in part" || echo "past saturation, ADMITTED"); fi
    echo "$transport,$stream,$n,$s,$budget,$n,$admitted,$pct,$verdict,$start_budget" | tee -a "$csv"
  done
done < <(tail -n +2 "$grid" | sort -t, -k1,1 -k2,2 -k3,3n)
