// What retargeting costs per frame (docs/retarget.md, "Cost"): CMU 01_01 as
// ASF/AMC (31 joints) onto the corpus's Character Creator rig and its Mixamo
// rig, the whole take per iteration (planning included, under 0.1% of it);
// items/s is frames/s. Also the plan alone, which a live subscription pays once.
#include <benchmark/benchmark.h>

#include "bench_data.h"
#include "gmr/io/motion_file.h"
#include "gmr/retarget/retarget.h"

namespace gmr::bench {
namespace {

Motion load(const char* relative) {
  auto m = load_motion(data_dir() / relative);
  if (!m) die(m.error().to_string());
  return std::move(*m);
}

const char* kRigs[] = {"bvh/cmu_iclone/001_01.bvh", "bvh/mixamo/Beta_jump.bvh"};

void BM_RetargetTake(benchmark::State& state) {
  static const Motion source = load("asfamc/01/01_01.amc");
  const Motion rig = load(kRigs[state.range(0)]);
  for (auto _ : state) {
    auto out = retarget(source, rig);
    if (!out) die(out.error().to_string());
    benchmark::DoNotOptimize(out->values.data());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(source.frame_count));
  state.SetLabel(std::to_string(source.skeleton.size()) + " joints onto " + std::to_string(rig.skeleton.size()) + " (" +
                 kRigs[state.range(0)] + ")");
}
BENCHMARK(BM_RetargetTake)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

void BM_RetargetPlan(benchmark::State& state) {
  static const Motion source = load("asfamc/01/01_01.amc");
  const Motion rig = load(kRigs[state.range(0)]);
  for (auto _ : state) {
    auto plan = plan_retarget(source, rig);
    if (!plan) die(plan.error().to_string());
    benchmark::DoNotOptimize(plan->scale);
  }
  state.SetLabel(kRigs[state.range(0)]);
}
BENCHMARK(BM_RetargetPlan)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace gmr::bench

BENCHMARK_MAIN();
