// Loading a library folder: every good file becomes a motion, every bad one
// is reported with its reason, and loading does not stop at the first.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>

#include "gmr/server/library.h"
#include "test_data.h"

namespace gmr::test {
namespace {

TEST(Library, LoadsTheSharedDataAndReportsRejectedFiles) {
  GMR_REQUIRE_DATA();
  std::size_t progress_calls = 0;
  auto lib = server::load_library(data_dir(), 2, [&](std::size_t done, std::size_t total, const auto&, const auto*) {
    ++progress_calls;
    EXPECT_LE(done, total);
  });
  ASSERT_TRUE(lib.ok()) << lib.error().to_string();
  // BVH, AMC (with their ASF) load; C3D, TRC and text are skipped.
  EXPECT_GE(lib->entries.size(), 40u);
  EXPECT_GT(lib->skipped, 0u);
  auto has = [&](const std::string& name) {
    return std::any_of(lib->entries.begin(), lib->entries.end(), [&](const auto& e) { return e.name == name; });
  };
  EXPECT_TRUE(has("bvh/cmu/02_01"));
  EXPECT_TRUE(has("asfamc/07/07_05-walk"));
  for (const auto& e : lib->entries) {
    EXPECT_EQ(e.motion->convention, Convention::kPreRotation) << e.name;
    EXPECT_GT(e.motion->frame_count, 0u) << e.name;
    // Clients see where a motion came from relative to the library, never the server's own paths.
    EXPECT_FALSE(std::filesystem::path(e.source).is_absolute()) << e.source;
    EXPECT_EQ(e.source.find(".."), std::string::npos) << e.source;
    EXPECT_TRUE(std::filesystem::exists(data_dir() / e.source)) << e.source;
  }
  // The truncated files are rejected, each with a located reason.
  auto rejected = [&](const std::string& file) {
    const auto it = std::find_if(lib->rejected.begin(), lib->rejected.end(),
                                 [&](const auto& r) { return r.path.filename() == file; });
    return it == lib->rejected.end() ? std::string() : it->reason;
  };
  for (const char* f :
       {"TRUNC_02_01_in_hierarchy.bvh", "TRUNC_02_01_mid_frame.bvh", "TRUNC_02_01_no_motion_lines.bvh"}) {
    const std::string why = rejected(f);
    EXPECT_FALSE(why.empty()) << f << " was not rejected";
    EXPECT_NE(why.find(f), std::string::npos) << why;
  }
  // One progress call per motion file read, good or rejected.
  EXPECT_EQ(progress_calls, lib->entries.size() + lib->rejected.size());
}

// AMC files hold no frame rate: 120 Hz unless the server is told (--amc-fps);
// BVH files keep their own.
TEST(Library, AmcFrameRateComesFromTheOptions) {
  GMR_REQUIRE_DATA();
  TempDir d;
  namespace fs = std::filesystem;
  fs::create_symlink(data_file("asfamc/09/09-run.asf"), d.path / "09-run.asf");
  fs::create_symlink(data_file("asfamc/09/09_06-run.amc"), d.path / "09_06-run.amc");
  fs::create_symlink(data_file("bvh/cmu/02_01.bvh"), d.path / "02_01.bvh");
  for (const double fps : {0.0, 30.0}) {
    LoadOptions options;
    options.amc_fps = fps;
    auto lib = server::load_library(d.path, 1, {}, {}, options);
    ASSERT_TRUE(lib.ok()) << lib.error().to_string();
    ASSERT_EQ(lib->entries.size(), 2u);
    for (const auto& e : lib->entries) {
      const double want = e.name == "02_01" ? 0.0083333
                          : fps == 0.0      ? 1.0 / 120.0
                                            : 1.0 / 30.0;  // the BVH says .0083333
      EXPECT_NEAR(e.motion->frame_time, want, 1e-15) << e.name << " at " << fps;
    }
  }
}

TEST(Library, NamesFilesAsFoundAndPicksEachAmcsSkeleton) {
  GMR_REQUIRE_DATA();
  // A folder of symbolic links (how a deployment often points at a shared
  // corpus) and one folder holding two subjects' skeletons.
  TempDir d;
  namespace fs = std::filesystem;
  fs::create_directories(d.path / "walks");
  fs::create_symlink(data_file("bvh/cmu/02_01.bvh"), d.path / "walks" / "cmu_walk.bvh");
  fs::create_directories(d.path / "acclaim");
  for (const char* f :
       {"asfamc/07/07-walk.asf", "asfamc/07/07_05-walk.amc", "asfamc/09/09-run.asf", "asfamc/09/09_06-run.amc"}) {
    fs::create_symlink(data_file(f), d.path / "acclaim" / fs::path(f).filename());
  }
  auto lib = server::load_library(d.path, 2);
  ASSERT_TRUE(lib.ok()) << lib.error().to_string();
  std::vector<std::string> names;
  for (const auto& e : lib->entries) names.push_back(e.name);
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"acclaim/07_05-walk", "acclaim/09_06-run", "walks/cmu_walk"}));
  EXPECT_TRUE(lib->rejected.empty()) << lib->rejected.front().reason;
}

// A marker file is served when a skeleton model sits beside it (X.model, or
// markers.model for the folder); without one it is skipped, and a bad model
// rejects the file with the model's error.
TEST(Library, MarkerFilesWithAModelBesideThemBecomeMotions) {
  GMR_REQUIRE_DATA();
  TempDir d;
  namespace fs = std::filesystem;
  fs::create_directories(d.path / "own");
  fs::create_directories(d.path / "shared");
  fs::create_directories(d.path / "none");
  fs::create_directories(d.path / "bad");
  fs::create_symlink(data_file("c3d/cmu_02_01.c3d"), d.path / "own" / "walk.c3d");
  std::ofstream(d.path / "own" / "walk.model") << "builtin cmu41\n";
  fs::create_symlink(data_file("c3d/cmu_02_01.c3d"), d.path / "shared" / "walk.c3d");
  std::ofstream(d.path / "shared" / "markers.model") << "# every take here\nbuiltin cmu41\n";
  fs::create_symlink(data_file("c3d/cmu_02_01.c3d"), d.path / "none" / "walk.c3d");
  fs::create_symlink(data_file("c3d/opensim_walking2.c3d"), d.path / "bad" / "gait.c3d");
  std::ofstream(d.path / "bad" / "gait.model") << "builtin cmu41\n";
  auto lib = server::load_library(d.path, 2);
  ASSERT_TRUE(lib.ok()) << lib.error().to_string();
  std::vector<std::string> names;
  for (const auto& e : lib->entries) names.push_back(e.name);
  EXPECT_EQ(names, (std::vector<std::string>{"own/walk", "shared/walk"}));
  for (const auto& e : lib->entries) {
    EXPECT_EQ(e.motion->frame_count, 343u);
    EXPECT_EQ(e.motion->skeleton.size(), 21u);
    EXPECT_GE(e.motion->skeleton.find("lfemur"), 0);
    EXPECT_DOUBLE_EQ(e.metres_per_unit, 0.001);  // the C3D's millimetres
    EXPECT_NEAR(e.motion->frame_time, 1.0 / 120, 1e-12);
  }
  ASSERT_EQ(lib->rejected.size(), 1u);
  EXPECT_NE(lib->rejected[0].reason.find("gait.c3d"), std::string::npos) << lib->rejected[0].reason;
  EXPECT_NE(lib->rejected[0].reason.find("the marker file lacks"), std::string::npos) << lib->rejected[0].reason;
}

// Forty roots without channels and `frames` frames: about 2 KB of BVH.
std::string channel_less_roots(const std::string& frames) {
  std::string s = "HIERARCHY\n";
  for (int j = 0; j < 40; ++j) {
    s += "ROOT r" + std::to_string(j) + "\n{\n  OFFSET " + std::to_string(j) + " 1 0\n  CHANNELS 0\n}\n";
  }
  return s + "MOTION\nFrames: " + frames + "\nFrame Time: 0.01\n";
}

TEST(Library, AMotionAboveTheLimitsIsRejectedAtLoadWithItsFigures) {
  TempDir d;
  // 2^20 frames: the most a reader takes without channels (gmr/core/limits.h).
  std::ofstream(d.path / "huge.bvh") << channel_less_roots("1048576");
  std::ofstream(d.path / "small.bvh") << channel_less_roots("3");
  EXPECT_LT(std::filesystem::file_size(d.path / "huge.bvh"), 2000u);
  auto lib = server::load_library(d.path, 2);
  ASSERT_TRUE(lib.ok()) << lib.error().to_string();
  ASSERT_EQ(lib->entries.size(), 1u);
  EXPECT_EQ(lib->entries[0].name, "small");
  ASSERT_EQ(lib->rejected.size(), 1u);
  EXPECT_EQ(lib->rejected[0].path.filename(), "huge.bvh");
  EXPECT_NE(lib->rejected[0].reason.find("huge.bvh"), std::string::npos) << lib->rejected[0].reason;
  EXPECT_NE(lib->rejected[0].reason.find("too large to serve: 1048576 frames x 40 joints = 41943040 joint-frames, "
                                         "above the server's limit of 33554432 (--max-motion-joint-frames)"),
            std::string::npos)
      << lib->rejected[0].reason;

  // The value bytes limit.
  server::MotionLimits tight;
  tight.max_value_bytes = 1000;
  EXPECT_TRUE(server::check_motion_limits(*lib->entries[0].motion, tight).ok()) << "no channels: no values";
  const auto walk = server::builtin_library().front().motion;
  auto refused = server::check_motion_limits(*walk, tight);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().message, "too large to serve: " + std::to_string(walk->frame_count) + " frames x " +
                                         std::to_string(walk->stride()) + " channels take " +
                                         std::to_string(walk->values.size() * 8) +
                                         " bytes, above the server's limit of 1000 (--max-motion-bytes)");

  // Limits raised by the operator.
  server::MotionLimits raised;
  raised.max_joint_frames = std::uint64_t{1} << 28;
  auto again = server::load_library(d.path, 1, {}, raised);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->entries.size(), 2u);
  EXPECT_TRUE(again->rejected.empty());
}

TEST(Library, AMissingFolderIsAnError) {
  auto lib = server::load_library("/nonexistent/gmr/library");
  ASSERT_FALSE(lib.ok());
  EXPECT_NE(lib.error().to_string().find("/nonexistent/gmr/library"), std::string::npos);
}

TEST(Library, BuiltinLibraryIsPreRotationAndNamed) {
  const auto lib = server::builtin_library();
  ASSERT_FALSE(lib.empty());
  for (const auto& e : lib) {
    EXPECT_FALSE(e.name.empty());
    EXPECT_EQ(e.source, "builtin");
    EXPECT_EQ(e.motion->convention, Convention::kPreRotation);
  }
}

}  // namespace
}  // namespace gmr::test
