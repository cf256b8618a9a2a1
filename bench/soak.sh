#!/usr/bin/env bash
# The soak benchmark (docs/reliability.md, "Soak"): gmr-server on the demo
# library, pinned to CPU 0, and gmr-soak on CPU 1 with 1,000 steady clients,
# churn and hostile clients for 10 minutes; the samples go to OUT.csv and the
# server's log to OUT.server.log.
#   bench/soak.sh [BUILD_DIR] [OUT] [-- gmr-soak flags]
# Not a CI step: ten minutes and both cores.
set -euo pipefail
build=${1:-build}
out=${2:-$build/soak}
shift $(( $# < 2 ? $# : 2 ))
[ "${1:-}" = "--" ] && shift
server="$build/bin/gmr-server"
soak="$build/bin/gmr-soak"
for b in "$server" "$soak"; do
  [ -x "$b" ] || { echo "soak: $b not built" >&2; exit 1; }
done
mkdir -p "$(dirname "$out")"
port_file=$(mktemp)
rm -f "$port_file"
# Every client is on 127.0.0.1: no per-address limit, room for 1,000 steady
# clients plus the hostile ones; no send budget, so that the hostile clients'
# 2 kHz subscriptions are admitted and press on memory.
taskset -c 0 "$server" --port 0 --port-file "$port_file" --max-connections 4096 \
  --max-connections-per-address 0 --send-budget 0 --log-level warn >"$out.server.log" 2>&1 &
server_pid=$!
stop_server() {
  kill -INT "$server_pid" 2>/dev/null && wait "$server_pid" || true
  rm -f "$port_file"
}
trap stop_server EXIT
for _ in $(seq 100); do
  [ -s "$port_file" ] && break
  kill -0 "$server_pid" 2>/dev/null || { cat "$out.server.log" >&2; exit 1; }
  sleep 0.1
done
[ -s "$port_file" ] || { echo "soak: gmr-server did not start" >&2; exit 1; }
ulimit -n 65536 2>/dev/null || ulimit -n "$(ulimit -Hn)"
taskset -c 1 "$soak" --port "$(cat "$port_file")" --server-pid "$server_pid" --csv "$out.csv" "$@"
