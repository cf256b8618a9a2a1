#!/usr/bin/env bash
# Coverage-guided fuzzing of every reader and the wire decoders (libFuzzer,
# with ASan and UBSan), each for FUZZ_SECONDS (default 60; make fuzz-smoke, in
# CI, sets 10; the long runs' figures are in docs/reliability.md), two at a time.
# Seeds: the corpus files of ../shared/data with the harness's extension, and
# fuzz/seeds/<harness>/ (files made here: .gmr has no third-party corpus).
# A crash (or a failed property) stops that harness, keeps the input in
# $BUILD/artifacts/ (build-fuzz, or the sanitizer tree for make fuzz-smoke)
# and makes this script fail; turn it into a test.
#   scripts/fuzz.sh [harness ...]      (default: all)
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${FUZZ_BUILD:-build-fuzz}
SECONDS_EACH=${FUZZ_SECONDS:-60}
JOBS=${JOBS:-$(nproc)}
DATA=../shared/data

if [ "${FUZZ_PREBUILT:-}" = 1 ]; then
  # make fuzz-smoke: the sanitizer tree (GMR_FUZZ_HARNESSES, configured by
  # make test-sanitize) built the harnesses; configuring it here would undo that.
  [ -x "$BUILD/fuzz/gmr_fuzz_bvh" ] || { echo "fuzz: no harnesses in $BUILD/fuzz (make test-sanitize builds them)" >&2; exit 1; }
else
  cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ -DGMR_FUZZ=ON \
    -DGMR_BUILD_TESTS=OFF -DGMR_BUILD_BENCH=OFF -DGMR_BUILD_TOOLS=OFF -DGMR_BUILD_NET=ON -DGMR_INSTALL=OFF >/dev/null
  cmake --build "$BUILD" -j "$JOBS" --target gmr_fuzzers
fi

harnesses=("$@")
[ ${#harnesses[@]} -eq 0 ] && harnesses=(bvh gmr gmrb asf amc c3d trc csv model wire requests client)
if [ ! -d "$DATA" ]; then
  if [ "${CI:-}" = true ]; then echo "fuzz: $DATA is missing (needed for the seed corpora in CI)" >&2; exit 1; fi
  echo "fuzz: $DATA not found: starting from empty corpora" >&2
fi
mkdir -p "$BUILD/artifacts" "$BUILD/logs"

# Seeds: files of the harness's kind (the wire harness from three frames in fuzz/seeds/wire;
# the request harness from the sessions its seed program writes).
seed() {
  local name=$1 dir=$BUILD/corpus/$1
  mkdir -p "$dir"
  if [ -d "fuzz/seeds/$name" ]; then cp -n fuzz/seeds/"$name"/* "$dir"/ 2>/dev/null || true; fi
  if [ "$name" = requests ]; then "$BUILD/fuzz/gmr_fuzz_requests_seeds" "$dir" >/dev/null; fi
  [ -d "$DATA" ] || return 0
  local exts
  case $name in
    bvh) exts="bvh" ;; gmr) exts="gmr" ;; gmrb) exts="gmrb" ;; asf) exts="asf" ;;
    amc) exts="amc" ;; c3d) exts="c3d" ;; trc) exts="trc" ;; *) return 0 ;;
  esac
  for e in $exts; do
    find "$DATA" -type f -iname "*.$e" -size -2M -exec cp -n {} "$dir"/ \; 2>/dev/null || true
  done
}

run() {
  local name=$1
  seed "$name"
  local log=$BUILD/logs/$name.log
  if "$BUILD/fuzz/gmr_fuzz_$name" "$BUILD/corpus/$name" -max_total_time="$SECONDS_EACH" -max_len=65536 \
      -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$BUILD/artifacts/$name-" >"$log" 2>&1; then
    echo "fuzz $name: $(grep -E '^stat::number_of_executed_units' "$log" | awk '{print $2}') runs," \
         "$(grep -E '^#[0-9]+.*DONE' "$log" | grep -oE 'cov: [0-9]+' | tail -1), no crash ($SECONDS_EACH s)"
  else
    echo "fuzz $name: FAILED; the input is in $BUILD/artifacts/, the log is $log:" >&2
    grep -E 'ERROR|SUMMARY|property failed|Test unit written' "$log" | head -20 >&2
    return 1
  fi
}

failed=0
running=0
pids=()
names=()
for h in "${harnesses[@]}"; do
  run "$h" &
  pids+=($!)
  names+=("$h")
  running=$((running + 1))
  if [ "$running" -ge "$JOBS" ]; then
    wait "${pids[0]}" || failed=1
    pids=("${pids[@]:1}")
    running=$((running - 1))
  fi
done
for p in "${pids[@]}"; do wait "$p" || failed=1; done
exit $failed
