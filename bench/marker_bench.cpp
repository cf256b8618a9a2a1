// What solving markers costs (docs/performance.md, "Markers frame by frame"):
// CMU 01_01's C3D (41 markers of the cmu41 model, 43 in the file) solved one
// frame at a time after a calibration on its first two seconds, as a live
// marker source is (gmr/markers/marker_frames.h); the calibration itself; and
// the whole take at once (solve_markers), per frame. items/s is frames/s.
#include <benchmark/benchmark.h>

#include "bench_data.h"
#include "gmr/markers/marker_frames.h"
#include "gmr/markers/marker_model.h"
#include "gmr/markers/marker_solve.h"

namespace gmr::bench {
namespace {

const MarkerTrajectories& take() {
  static const MarkerTrajectories t = [] {
    auto m = load_markers(data_dir() / "c3d/cmu_01_01.c3d");
    if (!m) die(m.error().to_string());
    return std::move(*m);
  }();
  return t;
}

MarkerModel cmu41() {
  auto m = builtin_marker_model("cmu41");
  if (!m) die(m.error().to_string());
  return std::move(*m);
}

std::size_t two_seconds() { return static_cast<std::size_t>(2 * take().frame_rate); }

// One frame: every part's fit, the joints, the channel values.
void BM_MarkerFrame(benchmark::State& state) {
  const MarkerTrajectories& t = take();
  auto solver = MarkerFrameSolver::calibrate(t, cmu41(), 0, two_seconds());
  if (!solver) die(solver.error().to_string());
  const std::size_t row = t.marker_count() * 3;
  std::size_t f = 0;
  for (auto _ : state) {
    auto values = solver->solve(std::span<const double>(t.positions).subspan(f * row, row));
    if (!values) die(values.error().to_string());
    benchmark::DoNotOptimize(values->data());
    f = (f + 1) % t.frame_count;
  }
  state.SetItemsProcessed(state.iterations());
  state.SetLabel(std::to_string(t.marker_count()) + " markers, " + std::to_string(solver->skeleton().size()) +
                 " joints");
}
BENCHMARK(BM_MarkerFrame)->Unit(benchmark::kMicrosecond);

// The calibration a live source makes once, on its first two seconds.
void BM_MarkerCalibrate(benchmark::State& state) {
  const MarkerModel model = cmu41();
  for (auto _ : state) {
    auto solver = MarkerFrameSolver::calibrate(take(), model, 0, two_seconds());
    if (!solver) die(solver.error().to_string());
    benchmark::DoNotOptimize(&solver->skeleton());
  }
  state.SetLabel(std::to_string(two_seconds()) + " frames");
}
BENCHMARK(BM_MarkerCalibrate)->Unit(benchmark::kMillisecond);

// The whole take at once (gmr convert --model), per frame.
void BM_MarkerWholeTake(benchmark::State& state) {
  const MarkerModel model = cmu41();
  for (auto _ : state) {
    auto r = solve_markers(take(), model);
    if (!r) die(r.error().to_string());
    benchmark::DoNotOptimize(r->motion.values.data());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(take().frame_count));
}
BENCHMARK(BM_MarkerWholeTake)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace gmr::bench

BENCHMARK_MAIN();
