# The two commands a newcomer needs:
#   make run    installs what is missing, builds, and runs the main job
#   make test   installs what is missing, builds, and runs every test
BUILD ?= build
ASAN_BUILD ?= build-sanitize
TSAN_BUILD ?= build-tsan
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?=

.PHONY: setup configure build run test test-unit test-sanitize test-tsan fuzz fuzz-smoke clean

setup:
	@scripts/install-deps.sh

configure: setup
	@cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release $(CMAKE_FLAGS) >/dev/null

build: configure
	@cmake --build $(BUILD) -j $(JOBS)

run: build
	@scripts/run-demo.sh $(BUILD)

test-unit: build
	@cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

# The core, readers, operations and server tests under AddressSanitizer and
# UndefinedBehaviorSanitizer (Debug: slow paths check fewer frames there),
# built with clang: so gmr builds with both of Debian's compilers. The same
# tree builds the libFuzzer harnesses that fuzz-smoke runs, with coverage only
# in the code they fuzz (GMR_FUZZ_HARNESSES): the library and the server are
# built under ASan once, not twice (a tree of their own was 8 of CI's minutes).
test-sanitize: setup
	@cmake -S . -B $(ASAN_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Debug -DGMR_SANITIZE=ON \
	  -DGMR_FUZZ=OFF -DGMR_FUZZ_HARNESSES=ON -DCMAKE_CXX_COMPILER=clang++ \
	  -DGMR_BUILD_BENCH=OFF -DGMR_BUILD_NET=ON -DGMR_BUILD_TOOLS=OFF >/dev/null
	@cmake --build $(ASAN_BUILD) -j $(JOBS) --target gmr_sanitize_tests gmr_fuzzers
	@cd $(ASAN_BUILD) && ctest --output-on-failure -j $(JOBS) -L sanitize

# The server and client tests (the server's thread, the clients' shared
# EventLoop threads, 1,000 subscribers across them) under ThreadSanitizer; a
# race fails the test (TSan's exit code). Only gmr_net_tests is built here,
# at -O1: every access is still instrumented, and a server file compiles in a
# fifth less time than at -O2.
test-tsan: setup
	@cmake -S . -B $(TSAN_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DGMR_TSAN=ON \
	  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g -DNDEBUG" \
	  -DCMAKE_CXX_COMPILER=clang++ -DGMR_BUILD_BENCH=OFF -DGMR_BUILD_NET=ON >/dev/null
	@cmake --build $(TSAN_BUILD) -j $(JOBS) --target gmr_net_tests
	@cd $(TSAN_BUILD) && ctest --output-on-failure -j $(JOBS) -L sanitize -E '_NOT_BUILT$$'

# Coverage-guided fuzzing (libFuzzer, clang, ASan/UBSan) of every reader and
# the wire decoders, FUZZ_SECONDS each (default 60), seeded from ../shared/data
# (scripts/fuzz.sh; longer runs' figures are in docs/reliability.md), in an
# optimised tree of its own (build-fuzz) instrumented everywhere.
fuzz: setup
	@scripts/fuzz.sh

# What make test fuzzes: every harness for FUZZ_SECONDS (default 10) from its
# seeds, with the harnesses the sanitizer tree built (Debug, coverage where
# they fuzz: fewer runs a second than make fuzz, the same checks).
fuzz-smoke: test-sanitize
	@FUZZ_BUILD=$(ASAN_BUILD) FUZZ_PREBUILT=1 FUZZ_SECONDS=$${FUZZ_SECONDS:-10} scripts/fuzz.sh

test: test-unit test-sanitize test-tsan fuzz-smoke

clean:
	rm -rf $(BUILD) $(ASAN_BUILD) $(TSAN_BUILD) build-fuzz
