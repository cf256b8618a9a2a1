#!/usr/bin/env bash
# The main job: for now, write the built-in demo library and show one motion.
set -euo pipefail
build=${1:-build}
gmr="$build/bin/gmr"
out="$build/demo"
"$gmr" demo "$out"
first=$(ls "$out"/*.gmr | head -n 1)
"$gmr" info "$first"
"$gmr" convert "$first" "$out/demo.bvh"
"$gmr" positions "$first" --frames 0:2
