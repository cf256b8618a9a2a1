// What a server's streams pay for forward kinematics (server/src/streams/fk_blocks.h):
// N streams of CMU 01_01 at 120 Hz, each its own distance into the take (as
// clients subscribing at different times are), ticking together. Per tick
// every stream asks for its frame and reads it (here: sums its positions,
// as view_frame_float reads them), by
//   alone   the one-frame kernel per stream and tick (FkFrameJob; the server before FkBlocks, and --fk-cache-mb 0)
//   blocks  FkBlocks: 16 frames computed at once by the range kernel, kept for every stream
// Reported per frame a stream gets. Run from the repository root:
//   build/bin/gmr_stream_fk_bench
#include <benchmark/benchmark.h>

#include "bench_data.h"
#include "streams/fk_blocks.h"
#include "gmr/fast/compiled_motion.h"
#include "gmr/fast/fast_fk.h"
#include "gmr/server/view.h"

namespace {

using gmr::server::CompiledForm;
using gmr::server::FkBlocks;

const std::shared_ptr<const CompiledForm>& form() {
  static const std::shared_ptr<const CompiledForm> f = [] {
    auto pre = gmr::to_pre_rotation(gmr::bench::load_main_bvh());
    if (!pre) gmr::bench::die(pre.error().to_string());
    auto c = std::make_shared<const CompiledForm>(std::make_shared<const gmr::Motion>(std::move(*pre)));
    if (c->get() == nullptr) gmr::bench::die("01_01 did not compile");
    return c;
  }();
  return f;
}

// Stream s starts 2752 * s / N frames into the take (spread evenly).
std::size_t frame_of(std::size_t s, std::size_t streams, std::size_t tick, std::size_t frames) {
  return (frames * s / streams + tick) % frames;
}

float sum(std::span<const float> p) {
  float t = 0;
  for (float x : p) t += x;
  return t;
}

void BM_Alone(benchmark::State& state) {
  const auto streams = static_cast<std::size_t>(state.range(0));
  const bool orient = state.range(1) != 0;
  const gmr::fast::CompiledMotion& cm = *form()->get();
  const std::size_t n = cm.joint_count(), frames = cm.frame_count();
  std::vector<float> ws(form()->workspace_floats()), p(n * 3), o(orient ? n * 9 : 0);
  std::size_t tick = 0;
  for (auto _ : state) {
    float t = 0;
    for (std::size_t s = 0; s < streams; ++s) {
      gmr::fast::FkFrameJob job{&cm, frame_of(s, streams, tick, frames), p, o, ws};
      job.run();
      t += sum(p);
    }
    benchmark::DoNotOptimize(t);
    ++tick;
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * streams));
}

void BM_Blocks(benchmark::State& state) {
  const auto streams = static_cast<std::size_t>(state.range(0));
  const bool orient = state.range(1) != 0;
  const std::size_t frames = form()->get()->frame_count();
  std::vector<float> ws(form()->workspace_floats());
  FkBlocks blocks(std::size_t{32} << 20);
  std::size_t tick = 0;
  for (auto _ : state) {
    float t = 0;
    for (std::size_t s = 0; s < streams; ++s) {
      const auto pose = blocks.frame(form(), frame_of(s, streams, tick, frames), orient, ws);
      t += sum(pose->positions);
    }
    benchmark::DoNotOptimize(t);
    ++tick;
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * streams));
  state.counters["blocks_per_tick"] =
      static_cast<double>(blocks.blocks_computed()) / static_cast<double>(std::max<std::size_t>(1, tick));
}

void args(benchmark::internal::Benchmark* b) {
  b->ArgNames({"streams", "orient"});
  for (int orient : {0, 1}) {
    for (int streams : {1, 100, 1000}) b->Args({streams, orient});
  }
}

}  // namespace

BENCHMARK(BM_Alone)->Name("stream_fk/alone")->Apply(args);
BENCHMARK(BM_Blocks)->Name("stream_fk/blocks")->Apply(args);
BENCHMARK_MAIN();
