#!/usr/bin/env bash
# The server throughput grid of docs/performance.md ("Throughput: the grid"):
# subscribers x {TCP, UDP} x {own stream, one shared stream} at 120 Hz, each
# point on a freshly started gmr-server pinned to CPU 0 with gmr-load pinned
# to CPU 1, repeated; the medians go to a CSV and a PNG.
#
#   bench/server/run.sh [BUILD_DIR] [OUT_DIR]
#     SUBSCRIBERS="100 1000 3000 10000"  REPEATS=3  SECONDS_PER_POINT=10  RATE=120
#     MOTION_FILE=../shared/data/bvh/cmu/01_01.bvh  TRANSPORTS="tcp udp"  MODES="own shared"
#     CLIENTS_PER_PROCESS=(what the open-files limit allows)  LOAD_THREADS=1  PHASES=5
#     SERVER_CPUS=0  LOAD_CPUS=1  FLOOR=1  SERVER_FLAGS=
#
# SERVER_FLAGS are more gmr-server options, word-split (say
# SERVER_FLAGS="--tick-grid-ms 0" for own streams that tick from when they start).
# SERVER_CPUS and LOAD_CPUS are taskset lists: SERVER_CPUS=0,1 LOAD_CPUS=0,1
# gives the server both cores (one I/O thread per CPU), shared with the load
# generator; FLOOR=0 skips the floor (it is pinned to CPUs 0 and 1 whatever
# those say).
#
# Each (transport, subscribers) point also runs gmr-floor (bench/floor.cpp) as
# many times, pinned the same way: the same frames, of the same size (BYTES,
# default 510: a 01_01 frame at float32 with its head), sent with sendmmsg or
# writev and nothing else. The CSV gives gmr's CPU per frame as a ratio to it.
# Own streams start at different times, but on the server's grid (2 ms by
# default, --tick-grid-ms), so at 120 Hz their frames leave in 5 groups a
# period, not in one burst: for them the floor also runs with --phases
# PHASES, and the CSV gives the ratio to that floor too (phased_floor_*).
# Without the grid (SERVER_FLAGS="--tick-grid-ms 0") the clock's 0.5 ms
# grain leaves about 17 groups a period: PHASES=17 is that floor.
#
# Writes OUT_DIR/runs/*.json (every run, gmr-load --json; the floor's in
# runs/floor/, in phases in runs/floor/phased/), OUT_DIR/grid.csv (one row per point, medians over the
# repeats) and OUT_DIR/grid.png. No send
# budget (--send-budget 0): the grid means to find where the server stops
# keeping up. The full grid takes about 45 minutes and both cores; it is a
# benchmark, not a CI step.
set -euo pipefail
build=${1:-build}
out=${2:-bench/server/results}
subscribers=${SUBSCRIBERS:-100 1000 3000 10000}
repeats=${REPEATS:-3}
seconds=${SECONDS_PER_POINT:-10}
rate=${RATE:-120}
motion_file=${MOTION_FILE:-../shared/data/bvh/cmu/01_01.bvh}
load_threads=${LOAD_THREADS:-1}
transports=${TRANSPORTS:-tcp udp}
modes=${MODES:-own shared}
bytes=${BYTES:-510}
phases=${PHASES:-5}
server_cpus=${SERVER_CPUS:-0}
load_cpus=${LOAD_CPUS:-1}
run_floor=${FLOOR:-1}
read -r -a server_flags <<<"${SERVER_FLAGS:-}"
bin="$build/bin"
here=$(dirname "$0")

[ -x "$bin/gmr-server" ] && [ -x "$bin/gmr-load" ] && [ -x "$bin/gmr-floor" ] ||
  { echo "server bench: build gmr-server, gmr-load and gmr-floor in $build first" >&2; exit 1; }
[ -f "$motion_file" ] || { echo "server bench: no $motion_file (../shared/data, or set MOTION_FILE)" >&2; exit 1; }
[ "$(nproc)" -ge 2 ] || { echo "server bench: needs two CPUs (server on 0, load on 1)" >&2; exit 1; }
# A gmr-load client holds two sockets (its TCP connection and a UDP socket,
# whatever the transport): a point that needs more than the open-files limit
# allows runs several processes at once (all on CPU 1), whose results
# gmr-load --merge adds up.
ulimit -n "$(ulimit -Hn)"
clients_per_process() {
  [ -n "${CLIENTS_PER_PROCESS:-}" ] && { echo "$CLIENTS_PER_PROCESS"; return; }
  echo $(( ($(ulimit -n) - 200) / 2 ))
}

mkdir -p "$out/runs/floor/phased"
bench_name="server bench"
# shellcheck source=bench/server/common.sh
. "$here/common.sh"

for n in $subscribers; do
  for transport in $transports; do
    for rep in $(seq "$repeats"); do
      [ "$run_floor" = 1 ] || break
      "$bin/gmr-floor" --transport "$transport" --sockets "$n" --rate "$rate" --bytes "$bytes" --seconds "$seconds" \
        --send-cpu 0 --receive-cpu 1 --json "$out/runs/floor/$transport-$n-$rep.json" | sed "s/^/floor $transport-$n-$rep: /"
      if [[ " $modes " == *" own "* ]] && [ "$phases" -gt 1 ]; then
        "$bin/gmr-floor" --transport "$transport" --sockets "$n" --rate "$rate" --bytes "$bytes" --seconds "$seconds" \
          --phases "$phases" --send-cpu 0 --receive-cpu 1 --json "$out/runs/floor/phased/$transport-$n-$rep.json" |
          sed "s/^/floor (phased) $transport-$n-$rep: /"
      fi
    done
    for mode in $modes; do
      for rep in $(seq "$repeats"); do
        name="$transport-$mode-$n-$rep"
        flags=()
        [ "$transport" = udp ] && flags+=(--udp)
        [ "$mode" = shared ] && flags+=(--shared)
        start_server "$server_cpus" --http-port -1 --max-connections 30000 --max-connections-per-address 0 \
          --max-pending-handshakes 30000 --send-budget 0 --log-level warn "${server_flags[@]}"
        per_process=$(clients_per_process)
        processes=$(( (n + per_process - 1) / per_process ))
        pids=(); parts=()
        # Several processes share one window, opened after the slowest
        # set-up (up to about 20 ms per client on an overloaded server).
        window=()
        [ "$processes" -gt 1 ] && window=(--start-at $(( $(date +%s) + 10 + n / 50 )))
        for p in $(seq "$processes"); do
          share=$(( n / processes + (p <= n % processes ? 1 : 0) ))
          part="$out/runs/$name.part$p"
          taskset -c "$load_cpus" "$bin/gmr-load" --port "$(cat "$library/port")" --clients "$share" --rate "$rate" \
            --seconds "$seconds" --warmup 2 --threads "$load_threads" --motion "$motion" --server-pid "$spid" \
            "${window[@]}" "${flags[@]}" --json "$part.json" >"$part.txt" 2>&1 &
          pids+=($!); parts+=("$part.json")
        done
        failed=0
        for pid in "${pids[@]}"; do wait "$pid" || failed=1; done
        if [ "$failed" = 0 ]; then
          "$bin/gmr-load" --merge "${parts[@]}" --json "$out/runs/$name.json" >"$out/runs/$name.txt" 2>&1 || failed=1
        fi
        [ "$failed" = 0 ] || { echo "server bench: $name failed:" >&2; cat "$out/runs/$name".part*.txt >&2; }
        rm -f "$out/runs/$name".part*
        stop_server
        grep -E "^delivered|^latency" "$out/runs/$name.txt" | sed "s/^/$name: /" || true
      done
    done
  done
done
python3 "$here/summarize.py" "$out/runs" "$out/grid.csv" "$out/grid.png"
