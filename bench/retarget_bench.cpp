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

// A live source's frame: one-frame motions through a plan made once (what the
// server's retargeted view of a live source does per frame), the copy of the
// frame included.
void BM_RetargetLiveFrame(benchmark::State& state) {
  static const Motion source = load("asfamc/01/01_01.amc");
  const Motion rig = load(kRigs[state.range(0)]);
  auto r = Retargeter::make(source, rig);
  if (!r) die(r.error().to_string());
  Motion one;
  one.skeleton = source.skeleton;
  one.convention = source.convention;
  one.frame_time = source.frame_time;
  one.frame_count = 1;
  std::size_t f = 0;
  for (auto _ : state) {
    const auto values = source.frame(f);
    one.values.assign(values.begin(), values.end());
    auto out = r->apply(one);
    if (!out) die(out.error().to_string());
    benchmark::DoNotOptimize(out->values.data());
    f = (f + 1) % source.frame_count;
  }
  state.SetItemsProcessed(state.iterations());
  state.SetLabel(kRigs[state.range(0)]);
}
BENCHMARK(BM_RetargetLiveFrame)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

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
