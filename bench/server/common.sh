# shellcheck shell=bash disable=SC2154  # bin, motion_file, bench_name: the sourcing script's
# What the bench/server scripts share; sourced once they have set `bin` (the
# build's bin folder), `motion_file` and `bench_name` (for their messages):
#
#   library, motion           a fresh folder holding a link to motion_file, and
#                             the motion's name there; removed at exit
#   start_server CPUS ARGS... gmr-server on the library, pinned to CPUS, with
#                             ARGS; returns once it wrote its port to
#                             $library/port (its log: $library/server.log)
#   stop_server               stops it (SIGINT) and waits; spid is its pid
library=$(mktemp -d)
ln -s "$(realpath "$motion_file")" "$library/"
motion=$(basename "$motion_file"); motion=${motion%.*}
spid=""
start_server() {
  local cpus=$1
  shift
  rm -f "$library/port"
  taskset -c "$cpus" "$bin/gmr-server" --library "$library" --port 0 --port-file "$library/port" "$@" \
    >"$library/server.log" 2>&1 &
  spid=$!
  for _ in $(seq 300); do [ -s "$library/port" ] && return; sleep 0.1; done
  echo "$bench_name: gmr-server did not start:" >&2; cat "$library/server.log" >&2; exit 1
}
stop_server() { [ -n "$spid" ] && kill -INT "$spid" 2>/dev/null && wait "$spid" 2>/dev/null; spid=""; }
trap 'stop_server || true; rm -rf "$library"' EXIT
