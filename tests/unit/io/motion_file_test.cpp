#include "gmr/io/motion_file.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <tuple>
#include <vector>

#include "gmr/core/file_util.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "io_test_util.h"
#include "test_data.h"

namespace gmr {
namespace {
namespace fs = std::filesystem;
using ::testing::HasSubstr;

using test::TempDir;

constexpr std::string_view kBvh =
    "HIERARCHY\nROOT A\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}\n"
    "MOTION\nFrames: 1\nFrame Time: 0.5\n1 2 3\n";

TEST(LoadMotion, ByExtensionCaseInsensitive) {
  TempDir d;
  ASSERT_TRUE(write_file_atomic(d.path / "a.BVH", kBvh).ok());
  auto m = load_motion(d.path / "a.BVH");
  ASSERT_TRUE(m.ok()) << m.error().to_string();
  EXPECT_EQ(m->convention, Convention::kPostRotation);
  ASSERT_TRUE(write_file_atomic(d.path / "a.gmr", "GMR 1\n" + std::string(kBvh)).ok());
  auto g = load_motion(d.path / "a.gmr");
  ASSERT_TRUE(g.ok()) << g.error().to_string();
  EXPECT_EQ(g->convention, Convention::kPreRotation);
}

TEST(LoadMotion, UnknownExtensionsAndMissingFiles) {
  auto r = load_motion("x.txt");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().file, "x.txt");
  EXPECT_THAT(r.error().message, HasSubstr("'.txt'"));
  EXPECT_THAT(load_motion("noext").error().message, HasSubstr("without extension"));
  auto missing = load_motion("/nonexistent/a.bvh");
  ASSERT_FALSE(missing.ok());
  EXPECT_THAT(missing.error().to_string(), HasSubstr("/nonexistent/a.bvh"));
}

TEST(LoadMotion, AmcNeedsExactlyOneAsf) {
  TempDir d;
  ASSERT_TRUE(write_file_atomic(d.path / "t.amc", ":FULLY-SPECIFIED\n").ok());
  auto none = load_motion(d.path / "t.amc");
  ASSERT_FALSE(none.ok());
  EXPECT_THAT(none.error().message, HasSubstr("no .asf skeleton"));
  EXPECT_THAT(none.error().message, HasSubstr("--asf"));
  ASSERT_TRUE(write_file_atomic(d.path / "a.asf", "").ok());
  ASSERT_TRUE(write_file_atomic(d.path / "b.ASF", "").ok());
  auto several = load_motion(d.path / "t.amc");
  ASSERT_FALSE(several.ok());
  EXPECT_THAT(several.error().message, HasSubstr("several .asf skeletons"));
  EXPECT_THAT(several.error().message, HasSubstr("a.asf, b.ASF"));
  EXPECT_THAT(several.error().message, HasSubstr("none for subject 't'"));
}

TEST(LoadMotion, AmcPicksTheAsfOfItsSubjectAmongSeveral) {
  GMR_REQUIRE_DATA();
  // CMU names: 07_05-walk.amc goes with 07-walk.asf; a folder may hold the
  // skeletons of several subjects.
  TempDir d;
  fs::copy_file(test::data_file("asfamc/07/07-walk.asf"), d.path / "07-walk.asf");
  fs::copy_file(test::data_file("asfamc/07/07_05-walk.amc"), d.path / "07_05-walk.amc");
  fs::copy_file(test::data_file("asfamc/09/09-run.asf"), d.path / "09-run.asf");
  const auto m = load_motion(d.path / "07_05-walk.amc");
  ASSERT_TRUE(m.ok()) << m.error().to_string();
  const auto want = load_motion(d.path / "07_05-walk.amc", LoadOptions{.asf = d.path / "07-walk.asf"});
  ASSERT_TRUE(want.ok());
  EXPECT_EQ(m->values, want->values);
  EXPECT_EQ(m->skeleton.size(), want->skeleton.size());
  // Two skeletons of the same subject: still a question only the user can answer.
  fs::copy_file(d.path / "07-walk.asf", d.path / "07-other.asf");
  const auto two = load_motion(d.path / "07_05-walk.amc");
  ASSERT_FALSE(two.ok());
  EXPECT_THAT(two.error().message, HasSubstr("07-other.asf, 07-walk.asf, 09-run.asf) for subject '07'"));
  EXPECT_THAT(two.error().message, HasSubstr("--asf"));
}

// The unit a file declares: an ASF's `units length` (CMU: inches / 0.45),
// nothing for BVH or GMR, nothing for an .amc whose skeleton cannot be read.
TEST(DeclaredUnit, AsfLengthIsInchesOverLength) {
  TempDir d;
  ASSERT_TRUE(write_file_atomic(d.path / "a.bvh", kBvh).ok());
  EXPECT_EQ(declared_metres_per_unit(d.path / "a.bvh"), 0.0);
  ASSERT_TRUE(write_file_atomic(d.path / "t.amc", ":FULLY-SPECIFIED\n").ok());
  EXPECT_EQ(declared_metres_per_unit(d.path / "t.amc"), 0.0) << "no .asf beside it";
  ASSERT_TRUE(write_file_atomic(d.path / "t.asf",
                                ":version 1.10\n:name t\n:units\n  mass 1.0\n  length 0.5\n  angle deg\n"
                                ":root\n  order TX TY TZ RX RY RZ\n  axis XYZ\n  position 0 0 0\n"
                                "  orientation 0 0 0\n:bonedata\n:hierarchy\n  begin\n  end\n")
                  .ok());
  EXPECT_DOUBLE_EQ(declared_metres_per_unit(d.path / "t.amc"), 0.0254 / 0.5);
  if (!test::have_data() && !test::in_ci()) return;
  EXPECT_DOUBLE_EQ(declared_metres_per_unit(test::data_file("asfamc/07/07_05-walk.amc")), 0.0254 / 0.45);
}

// A file without a unit gets it from X.units beside it, else from
// folder.units; the file's own declaration (an ASF's) wins; a sidecar that
// says no unit, or two, is an error naming it and the line.
TEST(DeclaredUnit, SidecarsDeclareTheUnitOfFilesWithoutOne) {
  TempDir d;
  for (const char* name : {"a.bvh", "b.bvh", "c.gmr"}) ASSERT_TRUE(write_file_atomic(d.path / name, kBvh).ok());
  auto unit = [&](const char* name) {
    auto u = motion_metres_per_unit(d.path / name);
    EXPECT_TRUE(u.ok()) << u.error().to_string();
    return u.ok() ? *u : -1.0;
  };
  EXPECT_EQ(unit("a.bvh"), 0.0) << "no sidecar: unknown";
  ASSERT_TRUE(write_file_atomic(d.path / "folder.units", "# the lab's BVH exports\ncm\n").ok());
  EXPECT_DOUBLE_EQ(unit("a.bvh"), 0.01);
  EXPECT_DOUBLE_EQ(unit("c.gmr"), 0.01);
  ASSERT_TRUE(write_file_atomic(d.path / "a.units", "  0.0254   # inches, as a number\n\n").ok());
  EXPECT_DOUBLE_EQ(unit("a.bvh"), 0.0254) << "the file's own sidecar before the folder's";
  EXPECT_DOUBLE_EQ(unit("b.bvh"), 0.01);
  for (const auto& [text, metres] : std::vector<std::pair<std::string, double>>{
           {"Inches", 0.0254}, {"mm\r\n", 0.001}, {"feet", 0.3048}, {"metres", 1.0}, {"1e-3", 0.001}}) {
    ASSERT_TRUE(write_file_atomic(d.path / "b.units", text).ok());
    EXPECT_DOUBLE_EQ(unit("b.bvh"), metres) << text;
  }
  for (const auto& [text, line, says] :
       std::vector<std::tuple<std::string, int, std::string>>{{"inchs\n", 1, "inchs is not a unit"},
                                                              {"# nothing\n", 0, "names no unit"},
                                                              {"cm\nmm\n", 2, "a second line says mm"},
                                                              {"-1\n", 1, "-1 is not a unit"},
                                                              {"nan\n", 1, "nan is not a unit"},
                                                              {std::string(5000, 'x'), 0, "holds one unit"}}) {
    ASSERT_TRUE(write_file_atomic(d.path / "b.units", text).ok());
    auto u = motion_metres_per_unit(d.path / "b.bvh");
    ASSERT_FALSE(u.ok()) << text;
    EXPECT_EQ(u.error().file, (d.path / "b.units").string());
    EXPECT_EQ(u.error().line, line) << text;
    EXPECT_THAT(u.error().message, HasSubstr(says));
  }
  // An Acclaim motion declares its own unit; sidecars are not read for it.
  ASSERT_TRUE(write_file_atomic(d.path / "t.amc", ":FULLY-SPECIFIED\n").ok());
  ASSERT_TRUE(write_file_atomic(d.path / "t.units", "m\n").ok());
  EXPECT_EQ(unit("t.amc"), 0.0) << "an .amc without its .asf is unknown, not the sidecar's";
}

TEST(SaveMotion, UnknownExtension) {
  Motion m;
  const Status s = save_motion(m, "out.xyz");
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s.error().to_string(), HasSubstr("out.xyz: cannot write '.xyz' files"));
}

// A BVH is saved in the form every reader takes alike (to_bvh_interchange):
// here the root's three position channels gain three rotation channels at
// zero (Assimp reads positions only from six-channel joints); the values and
// the position stay.
TEST(SaveMotion, BvhIsWrittenInTheInterchangeForm) {
  TempDir d;
  ASSERT_TRUE(write_file_atomic(d.path / "a.bvh", kBvh).ok());
  const Motion m = load_motion(d.path / "a.bvh").value();
  ASSERT_TRUE(save_motion(m, d.path / "b.bvh").ok());
  const Motion b = load_motion(d.path / "b.bvh").value();
  EXPECT_EQ(b.values, (std::vector<double>{1, 2, 3, 0, 0, 0}));
  EXPECT_EQ(b.skeleton.joint(0).channels.size(), 6u);
  EXPECT_EQ(compute_positions(b), compute_positions(m));
}

// Positions of `b`'s joints rearranged to `a`'s joint order (by name), so the
// two can be compared joint for joint; `b` may have extra joints.
std::vector<Eigen::Vector3d> positions_by_name(const Motion& a, const Motion& b) {
  const auto pb = compute_positions(b);
  std::vector<int> map;
  for (const Joint& j : a.skeleton.joints()) {
    map.push_back(b.skeleton.find(j.name));
    EXPECT_GE(map.back(), 0) << "joint " << j.name << " missing after the round trip";
    if (map.back() < 0) map.back() = 0;
  }
  std::vector<Eigen::Vector3d> out;
  out.reserve(a.frame_count * map.size());
  for (std::size_t f = 0; f < b.frame_count; ++f)
    for (int k : map) out.push_back(pb[f * b.skeleton.size() + static_cast<std::size_t>(k)]);
  return out;
}

// The end-to-end check through files: BVH -> .gmr file -> read ->
// .bvh file -> read keeps every joint's position in every frame, for every
// BVH of the corpus (within 1e-6 of the skeleton's size). Debug and
// sanitizer builds take evenly spaced frames of each file.
TEST(SaveMotionRealFiles, BvhToGmrFileToBvhFileKeepsPositions) {
  GMR_REQUIRE_DATA();
  TempDir d;
  for (const auto& path : test::data_files("bvh", ".bvh")) {
    SCOPED_TRACE(path.string());
    const Motion bvh = test::sample_frames(load_motion(path).value());
    const double tol = 1e-6 * skeleton_size(bvh);
    const auto p0 = compute_positions(bvh);

    const fs::path gmr_path = d.path / "m.gmr";
    const Status s1 = save_motion(bvh, gmr_path);
    ASSERT_TRUE(s1.ok()) << s1.error().to_string();
    auto gmr = load_motion(gmr_path);
    ASSERT_TRUE(gmr.ok()) << gmr.error().to_string();
    EXPECT_EQ(gmr->convention, Convention::kPreRotation);
    EXPECT_EQ(gmr->frame_count, bvh.frame_count);
    EXPECT_EQ(gmr->frame_time, bvh.frame_time);
    EXPECT_POSITIONS_NEAR(bvh.skeleton, p0, positions_by_name(bvh, *gmr), tol);

    const fs::path bvh_path = d.path / "m.bvh";
    const Status s2 = save_motion(*gmr, bvh_path);
    ASSERT_TRUE(s2.ok()) << s2.error().to_string();
    auto back = load_motion(bvh_path);
    ASSERT_TRUE(back.ok()) << back.error().to_string();
    EXPECT_EQ(back->convention, Convention::kPostRotation);
    EXPECT_POSITIONS_NEAR(bvh.skeleton, p0, positions_by_name(bvh, *back), tol);
  }
}

}  // namespace
}  // namespace gmr
