#!/usr/bin/env bash
# Installs every Debian package gmr needs to build, test and benchmark.
# Works as root or through sudo; does nothing when everything is already there.
#   scripts/install-deps.sh           everything (build, tests, benchmarks, interop)
#   scripts/install-deps.sh --build   only what building gmr-server, gmr and gmr-load needs
#                                     (the container image's build stage: docker/Dockerfile)
set -euo pipefail

build_packages=(
  build-essential cmake ninja-build pkg-config
  libeigen3-dev libhwy-dev libcli11-dev nlohmann-json3-dev libspdlog-dev libfmt-dev
  libboost-dev libboost-system-dev prometheus-cpp-dev libnats-dev libssl-dev
  libprotobuf-dev protobuf-compiler
)

packages=(
  build-essential cmake ninja-build pkg-config
  libeigen3-dev            # the math: vectors, matrices, quaternions
  libgtest-dev libgmock-dev # tests
  libbenchmark-dev          # benchmarks in bench/
  liburing-dev              # bench/udp_send_bench.cpp: io_uring against sendmmsg for the UDP fan-out
  libhwy-dev                # Highway: run-time SIMD dispatch for the fast FK path
  libcli11-dev              # argument parsing for the gmr and gmr-server commands
  nlohmann-json3-dev        # JSON: gmr-bench fk --json, gmr-load --json and --merge
  libspdlog-dev libfmt-dev  # logging outside lib/
  libboost-dev libboost-system-dev # Boost.Asio for the server and client; Boost.Beast for HTTP and WebSocket
  prometheus-cpp-dev        # /metrics in the Prometheus text format
  iproute2 util-linux       # the multicast test runs in a network namespace of its own (ip, unshare)
  libnats-dev nats-server   # replicas share live sources through NATS (the replica test starts nats-server)
  libjs-three               # three.js for the browser viewer, served by gmr-server (no CDN)
  libssl-dev                # OpenSSL: TLS (Asio's SSL), token digests, the tests' certificates
  libprotobuf-dev protobuf-compiler # the wire protocol
  gnuplot-nox               # plots: gmr-bench figure4, gmr-load --plot, bench/server
  python3                   # the layout check (tests/layout/check_layout.py)
  python3-protobuf python3-numpy # the Python client (client/python) and the Blender add-on
  python3-prometheus-client # the metrics test parses /metrics with Prometheus's own parser
  chromium                  # the viewer test: the page in a real headless browser
  clang libclang-rt-14-dev  # the sanitizer build uses clang (gmr builds with GCC and clang)
  clang-format              # the C and C++ style, checked on every file (scripts/check-format.sh)
  blender                   # the interop test: Blender's own BVH importer reads what gmr writes
  nodejs npm                # the interop test: three.js's BVHLoader (npm, tests/interop/package.json)
  libassimp-dev             # the interop test: Assimp's BVH importer
  godot3-server             # the Godot add-on's test: client/godot in a real (headless) Godot 3
  mono-mcs mono-runtime     # the C# package's test: client/csharp compiled with mcs, run under Mono
)

build_only=false
if [ "${1:-}" = --build ]; then
  build_only=true
  packages=("${build_packages[@]}")
fi

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
# Debian's nodejs and npm, unless a node is already there (node from another
# source ships its own npm, which Debian's npm package would conflict with).
if command -v node >/dev/null && command -v npm >/dev/null; then
  kept=()
  for p in "${missing[@]}"; do [ "$p" = nodejs ] || [ "$p" = npm ] || kept+=("$p"); done
  missing=("${kept[@]}")
fi

# The npm packages of the JS-side tests, pinned by tests/interop/package-lock.json
# and tests/deploy/package-lock.json (the Kubernetes manifests' schema check).
npm_packages() {
  local root dir
  $build_only && return 0
  root="$(cd "$(dirname "$0")/.." && pwd)"
  dir="$root/tests/interop"
  if [ ! -f "$dir/node_modules/three/package.json" ]; then
    echo "install-deps: npm ci in tests/interop"
    (cd "$dir" && npm ci --no-audit --no-fund --loglevel=error)
  fi
  dir="$root/tests/deploy"
  if [ ! -f "$dir/node_modules/kubernetes-models/package.json" ] || [ ! -f "$dir/node_modules/yaml/package.json" ]; then
    echo "install-deps: npm ci in tests/deploy"
    (cd "$dir" && npm ci --no-audit --no-fund --loglevel=error)
  fi
}

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  npm_packages
  exit 0
fi

sudo=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
  sudo="sudo"
fi
echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
npm_packages
