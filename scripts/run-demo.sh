#!/usr/bin/env bash
# The main job: write the built-in demo library and show one motion as files,
# then start gmr-server on the built-in library (loopback, a free port) and
# show clients querying it and streaming from it; the server stops at the end
# (or on any failure) through the trap.
set -euo pipefail
build=${1:-build}
gmr="$build/bin/gmr"
server="$build/bin/gmr-server"
out="$build/demo"
"$gmr" demo "$out"
first=$(ls "$out"/*.gmr | head -n 1)
"$gmr" info "$first"
"$gmr" convert "$first" "$out/demo.bvh"
"$gmr" positions "$first" --frames 0:2

if [ ! -x "$server" ]; then
  echo "run-demo: $server not built (GMR_BUILD_NET=OFF): skipping the server demo"
  exit 0
fi
port_file="$out/server.port"
log="$out/server.log"
rm -f "$port_file"
"$server" --port 0 --port-file "$port_file" >"$log" 2>&1 &
server_pid=$!
stop_server() {
  if kill -0 "$server_pid" 2>/dev/null; then
    kill -INT "$server_pid"
    wait "$server_pid" || true
  fi
}
trap stop_server EXIT
for _ in $(seq 100); do
  [ -s "$port_file" ] && break
  if ! kill -0 "$server_pid" 2>/dev/null; then cat "$log" >&2; exit 1; fi
  sleep 0.1
done
[ -s "$port_file" ] || { echo "run-demo: gmr-server did not start" >&2; cat "$log" >&2; exit 1; }
port=$(cat "$port_file")
echo
echo "== gmr-server on 127.0.0.1:$port, built-in library (log: $log)"
"$gmr" ls --port "$port"
echo
echo "== gmr query walk --frames 0:1 --relative-to head (the head's viewpoint)"
"$gmr" query walk --port "$port" --frames 0:1 --relative-to head
echo
echo "== gmr stream walk over TCP: 120 frames at 60 Hz, live summary"
"$gmr" stream walk --port "$port" --count 120 --summary
echo
echo "== gmr stream wave over UDP from l_hand as root: 5 frames of head and hands as CSV"
"$gmr" stream wave --port "$port" --udp --roots l_hand --count 5 --joints head,l_hand,r_hand
echo
kill -INT "$server_pid"
wait "$server_pid"
echo "== gmr-server stopped cleanly (exit 0)"
tail -n 3 "$log"
