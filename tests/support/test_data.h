// Access to the shared real-data corpus (../shared/data) and common assertions.
//
// Outside CI a test that needs the corpus is skipped with a clear message when
// it is missing; with CI=true its absence is a failure.
#pragma once

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "gmr/skeleton/skeleton.h"

namespace gmr::test {

// Root of the corpus: $GMR_DATA_DIR if set, else <repo>/../shared/data.
std::filesystem::path data_dir();
// True when the corpus exists.
bool have_data();
// True when running in CI (CI=true).
bool in_ci();
// Every regular file under data_dir()/sub whose extension (lower-cased, with the
// dot) is `ext`, sorted. Empty when the corpus is missing. When it is present,
// fails the running test unless exactly expected_data_files(sub, ext) were
// found (a renamed or emptied folder never turns a loop into a silent pass).
std::vector<std::filesystem::path> data_files(const std::string& sub, const std::string& ext);
// How many such files the corpus holds (fails the test for an unlisted kind).
std::size_t expected_data_files(const std::string& sub, const std::string& ext);
// Absolute path of a file in the corpus.
std::filesystem::path data_file(const std::string& relative);

// A fresh, empty folder under the system temp folder named after the running
// test, removed with everything in it when the object goes.
struct TempDir {
  std::filesystem::path path;
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  // Number of entries in the folder (to check that nothing was left behind).
  std::size_t entries() const;
};

// Largest distance between corresponding positions, and where it happened.
struct PositionDiff {
  double max_error = 0.0;
  std::size_t frame = 0;
  int joint = -1;
};
// a and b are frame-major arrays of `joints` positions per frame.
// Engine-bone locals (gmr/view/engine_pose.h) composed from the roots down,
// O_j = O_p Q_j and P_j = P_p + O_p T_j: the world positions they give, one
// per joint of `skeleton` (q and t hold one entry per joint, in its order).
std::vector<Eigen::Vector3d> compose_locals(const Skeleton& skeleton, std::span<const Eigen::Quaterniond> q,
                                            std::span<const Eigen::Vector3d> t);

PositionDiff compare_positions(std::span<const Eigen::Vector3d> a, std::span<const Eigen::Vector3d> b,
                               std::size_t joints);

}  // namespace gmr::test

// Skips the test (outside CI) or fails it (in CI) when the corpus is missing.
#define GMR_REQUIRE_DATA()                                                                                         \
  do {                                                                                                             \
    if (!::gmr::test::have_data()) {                                                                               \
      if (::gmr::test::in_ci()) FAIL() << "CI=true but the shared data is missing at " << ::gmr::test::data_dir(); \
      GTEST_SKIP() << "shared data not found at " << ::gmr::test::data_dir()                                       \
                   << " (set GMR_DATA_DIR or check out ../shared)";                                                \
    }                                                                                                              \
  } while (0)

// Asserts that two frame-major position arrays agree within `tol`, naming the
// worst frame and joint when they do not.
#define EXPECT_POSITIONS_NEAR(skeleton, a, b, tol)                                             \
  do {                                                                                         \
    ASSERT_EQ((a).size(), (b).size());                                                         \
    const auto gmr_diff_ = ::gmr::test::compare_positions((a), (b), (skeleton).size());        \
    EXPECT_LE(gmr_diff_.max_error, (tol))                                                      \
        << "worst at frame " << gmr_diff_.frame << ", joint "                                  \
        << (gmr_diff_.joint >= 0 ? (skeleton).joint(gmr_diff_.joint).name : std::string("?")); \
  } while (0)
