// The operation commands of the `gmr` binary (roots, shift, split, join,
// strip-dummies, constant-rotations) and the view options of `gmr positions`.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>

#include "gmr/core/file_util.h"
#include "gmr/io/motion_file.h"
#include "cli_test_util.h"
#include "test_data.h"

namespace gmr {
namespace {
namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::StartsWith;

using Outcome = test::CliOutcome;
using test::shell_quote;

class CliOps : public test::CliTest {
 protected:
  void SetUp() override {
    CliTest::SetUp();
    bvh_ = shell_quote(test::data_file("bvh/cmu/02_01.bvh").string());
  }
  std::string bvh_;
};

// "frame,joint" -> position.
std::map<std::string, Eigen::Vector3d> parse_csv(const std::string& csv) {
  std::map<std::string, Eigen::Vector3d> out;
  std::istringstream in(csv);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "frame,joint,x,y,z");
  while (std::getline(in, line)) {
    const auto c2 = line.find(',', line.find(',') + 1);
    Eigen::Vector3d p;
    std::sscanf(line.c_str() + c2 + 1, "%lf,%lf,%lf", &p.x(), &p.y(), &p.z());
    out[line.substr(0, c2)] = p;
  }
  return out;
}

// Largest distance between rows present in both; fails if `b` has rows `a` lacks.
double max_diff(const std::map<std::string, Eigen::Vector3d>& a, const std::map<std::string, Eigen::Vector3d>& b) {
  double e = 0.0;
  for (const auto& [key, p] : b) {
    auto it = a.find(key);
    if (it == a.end()) return 1e300;
    e = std::max(e, (it->second - p).norm());
  }
  return e;
}

TEST_F(CliOps, RootsWritesAGmrWithExactlyThoseRoots) {
  GMR_REQUIRE_DATA();
  const Outcome r = gmr("roots " + bvh_ + " --set Hips,LeftHand,Head -o " + path("r.gmr"));
  ASSERT_EQ(r.status, 0) << r.err;
  const auto m = load_motion(dir_ / "r.gmr");
  ASSERT_TRUE(m.ok()) << m.error().to_string();
  std::vector<std::string> roots;
  for (int j : m->skeleton.roots()) roots.push_back(m->skeleton.joint(j).name);
  std::sort(roots.begin(), roots.end());
  EXPECT_EQ(roots, (std::vector<std::string>{"Head", "Hips", "LeftHand"}));
  // Same positions as the BVH, every frame.
  const auto plain = parse_csv(gmr("positions " + bvh_).out);
  const auto after = parse_csv(gmr("positions " + path("r.gmr")).out);
  EXPECT_EQ(plain.size(), after.size());
  EXPECT_LE(max_diff(plain, after), 1e-6);
}

TEST_F(CliOps, PositionsWithRootsAndStripKeepTheContract) {
  GMR_REQUIRE_DATA();
  const Outcome plain = gmr("positions " + bvh_ + " --frames 10:20");
  const Outcome rooted = gmr("positions " + bvh_ + " --frames 10:20 --roots LeftFoot,Head");
  ASSERT_EQ(rooted.status, 0) << rooted.err;
  EXPECT_EQ(std::count(plain.out.begin(), plain.out.end(), '\n'),
            std::count(rooted.out.begin(), rooted.out.end(), '\n'));
  // Rows come in the file's joint order, like plain `gmr positions`.
  std::istringstream a(plain.out), b(rooted.out);
  std::string la, lb;
  while (std::getline(a, la) && std::getline(b, lb)) {
    EXPECT_EQ(la.substr(0, la.find(',', la.find(',') + 1)), lb.substr(0, lb.find(',', lb.find(',') + 1)));
  }
  EXPECT_LE(max_diff(parse_csv(plain.out), parse_csv(rooted.out)), 1e-9 * 100);

  const Outcome stripped = gmr("positions " + bvh_ + " --frames 10:20 --strip-dummies");
  ASSERT_EQ(stripped.status, 0) << stripped.err;
  EXPECT_THAT(stripped.out, ::testing::Not(HasSubstr("LHipJoint")));
  EXPECT_THAT(stripped.out, HasSubstr(",LeftUpLeg,"));
  EXPECT_LE(max_diff(parse_csv(plain.out), parse_csv(stripped.out)), 1e-9 * 100);
}

TEST_F(CliOps, PositionsRelativeToAJoint) {
  GMR_REQUIRE_DATA();
  const Outcome r = gmr("positions " + bvh_ + " --frames 0:3 --relative-to Head");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto rows = parse_csv(r.out);
  for (int f = 0; f < 3; ++f) EXPECT_LE(rows.at(std::to_string(f) + ",Head").norm(), 1e-12);
  // A rigid change of frame keeps distances between joints.
  const auto world = parse_csv(gmr("positions " + bvh_ + " --frames 0:3").out);
  const double d0 = (rows.at("1,Hips") - rows.at("1,LeftHand")).norm();
  const double d1 = (world.at("1,Hips") - world.at("1,LeftHand")).norm();
  EXPECT_NEAR(d0, d1, 1e-9);
}

TEST_F(CliOps, ShiftSplitJoinStrip) {
  GMR_REQUIRE_DATA();
  ASSERT_EQ(gmr("shift " + bvh_ + " --to LeftToeBase -o " + path("s.gmr")).status, 0);
  auto m = load_motion(dir_ / "s.gmr");
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->skeleton.joint(m->skeleton.roots()[0]).name, "LeftToeBase");

  ASSERT_EQ(gmr("split " + bvh_ + " --at Spine -o " + path("p.gmr")).status, 0);
  const Outcome j = gmr("join " + path("p.gmr") + " --root Spine -o " + path("j.bvh"));
  ASSERT_EQ(j.status, 0) << j.err;
  EXPECT_THAT(j.out, HasSubstr("static offset"));
  const auto plain = parse_csv(gmr("positions " + bvh_).out);
  EXPECT_LE(max_diff(plain, parse_csv(gmr("positions " + path("j.bvh")).out)), 1e-6);

  const Outcome s = gmr("strip-dummies " + bvh_ + " -o " + path("d.gmr"));
  ASSERT_EQ(s.status, 0) << s.err;
  EXPECT_THAT(s.out, HasSubstr("removed LHipJoint (zero-length, merged into Hips)"));
  EXPECT_THAT(s.out, HasSubstr("removed RHipJoint (zero-length, merged into Hips)"));
  EXPECT_LE(max_diff(plain, parse_csv(gmr("positions " + path("d.gmr")).out)), 1e-6);
  // The same joints go when the motion is rooted at the head first.
  ASSERT_EQ(gmr("shift " + bvh_ + " --to Head -o " + path("h.gmr")).status, 0);
  const Outcome sh = gmr("strip-dummies " + path("h.gmr") + " -o " + path("hd.gmr"));
  ASSERT_EQ(sh.status, 0) << sh.err;
  EXPECT_THAT(sh.out, HasSubstr("removed LowerBack (zero-length, merged into Hips)"));
  EXPECT_EQ(s.out.size(), sh.out.size()) << s.out << sh.out;
  const auto a = parse_csv(gmr("positions " + path("d.gmr")).out);
  const auto b = parse_csv(gmr("positions " + path("hd.gmr")).out);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_LE(max_diff(a, b), 1e-6);

  const Outcome c = gmr("constant-rotations " + bvh_);
  ASSERT_EQ(c.status, 0);
  EXPECT_THAT(c.out, HasSubstr("LHipJoint\n"));
}

TEST_F(CliOps, MisuseFailsWithOneLine) {
  GMR_REQUIRE_DATA();
  expect_one_line_error("shift " + bvh_ + " --to Nope -o " + path("x.gmr"), "unknown joint 'Nope'");
  expect_one_line_error("roots " + bvh_ + " --set Hips,Nope -o " + path("x.gmr"), "unknown joint 'Nope'");
  expect_one_line_error("roots " + bvh_ + " --set Hips,,Head -o " + path("x.gmr"), "");
  expect_one_line_error("roots " + bvh_ + " --set Head,Head -o " + path("x.gmr"), "twice");
  expect_one_line_error("split " + bvh_ + " --at Hips -o " + path("x.gmr"), "already a root");
  expect_one_line_error("join " + bvh_ + " --root Hips -o " + path("x.gmr"), "last root");
  expect_one_line_error("join " + bvh_ + " --root Spine -o " + path("x.gmr"), "not a root");
  ASSERT_EQ(gmr("roots " + bvh_ + " --set Hips,Head -o " + path("two.gmr")).status, 0);
  expect_one_line_error("join " + path("two.gmr") + " --root Hips -o " + path("x.gmr"), "no soft link");
  expect_one_line_error("positions " + bvh_ + " --relative-to Nope", "unknown joint 'Nope'");
  expect_one_line_error("positions " + bvh_ + " --strip-dummies --relative-to LHipJoint", "zero-length");
  EXPECT_FALSE(fs::exists(dir_ / "x.gmr")) << "a failed command writes nothing";
}

}  // namespace
}  // namespace gmr
