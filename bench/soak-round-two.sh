#!/usr/bin/env bash
# The round-two soak (docs/reliability.md, "Soak, round two"): gmr-server
# with its defences as deployed (tokens, anonymous share, per-address limits,
# record budget, an authenticated NATS relay) pinned to CPU 0, and gmr-soak on
# CPU 1 with 200 subscribers holding a token, churn, the first round's
# attacks 5 times a second and round two's twelve kinds 2 times a second, for
# 10 minutes. Samples go to OUT.csv, the server's log to OUT.server.log.
#   bench/soak-round-two.sh [BUILD_DIR] [OUT] [-- gmr-soak flags]
# Not a CI step: ten minutes and both cores. nats-server (scripts/install-deps.sh)
# is used when present; without it the rogue-relay attack is skipped and says so.
set -euo pipefail
build=${1:-build}
out=${2:-$build/soak-round-two}
shift $(( $# < 2 ? $# : 2 ))
[ "${1:-}" = "--" ] && shift
server="$build/bin/gmr-server"
soak="$build/bin/gmr-soak"
for b in "$server" "$soak"; do
  [ -x "$b" ] || { echo "soak: $b not built" >&2; exit 1; }
done
mkdir -p "$(dirname "$out")"
work=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null && wait "$p" 2>/dev/null || true; done
  rm -rf "$work"
}
trap cleanup EXIT

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
secret() { head -c 32 /dev/urandom | base64 | tr -d '/+=' | head -c 40; }

"$soak" --write-library "$work/library"
control=$(secret)
publish=$(secret)
viewer=$(secret)
printf 'control %s\npublish %s\nread %s\n' "$control" "$publish" "$viewer" >"$work/auth"
mkdir "$work/records"
relay_flags=()
soak_relay=()
if command -v nats-server >/dev/null; then
  nats_port=$(free_port)
  nats_password=$(secret)
  printf 'listen: 127.0.0.1:%s\nauthorization {\n  users = [ {user: gmr, password: "%s"} ]\n}\n' \
    "$nats_port" "$nats_password" >"$work/nats.conf"
  printf 'user gmr\npassword %s\n' "$nats_password" >"$work/nats.creds"
  secret >"$work/relay.secret"
  nats-server -c "$work/nats.conf" >"$out.nats.log" 2>&1 &
  pids+=($!)
  for _ in $(seq 100); do (exec 3<>"/dev/tcp/127.0.0.1/$nats_port") 2>/dev/null && break; sleep 0.1; done
  relay_flags=(--nats "nats://127.0.0.1:$nats_port" --nats-creds "$work/nats.creds"
               --relay-secret-file "$work/relay.secret")
  soak_relay=(--nats-port "$nats_port" --nats-user gmr --nats-password "$nats_password")
else
  echo "soak: nats-server not installed (scripts/install-deps.sh): no relay, the rogue-relay attack is skipped" >&2
fi

# 200 token holders come from 127.0.0.1, so one address may hold 256; every
# attack comes from an address of its own (127.0.0.10-17) or from
# 127.0.0.1 without a token. 512 connections: 128 for clients without one.
# The record budget is small so that ten minutes reach both of its bounds.
taskset -c 0 "$server" --library "$work/library" --port 0 --port-file "$work/port" \
  --http-port-file "$work/http_port" --auth-file "$work/auth" \
  --max-connections 512 --max-connections-per-address 256 \
  --record-dir "$work/records" --max-record-total-bytes $((64 << 20)) --max-record-dir-bytes $((512 << 20)) \
  "${relay_flags[@]}" >"$out.server.log" 2>&1 &
server_pid=$!
pids=("$server_pid" "${pids[@]}")
for _ in $(seq 300); do
  [ -s "$work/port" ] && [ -s "$work/http_port" ] && break
  kill -0 "$server_pid" 2>/dev/null || { cat "$out.server.log" >&2; exit 1; }
  sleep 0.1
done
[ -s "$work/port" ] || { echo "soak: gmr-server did not start" >&2; exit 1; }
ulimit -n 65536 2>/dev/null || ulimit -n "$(ulimit -Hn)"
status=0
taskset -c 1 "$soak" --port "$(cat "$work/port")" --http-port "$(cat "$work/http_port")" \
  --server-pid "$server_pid" --token "$control" --publish-token "$publish" --read-token "$viewer" "${soak_relay[@]}" \
  --clients 200 --round-two 2 --csv "$out.csv" "$@" || status=$?
echo "server log: $(wc -l <"$out.server.log") lines, $(wc -c <"$out.server.log") bytes"
echo "record directory: $(du -sb "$work/records" | cut -f1) bytes in $(find "$work/records" -type f | wc -l) files"
kill -0 "$server_pid" 2>/dev/null || { echo "soak: gmr-server is gone" >&2; status=3; }
exit "$status"
