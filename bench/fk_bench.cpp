// Forward kinematics: positions of every joint of every frame of CMU 01_01
// (31 joints + 7 end sites, 2752 frames), one core. Each benchmark reports
// ns_per_frame (time / frames computed) and the bytes per frame its input
// representation holds. Warm cache: the whole motion (~1 MB as floats) stays
// in L2/L3 across iterations, as it does for a server that streams one clip.
//
//   reference_double    gmr::compute_frame (Eigen, double): the reference path
//   scalar_float        one frame at a time, float, std::sin/std::cos
//   fast/bvh            SIMD across frames, Euler channels (post-rotation)
//   fast/bvh_in_l2      the same on 256-frame ranges that stay in L2
//   fast/gmr_roots:k    the GMR form with k roots (k = 1 .. all)
//   fast/gmr_all_roots  every joint a root: a copy of the stored positions
//   gmr_all_roots_view  the zero-copy view (no work at all)
//   single_frame/...    FkFrameJob, one frame per call (a server tick)
//   memcpy              baseline: copying the output bytes
#include <benchmark/benchmark.h>

#include <cstring>
#include <vector>

#include "bench_data.h"
#include "gmr/fast/fast_fk.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/view/viewpoint.h"

namespace gmr::bench {
namespace {

using fast::CompiledMotion;
using fast::FkFrameJob;
using fast::FkRangeJob;
using fast::Layout;

const Motion& bvh() {
  static const Motion m = load_main_bvh();
  return m;
}

void set_counters(benchmark::State& state, std::size_t frames, std::size_t bytes_per_frame) {
  // Seconds per frame (printed as e.g. "39.2n"), from CPU time.
  state.counters["per_frame"] = benchmark::Counter(
      static_cast<double>(frames), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["input_bytes_per_frame"] = static_cast<double>(bytes_per_frame);
  state.counters["joints"] = static_cast<double>(bvh().skeleton.size());
}

void BM_ReferenceDouble(benchmark::State& state) {
  const Motion& m = bvh();
  std::vector<Eigen::Vector3d> pos(m.skeleton.size());
  std::vector<Eigen::Matrix3d> world(m.skeleton.size());
  for (auto _ : state) {
    for (std::size_t f = 0; f < m.frame_count; ++f) compute_frame(m, f, pos, world);
    benchmark::DoNotOptimize(pos.data());
  }
  set_counters(state, m.frame_count, m.stride() * sizeof(double));
}
BENCHMARK(BM_ReferenceDouble)->Name("reference_double/bvh")->Unit(benchmark::kMillisecond);

void BM_ScalarFloat(benchmark::State& state) {
  auto cm = CompiledMotion::compile(bvh()).value();
  std::vector<float> ws(fast::fk_workspace_size(cm)), pos(cm.joint_count() * 3);
  for (auto _ : state) {
    for (std::size_t f = 0; f < cm.frame_count(); ++f) fast::scalar_float_frame(cm, f, pos, ws);
    benchmark::DoNotOptimize(pos.data());
  }
  set_counters(state, cm.frame_count(), cm.bytes_per_frame());
}
BENCHMARK(BM_ScalarFloat)->Name("scalar_float/bvh")->Unit(benchmark::kMillisecond);

void run_range(benchmark::State& state, const Motion& m, Layout layout) {
  auto cm = CompiledMotion::compile(m).value();
  std::vector<float> ws(fast::fk_workspace_size(cm)), pos(cm.frame_count() * cm.joint_count() * 3);
  const FkRangeJob job{
      .motion = &cm, .begin = 0, .end = cm.frame_count(), .layout = layout, .out_positions = pos, .workspace = ws};
  for (auto _ : state) {
    job.run();
    benchmark::DoNotOptimize(pos.data());
    benchmark::ClobberMemory();
  }
  set_counters(state, cm.frame_count(), cm.bytes_per_frame());
  state.SetLabel(std::string(fast::simd_target_name()) +
                 (layout == Layout::kFrameMajor ? " frame-major" : " joint-major"));
}

void BM_FastBvh(benchmark::State& state) { run_range(state, bvh(), static_cast<Layout>(state.range(0))); }
BENCHMARK(BM_FastBvh)->Name("fast/bvh")->ArgName("joint_major")->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

// The kernel's own cost: four 256-frame ranges of the motion, visited in turn,
// so inputs (4 x 256 frames x 360 B) and outputs (4 x 256 x 456 B) stay in
// L2; the whole-motion benchmark above adds the L3 traffic of 2.2 MB.
void BM_FastBvhInL2(benchmark::State& state) {
  constexpr std::size_t kRange = 256;
  constexpr std::size_t kRanges = 4;
  const auto layout = static_cast<Layout>(state.range(0));
  auto cm = CompiledMotion::compile(bvh()).value();
  if (cm.frame_count() < kRange * kRanges) die("01_01 is shorter than the ranges");
  std::vector<float> ws(fast::fk_workspace_size(cm)), pos(kRange * kRanges * cm.joint_count() * 3);
  std::vector<FkRangeJob> jobs;
  for (std::size_t r = 0; r < kRanges; ++r) {
    jobs.push_back(FkRangeJob{.motion = &cm,
                              .begin = r * kRange,
                              .end = (r + 1) * kRange,
                              .layout = layout,
                              .out_positions = std::span<float>(pos).subspan(r * kRange * cm.joint_count() * 3,
                                                                             kRange * cm.joint_count() * 3),
                              .workspace = ws});
  }
  for (auto _ : state) {
    for (const FkRangeJob& job : jobs) job.run();
    benchmark::DoNotOptimize(pos.data());
    benchmark::ClobberMemory();
  }
  set_counters(state, kRange * kRanges, cm.bytes_per_frame());
  state.SetLabel(std::string(fast::simd_target_name()) +
                 (layout == Layout::kFrameMajor ? " frame-major" : " joint-major"));
}
BENCHMARK(BM_FastBvhInL2)
    ->Name("fast/bvh_in_l2")
    ->ArgName("joint_major")
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMicrosecond);

// k roots: 1 (the conversion's own), a few, many, and every joint.
void BM_FastGmrRoots(benchmark::State& state) {
  static std::vector<std::pair<std::size_t, Motion>> cache;
  const std::size_t k = static_cast<std::size_t>(state.range(0));
  const Motion* m = nullptr;
  for (auto& [kk, mm] : cache) {
    if (kk == k) m = &mm;
  }
  if (m == nullptr) m = &cache.emplace_back(k, with_roots(bvh(), k, 42)).second;
  run_range(state, *m, static_cast<Layout>(state.range(1)));
}
BENCHMARK(BM_FastGmrRoots)
    ->Name("fast/gmr")
    ->ArgNames({"roots", "joint_major"})
    ->ArgsProduct({{1, 2, 4, 8, 16, 24, 32, 38}, {0, 1}})
    ->Unit(benchmark::kMicrosecond);

void BM_AllRootsView(benchmark::State& state) {
  auto cm = CompiledMotion::compile(with_roots(bvh(), 1000, 1)).value();
  for (auto _ : state) {
    const float* view = cm.stored_positions(0);
    benchmark::DoNotOptimize(view);
  }
  set_counters(state, cm.frame_count(), cm.bytes_per_frame());
}
BENCHMARK(BM_AllRootsView)->Name("fast/gmr_all_roots_view");

void run_single(benchmark::State& state, const Motion& m) {
  auto cm = CompiledMotion::compile(m).value();
  std::vector<float> ws(fast::fk_workspace_size(cm)), pos(cm.joint_count() * 3);
  for (auto _ : state) {
    for (std::size_t f = 0; f < cm.frame_count(); ++f) {
      FkFrameJob{.motion = &cm, .frame = f, .out_positions = pos, .workspace = ws}.run();
      benchmark::DoNotOptimize(pos.data());
    }
  }
  set_counters(state, cm.frame_count(), cm.bytes_per_frame());
  state.SetLabel(fast::simd_target_name());
}
void BM_SingleBvh(benchmark::State& state) { run_single(state, bvh()); }
BENCHMARK(BM_SingleBvh)->Name("single_frame/bvh")->Unit(benchmark::kMicrosecond);
void BM_SingleGmr(benchmark::State& state) {
  static const Motion m = with_roots(bvh(), static_cast<std::size_t>(state.range(0)), 42);
  run_single(state, m);
}
BENCHMARK(BM_SingleGmr)->Name("single_frame/gmr_one_root")->Arg(1)->Unit(benchmark::kMicrosecond);

// What a server's float32 stream does per frame and subscriber-visible view:
// FK with orientations, then the viewpoint, quaternions and (arg 1) an
// engine's conventions (Unreal: a mirror and a unit change) for every joint.
void BM_ServerFrame(benchmark::State& state) {
  const Motion& m = bvh();
  auto cm = CompiledMotion::compile(m).value();
  const std::size_t n = cm.joint_count();
  if (n == 0 || n > (std::size_t{1} << 20)) {  // (also bounds n for GCC's allocation-size check)
    state.SkipWithError("the benchmark motion has no joints, or too many");
    return;
  }
  std::vector<float> ws(fast::fk_workspace_size(cm)), pos(n * 3), rot(n * 9), out_p(n * 3), out_q(n * 4);
  std::vector<int> joints(n);
  for (std::size_t j = 0; j < n; ++j) joints[j] = static_cast<int>(j);
#if __has_include("gmr/view/conventions.h")
  Conventions c;
  if (state.range(0) == 1) {
    c.preset = ConventionPreset::kUnreal;
    c.source_metres_per_unit = 0.0254;
  }
  const OutputBasis basis = output_basis(c).value();
#else
  if (state.range(0) == 1) state.SkipWithError("no conventions in this tree");
#endif
  for (auto _ : state) {
    for (std::size_t f = 0; f < cm.frame_count(); ++f) {
      FkFrameJob{.motion = &cm, .frame = f, .out_positions = pos, .out_orientations = rot, .workspace = ws}.run();
#if __has_include("gmr/view/conventions.h")
      view_frame_float(pos, rot, -1, joints, out_p, out_q, basis);
#else
      view_frame_float(pos, rot, -1, joints, out_p, out_q);
#endif
      benchmark::DoNotOptimize(out_p.data());
      benchmark::DoNotOptimize(out_q.data());
    }
  }
  set_counters(state, cm.frame_count(), n * 7 * sizeof(float));
  state.SetLabel(fast::simd_target_name());
}
BENCHMARK(BM_ServerFrame)->Name("server_frame/bvh")->ArgName("unreal")->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

// The view alone, for what most streams ask (world coordinates, native
// conventions, positions only: the grid's frames): one frame's FK output to
// the 38 joints sent, in cache.
void BM_ViewWorldPositions(benchmark::State& state) {
  const Motion& m = bvh();
  auto cm = CompiledMotion::compile(m).value();
  const std::size_t n = cm.joint_count();
  if (n == 0 || n > (std::size_t{1} << 20)) {
    state.SkipWithError("the benchmark motion has no joints, or too many");
    return;
  }
  std::vector<float> ws(fast::fk_workspace_size(cm)), pos(n * 3), rot(n * 9), out_p(n * 3);
  FkFrameJob{.motion = &cm, .frame = 100, .out_positions = pos, .out_orientations = rot, .workspace = ws}.run();
  std::vector<int> joints(n);
  for (std::size_t j = 0; j < n; ++j) joints[j] = static_cast<int>(j);
  for (auto _ : state) {
    view_frame_float(pos, {}, -1, joints, out_p, {});
    benchmark::DoNotOptimize(out_p.data());
  }
  state.counters["joints"] = static_cast<double>(n);
}
BENCHMARK(BM_ViewWorldPositions)->Name("view/world_positions");

// The floor for every path: writing the output bytes. In cache (the 2752
// frames' positions, 1.25 MB, fit L2+L3) and from a 64 MB buffer (DRAM).
void BM_Memcpy(benchmark::State& state) {
  const std::size_t frames = static_cast<std::size_t>(state.range(0));
  const std::size_t floats = bvh().skeleton.size() * 3;
  std::vector<float> src(frames * floats, 1.0f), dst(frames * floats);
  for (auto _ : state) {
    std::memcpy(dst.data(), src.data(), src.size() * sizeof(float));
    benchmark::DoNotOptimize(dst.data());
    benchmark::ClobberMemory();
  }
  set_counters(state, frames, floats * sizeof(float));
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) *
                          static_cast<std::int64_t>(src.size() * sizeof(float)));
}
BENCHMARK(BM_Memcpy)
    ->Name("memcpy_positions")
    ->ArgName("frames")
    ->Arg(2752)
    ->Arg(2752 * 64)
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace gmr::bench

BENCHMARK_MAIN();
