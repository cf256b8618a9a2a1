// What the server pays to accept one frame of a live source
// (server/src/live/live_source.h, LiveSource::push: checked, kept as the newest frame,
// handed to the source's streams), with no stream attached: the cost every
// published frame has before any subscriber. CMU 01_01's skeleton (38 joints,
// 96 channels) as a publisher would announce it, and the same skeleton with
// every joint a root (what `gmr publish positions.csv` announces). Run from
// the repository root:
//   build/bin/gmr_live_push_bench
#include <benchmark/benchmark.h>

#include "bench_data.h"
#include "gmr/ops/convert.h"
#include "gmr/ops/set_roots.h"
#include "live/live_source.h"

namespace {

const gmr::Motion& cmu(bool all_roots) {
  static const gmr::Motion pre = [] {
    auto p = gmr::to_pre_rotation(gmr::bench::load_main_bvh());
    if (!p) gmr::bench::die(p.error().to_string());
    return std::move(*p);
  }();
  static const gmr::Motion roots = [] {
    std::vector<int> every(pre.skeleton.size());
    for (std::size_t j = 0; j < every.size(); ++j) every[j] = static_cast<int>(j);
    auto r = gmr::set_roots(pre, every);
    if (!r) gmr::bench::die(r.error().to_string());
    return std::move(*r);
  }();
  return all_roots ? roots : pre;
}

void BM_LivePush(benchmark::State& state) {
  const gmr::Motion& m = cmu(state.range(0) == 1);
  gmr::server::LiveSource source("bench", 1, m.skeleton, m.frame_time, 0.0);
  std::size_t f = 0;
  // Each frame arrives one frame time after the one before, as the declared
  // rate says (faster, RateHold would drop them: the cheap path, not this one).
  auto at = gmr::server::Clock::now();
  const auto step =
      std::chrono::duration_cast<gmr::server::Clock::duration>(std::chrono::duration<double>(m.frame_time));
  for (auto _ : state) {
    at += step;
    auto s = source.push(m.frame(f), std::nullopt, at);
    if (!s.ok()) gmr::bench::die(s.error().to_string());
    if (s.value() != gmr::server::LiveSource::Pushed::kSent)
      gmr::bench::die("a frame at the declared rate was dropped");
    benchmark::DoNotOptimize(source.latest().get());
    f = (f + 1) % m.frame_count;
  }
  state.SetLabel(std::to_string(m.skeleton.size()) + " joints, " + std::to_string(m.stride()) + " channels");
}
BENCHMARK(BM_LivePush)->Name("live/push")->Arg(0)->Arg(1);

}  // namespace

BENCHMARK_MAIN();
