#!/usr/bin/env bash
# Builds the gmr-server container image (docker/Dockerfile) with podman from a
# Debian 12 base made by mmdebstrap (no image registry needed), runs gmr-server
# in it, streams from the host with `gmr stream`, and checks that the Compose
# file's server service starts. Prints the image size and what each step saw;
# docs/deployment.md, "The image", has a run's output. Not a CI step: it
# downloads about 300 MB of Debian packages and compiles for several minutes.
#   scripts/image-test.sh [BUILD_DIR]     (BUILD_DIR: the host's gmr build, for `gmr stream`; default build)
# Needs root (or sudo) to install podman, runc, mmdebstrap and podman-compose
# when they are missing. Docker works the same from debian:12:
#   docker build -f docker/Dockerfile -t gmr-server .
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
gmr="$build/bin/gmr"
[ -x "$gmr" ] || { echo "image-test: $gmr not built (make build)" >&2; exit 1; }

sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
need=()
for p in podman runc mmdebstrap podman-compose uidmap slirp4netns; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || need+=("$p")
done
if [ ${#need[@]} -gt 0 ]; then
  echo "image-test: installing ${need[*]}"
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${need[@]}"
fi
work=$(mktemp -d)
# runc, not crun, and explicit limits: what runs containers on this machine
# kind (crun, and runc with the default limits, fail inside some sandboxes:
# "error setting rlimit type 7"). For podman and podman-compose alike.
cat >"$work/containers.conf" <<'EOF'
[containers]
default_ulimits = ["nofile=1024:1024", "nproc=1000:1000"]
[engine]
runtime = "runc"
EOF
export CONTAINERS_CONF="$work/containers.conf"
container=""
compose_up=false
made_library=false
cleanup() {
  $made_library && rmdir docker/library 2>/dev/null || true
  [ -n "$container" ] && podman rm -f "$container" >/dev/null 2>&1 || true
  $compose_up && (cd docker && podman-compose -f compose.yaml down >/dev/null 2>&1) || true
  rm -rf "$work"
}
trap cleanup EXIT
step() { echo; echo "== $*"; }

base=localhost/debian:bookworm
if ! podman image exists "$base"; then
  step "a Debian 12 base with mmdebstrap (minbase)"
  start=$(date +%s)
  $sudo mmdebstrap --variant=minbase bookworm "$work/base.tar" >"$work/mmdebstrap.log" 2>&1 ||
    { cat "$work/mmdebstrap.log" >&2; exit 1; }
  podman import "$work/base.tar" "$base" >/dev/null
  echo "base: $(du -h "$work/base.tar" | cut -f1) in $(( $(date +%s) - start )) s"
fi

step "podman build -f docker/Dockerfile -t gmr-server"
start=$(date +%s)
podman build --ignorefile docker/Dockerfile.dockerignore -f docker/Dockerfile \
  --build-arg BASE="$base" --build-arg RUNTIME_BASE="$base" -t localhost/gmr-server:latest . >"$work/build.log" 2>&1 ||
  { tail -40 "$work/build.log" >&2; exit 1; }
echo "built in $(( $(date +%s) - start )) s"
size=$(podman image inspect localhost/gmr-server:latest --format '{{.Size}}')
echo "image size: $(( size / 1000000 )) MB ($size bytes)"
echo "runtime libraries, by ldd inside the image:"
podman run --rm --entrypoint sh localhost/gmr-server:latest -c \
  'ldd /usr/local/bin/gmr-server | awk "{print \$1}" | sort | tr "\n" " "; echo; \
   ldd /usr/local/bin/gmr-server /usr/local/bin/gmr /usr/local/bin/gmr-load | grep -c "not found" || true'

step "gmr-server in the image, streamed from the host"
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
http=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
container=$(podman run -d -p "127.0.0.1:$port:7400/tcp" -p "127.0.0.1:$http:7480/tcp" \
  localhost/gmr-server:latest)
for _ in $(seq 100); do
  curl -fsS "http://127.0.0.1:$http/readyz" >/dev/null 2>&1 && break
  sleep 0.2
done
echo "readyz: $(curl -sS "http://127.0.0.1:$http/readyz")"
"$gmr" ls --port "$port"
"$gmr" stream walk --port "$port" --count 60 >"$work/stream.csv"
echo "gmr stream walk --count 60: $(( $(wc -l <"$work/stream.csv") - 1 )) rows (60 frames x 22 joints)"
"$gmr" stream walk --port "$port" --count 120 --summary | tail -1
"$gmr" query walk --port "$port" --frames 0:1 | head -3
echo "server log:"
podman logs "$container" 2>&1 | sed 's/^/  /' | head -12
podman stop -t 10 "$container" >/dev/null
echo "stopped: exit status $(podman inspect "$container" --format '{{.State.ExitCode}}')"
podman rm "$container" >/dev/null
container=""

step "docker/compose.yaml: the server service with podman-compose"
# The Compose file mounts ./library (empty: the built-in demo is served).
[ -d docker/library ] || { mkdir docker/library; made_library=true; }
podman tag localhost/gmr-server:latest gmr-server >/dev/null 2>&1 || true
(cd docker && podman-compose -f compose.yaml down >/dev/null 2>&1) || true
compose_up=true
(cd docker && podman-compose -f compose.yaml up -d --no-build server >"$work/compose.log" 2>&1) ||
  { cat "$work/compose.log" >&2; exit 1; }
for _ in $(seq 100); do
  curl -fsS "http://127.0.0.1:7480/readyz" >/dev/null 2>&1 && break
  sleep 0.2
done
ready=$(curl -sS http://127.0.0.1:7480/readyz || echo 'no answer')
echo "compose server readyz: $ready"
"$gmr" ls --port 7400 | head -3
(cd docker && podman-compose -f compose.yaml down >>"$work/compose.log" 2>&1) || true
compose_up=false
case "$ready" in ready*) ;; *) cat "$work/compose.log" >&2; exit 1 ;; esac
echo
echo "image-test: OK"
