// Marker frames solved one at a time (gmr/markers/marker_frames.h), on CMU's
// C3D takes: with the whole take as calibration every frame equals the whole
// take's solve; calibrated on the first two seconds, as a live source is, the
// joints stay near it; markers dropped at random move them little and are
// counted; bad frames are refused and counted.
#include "gmr/markers/marker_frames.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/markers/marker_model.h"
#include "gmr/markers/marker_solve.h"
#include "markers_test_util.h"
#include "test_data.h"

namespace gmr {
namespace {

using Eigen::Vector3d;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// The take most tests solve: 01_01 (2,751 frames); under the sanitizers,
// which solve about fifty times slower, 02_01 (343 frames), which also fits
// every part in every frame.
#if defined(GMR_SANITIZED)
constexpr const char* kTake = "c3d/cmu_02_01.c3d";
#else
constexpr const char* kTake = "c3d/cmu_01_01.c3d";
#endif

MarkerModel cmu41() {
  auto model = builtin_marker_model("cmu41");
  EXPECT_TRUE(model.ok());
  return model.ok() ? *model : MarkerModel{};
}

// Per (frame, joint) distances between two motions of the same joints (mm:
// the takes are in millimetres).
std::vector<double> distances(const Motion& a, const Motion& b) {
  EXPECT_EQ(a.skeleton.size(), b.skeleton.size());
  EXPECT_EQ(a.frame_count, b.frame_count);
  const auto pa = compute_positions(a);
  const auto pb = compute_positions(b);
  std::vector<double> d;
  for (std::size_t i = 0; i < std::min(pa.size(), pb.size()); ++i) d.push_back((pa[i] - pb[i]).norm());
  return d;
}

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

double quantile95(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(0.95 * static_cast<double>(v.size() - 1))];
}

// With the whole take as its calibration, a frame solved alone is the whole
// take's frame: the same layouts, joint places and bones, the same fit.
// 01_01 and 02_01 fit every part in every frame (docs/markers.md), so every
// frame compares.
TEST(MarkerFrames, CalibratedOnTheWholeTakeEveryFrameIsTheWholeTakesSolve) {
  GMR_REQUIRE_DATA();
  const MarkerTrajectories take = test::load_marker_file(kTake);
  const MarkerModel model = cmu41();
  auto whole = solve_markers(take, model);
  ASSERT_TRUE(whole.ok()) << whole.error().to_string();
  MarkerFrameCounts counts;
  auto frames = solve_marker_frames(take, model, 0, take.frame_count, &counts);
  ASSERT_TRUE(frames.ok()) << frames.error().to_string();
  EXPECT_EQ(counts.solved, take.frame_count);
  EXPECT_EQ(counts.refused, 0u);
  EXPECT_EQ(counts.held, 0u);
  const auto d = distances(whole->motion, *frames);
  ASSERT_EQ(d.size(), take.frame_count * whole->motion.skeleton.size());
  EXPECT_LE(*std::max_element(d.begin(), d.end()), 1e-6);
}

// As a live source: calibrated on the first two seconds, each frame alone.
// Against the whole take's solve, joint by joint over every frame (the
// calibration sees only the start of the take, so joint centres and bones
// differ by what the rest of the take would have told).
TEST(MarkerFrames, CalibratedOnTheFirstTwoSecondsTheJointsStayNearTheWholeTake) {
  GMR_REQUIRE_DATA();
  std::size_t takes = 0;
  std::vector<std::string> files = {"c3d/cmu_02_01.c3d"};
  if (std::string(kTake) != files[0]) files.push_back(kTake);
  for (const std::string& file : files) {
    SCOPED_TRACE(file);
    const MarkerTrajectories take = test::load_marker_file(file);
    const MarkerModel model = cmu41();
    auto whole = solve_markers(take, model);
    ASSERT_TRUE(whole.ok()) << whole.error().to_string();
    const auto two_seconds = static_cast<std::size_t>(2 * take.frame_rate);
    MarkerFrameCounts counts;
    auto frames = solve_marker_frames(take, model, 0, two_seconds, &counts);
    ASSERT_TRUE(frames.ok()) << frames.error().to_string();
    EXPECT_EQ(counts.solved + counts.refused, take.frame_count);
    EXPECT_LE(counts.refused, take.frame_count / 100);
    const auto d = distances(whole->motion, *frames);
    std::printf(
        "[ figures  ] %s calibrated on %zu frames: joints %.1f mm median, %.1f mm p95 from the whole take's "
        "solve; %zu frames solved, %zu refused, %zu part poses held, %zu outliers\n",
        file.c_str(), two_seconds, median(d), quantile95(d), counts.solved, counts.refused, counts.held,
        counts.outliers);
    EXPECT_LE(median(d), 15.0);
    EXPECT_LE(quantile95(d), 50.0);
    ++takes;
  }
  EXPECT_EQ(takes, files.size());
}

// One marker in ten dropped at random from every frame after the
// calibration: the joints stay within 1 cm (median) of the same frames solved
// with every marker, and each drop is counted as missing.
TEST(MarkerFrames, TenPercentOfMarkersDroppedMoveTheJointsLittleAndAreCounted) {
  GMR_REQUIRE_DATA();
  const MarkerTrajectories take = test::load_marker_file(kTake);
  const MarkerModel model = cmu41();
  const auto two_seconds = static_cast<std::size_t>(2 * take.frame_rate);
  auto full = MarkerFrameSolver::calibrate(take, model, 0, two_seconds);
  auto dropped = MarkerFrameSolver::calibrate(take, model, 0, two_seconds);
  ASSERT_TRUE(full.ok() && dropped.ok());
  std::mt19937 random(20261127);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const std::size_t row = take.marker_count() * 3;
  std::size_t missing = 0, removed = 0, compared = 0;  // in the frames solved
  std::vector<double> d;
  Motion a, b;
  a.skeleton = b.skeleton = full->skeleton();
  a.frame_count = b.frame_count = 1;
  for (std::size_t f = 0; f < take.frame_count; ++f) {
    std::vector<double> frame(take.positions.begin() + static_cast<std::ptrdiff_t>(f * row),
                              take.positions.begin() + static_cast<std::ptrdiff_t>((f + 1) * row));
    std::size_t missing_here = 0, removed_here = 0;
    for (std::size_t m = 0; m < take.marker_count(); ++m) {
      if (std::isnan(frame[3 * m])) {
        ++missing_here;
      } else if (uniform(random) < 0.1) {
        frame[3 * m] = frame[3 * m + 1] = frame[3 * m + 2] = kNaN;
        ++removed_here;
      }
    }
    auto va = full->solve(std::span<const double>(take.positions).subspan(f * row, row));
    auto vb = dropped->solve(frame);
    ASSERT_TRUE(va.ok()) << "frame " << f << ": " << va.error().to_string();
    // A part short of points before its first fit cannot be solved yet: the
    // frame is refused (counted), as a live source skips it.
    if (!vb.ok()) continue;
    missing += missing_here;
    removed += removed_here;
    a.values = *va;
    b.values = *vb;
    const auto more = distances(a, b);
    d.insert(d.end(), more.begin(), more.end());
    ++compared;
  }
  EXPECT_EQ(compared + dropped->counts().refused, take.frame_count);
  EXPECT_LE(dropped->counts().refused, 10u);
  EXPECT_EQ(dropped->counts().missing, missing + removed);
  std::printf(
      "[ figures  ] %s with %zu of %zu points dropped at random: joints %.1f mm median, %.1f mm p95 from "
      "the full frames; %zu frames refused (a part not fitted yet), %zu part poses held, %zu outliers\n",
      kTake, removed, compared * take.marker_count(), median(d), quantile95(d), dropped->counts().refused,
      dropped->counts().held, dropped->counts().outliers);
  EXPECT_LE(median(d), 10.0);
}

TEST(MarkerFrames, BadFramesAreRefusedAndCountedPartsWithoutMarkersHoldTheirPose) {
  GMR_REQUIRE_DATA();
  const MarkerTrajectories take = test::load_marker_file("c3d/cmu_01_01.c3d");
  auto solver = MarkerFrameSolver::calibrate(take, cmu41(), 0, 240);
  ASSERT_TRUE(solver.ok()) << solver.error().to_string();
  EXPECT_EQ(solver->marker_names(), take.names);
  const std::size_t row = take.marker_count() * 3;
  const std::vector<double> nothing(row, kNaN);

  // Before any part was fitted: nothing to hold.
  auto first = solver->solve(nothing);
  ASSERT_FALSE(first.ok());
  EXPECT_NE(first.error().message.find("has not been fitted in any frame yet"), std::string::npos)
      << first.error().message;
  // A wrong size, an infinite coordinate: refused, naming what.
  auto short_frame = solver->solve(std::span<const double>(take.positions).subspan(0, row - 3));
  ASSERT_FALSE(short_frame.ok());
  EXPECT_NE(short_frame.error().message.find("coordinates"), std::string::npos);
  std::vector<double> infinite(take.positions.begin(), take.positions.begin() + static_cast<std::ptrdiff_t>(row));
  infinite[4] = std::numeric_limits<double>::infinity();
  auto inf = solver->solve(infinite);
  ASSERT_FALSE(inf.ok());
  EXPECT_NE(inf.error().message.find("'" + take.names[1] + "'"), std::string::npos) << inf.error().message;
  EXPECT_EQ(solver->counts().refused, 3u);
  EXPECT_EQ(solver->counts().solved, 0u);

  // A good frame, then one without any marker: every part holds its pose, so
  // the joints stay where they were.
  auto good = solver->solve(std::span<const double>(take.positions).subspan(0, row));
  ASSERT_TRUE(good.ok()) << good.error().to_string();
  auto held = solver->solve(nothing);
  ASSERT_TRUE(held.ok()) << held.error().to_string();
  std::vector<int> parts;  // the parts the joints ride on: those a frame fits
  for (const ModelJoint& j : cmu41().joints) parts.push_back(j.part);
  std::sort(parts.begin(), parts.end());
  parts.erase(std::unique(parts.begin(), parts.end()), parts.end());
  EXPECT_EQ(solver->counts().held, parts.size());
  Motion a, b;
  a.skeleton = b.skeleton = solver->skeleton();
  a.frame_count = b.frame_count = 1;
  a.values = *good;
  b.values = *held;
  const auto d = distances(a, b);
  EXPECT_LE(*std::max_element(d.begin(), d.end()), 1e-9);
  EXPECT_EQ(solver->counts().solved, 2u);
  std::size_t missing_in_good = 0;
  for (std::size_t m = 0; m < take.marker_count(); ++m) missing_in_good += std::isnan(take.positions[3 * m]) ? 1 : 0;
  EXPECT_EQ(solver->counts().missing, missing_in_good + take.marker_count());
}

}  // namespace
}  // namespace gmr
