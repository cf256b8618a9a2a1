#!/usr/bin/env bash
# Multicast's cost (docs/performance.md, "Multicast"): one shared stream at
# RATE Hz to N subscribers over the server's multicast group, the server's
# CPU over the window, pinned to CPU 0 with gmr-load on CPU 1.
#
#   bench/server/multicast.sh [BUILD_DIR] [OUT_DIR]
#     SUBSCRIBERS="1 1000 10000"  REPEATS=3  SECONDS_PER_POINT=10  RATE=120
#     SERVER_FLAGS="--heartbeat-ms 15000"  (more gmr-server options)
#
# Runs itself again inside a network namespace of its own (unshare -n, so
# root): the group is routed out of a veth pair nobody listens on, as a LAN
# interface would carry it, while the clients talk to the server over
# loopback (their group membership is on loopback, so the kernel hands them
# no copies): the server's cost alone, whatever the receivers. Writes
# OUT_DIR/multicast-N-R.json (gmr-load --json) and OUT_DIR/multicast.csv
# (median server cores and ns per frame sent to the group).
set -euo pipefail
build=$(realpath "${1:-build}")
out=$(realpath -m "${2:-bench/server/results}")
if [ "${GMR_IN_NETNS:-}" != 1 ]; then
  exec unshare -n env GMR_IN_NETNS=1 "$0" "$build" "$out"
fi
subscribers=${SUBSCRIBERS:-1 1000 10000}
repeats=${REPEATS:-3}
seconds=${SECONDS_PER_POINT:-10}
rate=${RATE:-120}
motion_file=${MOTION_FILE:-../shared/data/bvh/cmu/01_01.bvh}
bin="$build/bin"
[ -x "$bin/gmr-server" ] && [ -x "$bin/gmr-load" ] || { echo "multicast bench: build gmr-server and gmr-load in $build" >&2; exit 1; }
[ -f "$motion_file" ] || { echo "multicast bench: no $motion_file (../shared/data, or set MOTION_FILE)" >&2; exit 1; }
ip link set lo up
ip link add mc0 type veth peer name mc1
ip addr add 10.77.0.1/24 dev mc0
ip link set mc0 up
ip link set mc1 up
ip route add 224.0.0.0/4 dev mc0
ulimit -n "$(ulimit -Hn)"

mkdir -p "$out"
bench_name="multicast bench"
# shellcheck source=bench/server/common.sh
. "$(dirname "$0")/common.sh"
echo "subscribers,repeat,server_cores,ns_per_multicast_frame,multicast_frames_sent" >"$out/multicast.csv"
for n in $subscribers; do
  for rep in $(seq "$repeats"); do
    # Bound to every address: the group leaves by its route (mc0), not loopback.
    # shellcheck disable=SC2086  # SERVER_FLAGS: options, split on spaces
    start_server 0 --bind 0.0.0.0 --http-port -1 --max-connections 30000 --max-connections-per-address 0 \
      --max-pending-handshakes 30000 --send-budget 0 --multicast-group 239.255.74.9 --multicast-port 17600 \
      --log-level warn ${SERVER_FLAGS:-}
    name="multicast-$n-$rep"
    # A client holds three sockets (TCP, UDP, the group's): past the
    # open-files limit, several processes measure one window (--merge).
    per_process=$(( ($(ulimit -n) - 200) / 3 ))
    processes=$(( (n + per_process - 1) / per_process ))
    window=()
    [ "$processes" -gt 1 ] && window=(--start-at $(( $(date +%s) + 15 + n / 200 )))
    pids=(); parts=()
    for p in $(seq "$processes"); do
      share=$(( n / processes + (p <= n % processes ? 1 : 0) ))
      taskset -c 1 "$bin/gmr-load" --host 127.0.0.1 --port "$(cat "$library/port")" --clients "$share" --rate "$rate" \
        --seconds "$seconds" --warmup 2 --motion "$motion" --multicast --server-pid "$spid" "${window[@]}" \
        --json "$out/$name.part$p.json" >"$out/$name.part$p.txt" 2>&1 &
      pids+=($!); parts+=("$out/$name.part$p.json")
    done
    failed=0
    for pid in "${pids[@]}"; do wait "$pid" || failed=1; done
    [ "$failed" = 0 ] && "$bin/gmr-load" --merge "${parts[@]}" --json "$out/$name.json" >"$out/$name.txt" 2>&1 || failed=1
    [ "$failed" = 0 ] || { echo "multicast bench: $name failed:" >&2; cat "$out/$name".part*.txt >&2; exit 1; }
    rm -f "$out/$name".part*
    stop_server
    python3 - "$out/$name.json" "$n" "$rep" >>"$out/multicast.csv" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
sent = j["server"]["multicast_frames_sent"]
cpu = j["server_cpu_seconds"]
print(f"{sys.argv[2]},{sys.argv[3]},{cpu / j['seconds']:.4f},{1e9 * cpu / max(sent, 1):.0f},{sent}")
PY
    tail -1 "$out/multicast.csv"
  done
done
