#!/usr/bin/env bash
# The main job: write the built-in demo library and show one motion as files,
# then start gmr-server on the built-in library (loopback, a free port; the
# browser viewer on http://127.0.0.1:7480/, or a free port when 7480 is taken)
# and show clients querying it and streaming from it. In a terminal the
# server then keeps serving the viewer until Ctrl-C; otherwise (CI, scripts,
# GMR_DEMO_KEEP=0) it stops at the end. It stops on any failure through the trap.
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
http_port_file="$out/server.http-port"
log="$out/server.log"
keep=${GMR_DEMO_KEEP:-}
if [ -z "$keep" ]; then
  if [ -t 0 ] && [ -t 1 ]; then keep=1; else keep=0; fi
fi
server_pid=
stop_server() {
  if [ -n "$server_pid" ] && kill -0 "$server_pid" 2>/dev/null; then
    kill -INT "$server_pid"
    wait "$server_pid" || true
  fi
}
trap stop_server EXIT
# The viewer's usual port, else any free one.
for http_port in "${GMR_HTTP_PORT:-7480}" 0; do
  rm -f "$port_file" "$http_port_file"
  "$server" --port 0 --port-file "$port_file" --http-port "$http_port" --http-port-file "$http_port_file" \
    >"$log" 2>&1 &
  server_pid=$!
  for _ in $(seq 100); do
    [ -s "$port_file" ] && [ -s "$http_port_file" ] && break
    kill -0 "$server_pid" 2>/dev/null || break
    sleep 0.1
  done
  [ -s "$http_port_file" ] && break
  wait "$server_pid" 2>/dev/null || true
  server_pid=
  grep -q "cannot bind HTTP" "$log" || { echo "run-demo: gmr-server did not start" >&2; cat "$log" >&2; exit 1; }
done
[ -n "$server_pid" ] || { echo "run-demo: gmr-server did not start" >&2; cat "$log" >&2; exit 1; }
port=$(cat "$port_file")
http_port=$(cat "$http_port_file")
viewer="http://127.0.0.1:$http_port/"
echo
echo "== gmr-server on 127.0.0.1:$port, built-in library (log: $log)"
echo "== the viewer: $viewer  (metrics: ${viewer}metrics)"
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
if [ "$keep" = 1 ]; then
  echo "== gmr-server keeps serving: open $viewer in a browser, click a joint, make it the root or"
  echo "   view the motion from it. Ctrl-C stops the server."
  trap 'echo; echo "== stopping"; kill -INT "$server_pid" 2>/dev/null || true' INT
  wait "$server_pid" || true
  wait "$server_pid" 2>/dev/null || true
  server_pid=
  echo "== gmr-server stopped"
  tail -n 3 "$log"
  exit 0
fi
kill -INT "$server_pid"
wait "$server_pid"
server_pid=
echo "== gmr-server stopped cleanly (exit 0)"
tail -n 3 "$log"
