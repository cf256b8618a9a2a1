// ASF/AMC through the `gmr` command: info, positions and convert with --asf,
// and the one-line error for broken files.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "gmr/acclaim/convert.h"
#include "gmr/acclaim/kinematics.h"
#include "gmr/core/file_util.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "cli_test_util.h"
#include "test_data.h"

namespace gmr {
namespace {
namespace fs = std::filesystem;

using Outcome = test::CliOutcome;
using test::shell_quote;
using ::testing::HasSubstr;

class CliAsf : public test::CliTest {};

// Positions of a `gmr positions` CSV, in row order.
std::vector<Eigen::Vector3d> csv_positions(const std::string& csv) {
  std::vector<Eigen::Vector3d> out;
  std::istringstream in(csv);
  std::string line;
  std::getline(in, line);
  while (std::getline(in, line)) {
    const auto c2 = line.find(',', line.find(',') + 1);
    Eigen::Vector3d p;
    if (std::sscanf(line.c_str() + c2 + 1, "%lf,%lf,%lf", &p.x(), &p.y(), &p.z()) == 3) out.push_back(p);
  }
  return out;
}

const std::string kAsf = "asfamc/09/09-run.asf";
const std::string kAmc = "asfamc/09/09_06-run.amc";

TEST_F(CliAsf, InfoAndPositions) {
  GMR_REQUIRE_DATA();
  const std::string args =
      shell_quote(test::data_file(kAmc).string()) + " --asf " + shell_quote(test::data_file(kAsf).string());
  const Outcome info = gmr("info " + args);
  ASSERT_EQ(info.status, 0) << info.err;
  EXPECT_NE(info.out.find("141"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("lfemur"), std::string::npos);

  const Outcome pos = gmr("positions " + args);
  ASSERT_EQ(pos.status, 0) << pos.err;
  EXPECT_EQ(pos.out.rfind("frame,joint,x,y,z\n0,root,", 0), 0u);
  // Exactly the library's positions (the CSV holds shortest round-trip numbers).
  auto g = read_asf_amc(test::data_file(kAsf), test::data_file(kAmc));
  ASSERT_TRUE(g.ok());
  const auto expect = compute_positions(*g);
  const auto got = csv_positions(pos.out);
  ASSERT_EQ(got.size(), expect.size());
  for (std::size_t i = 0; i < got.size(); ++i) ASSERT_EQ(got[i], expect[i]) << "row " << i;
}

// AMC files do not hold a frame rate: 120 unless --fps says, and the rate
// reaches what is written (the BVH's Frame Time).
TEST_F(CliAsf, FrameRateOfAnAmc) {
  GMR_REQUIRE_DATA();
  const std::string args =
      shell_quote(test::data_file(kAmc).string()) + " --asf " + shell_quote(test::data_file(kAsf).string());
  EXPECT_THAT(gmr("info " + args).out, HasSubstr("(120 fps)"));
  EXPECT_THAT(gmr("info " + args + " --fps 60").out, HasSubstr("(60 fps)"));
  const std::string bvh = shell_quote((dir_ / "at60.bvh").string());
  ASSERT_EQ(gmr("convert " + args + " --fps 60 " + bvh).status, 0);
  EXPECT_THAT(gmr("info " + bvh).out, HasSubstr("(60 fps)"));
  const Outcome zero = gmr("info " + args + " --fps 0");
  EXPECT_NE(zero.status, 0);  // CLI11's status for a value that fails its check
  EXPECT_THAT(zero.err, HasSubstr("--fps"));
}

TEST_F(CliAsf, ConvertToGmrAndToAmc) {
  GMR_REQUIRE_DATA();
  const std::string in =
      shell_quote(test::data_file(kAmc).string()) + " --asf " + shell_quote(test::data_file(kAsf).string());
  const std::string gmr_out = (dir_ / "run.gmr").string();
  const std::string amc_out = (dir_ / "run.amc").string();
  ASSERT_EQ(gmr("convert " + in + " " + shell_quote(gmr_out)).status, 0);
  const Outcome to_amc = gmr("convert " + in + " " + shell_quote(amc_out));
  ASSERT_EQ(to_amc.status, 0) << to_amc.err;
  EXPECT_TRUE(fs::exists(dir_ / "run.asf"));  // the skeleton goes beside the motion

  const auto ref = csv_positions(gmr("positions " + in).out);
  const auto from_gmr = csv_positions(gmr("positions " + shell_quote(gmr_out)).out);
  const auto from_amc = csv_positions(
      gmr("positions " + shell_quote(amc_out) + " --asf " + shell_quote((dir_ / "run.asf").string())).out);
  ASSERT_EQ(from_gmr.size(), ref.size());
  ASSERT_EQ(from_amc.size(), ref.size());
  for (std::size_t i = 0; i < ref.size(); ++i) {
    ASSERT_EQ(from_gmr[i], ref[i]) << "row " << i;
    ASSERT_LE((from_amc[i] - ref[i]).norm(), 1e-9 * 30.0) << "row " << i;
  }
}

// An .amc output is written with its .asf as a pair: an .asf beside it that
// holds another skeleton is kept unless --force, and a failure writes neither.
TEST_F(CliAsf, AmcOutputNeverClobbersAnotherSkeletonOrHalfWritesThePair) {
  GMR_REQUIRE_DATA();
  const std::string in =
      shell_quote(test::data_file(kAmc).string()) + " --asf " + shell_quote(test::data_file(kAsf).string());
  ASSERT_TRUE(write_file_atomic(dir_ / "run.asf", ":version 1.10\n# another subject's skeleton\n").ok());
  expect_one_line_error("convert " + in + " " + path("run.amc"), "holds another skeleton");
  EXPECT_EQ(read_file(dir_ / "run.asf").value(), ":version 1.10\n# another subject's skeleton\n");
  EXPECT_FALSE(fs::exists(dir_ / "run.amc"));
  ASSERT_EQ(gmr("convert " + in + " " + path("run.amc") + " --force").status, 0);
  const std::string written = read_file(dir_ / "run.asf").value();
  EXPECT_NE(written.find(":bonedata"), std::string::npos);
  // The same skeleton again needs no --force.
  const Outcome again = gmr("convert " + in + " " + path("run.amc"));
  EXPECT_EQ(again.status, 0) << again.err;
  EXPECT_EQ(read_file(dir_ / "run.asf").value(), written);

  // The .amc cannot be written (a folder stands there): no .asf appears either.
  fs::create_directories(dir_ / "blocked.amc");
  expect_one_line_error("convert " + in + " " + path("blocked.amc"), "blocked.amc");
  EXPECT_FALSE(fs::exists(dir_ / "blocked.asf"));
  for (const auto& e : fs::directory_iterator(dir_)) {
    EXPECT_EQ(e.path().filename().string().find(".tmp."), std::string::npos) << "temporary left: " << e.path();
  }
}

// A 40,000-bone chain: reading it and printing its tree are linear (they
// once took 15 s and printed 1.6 GB of indentation).
TEST_F(CliAsf, ADeepChainLoadsAndPrintsInLinearSize) {
  constexpr int kBones = 40000;
  std::string asf =
      ":version 1.10\n:name chain\n:units\n  angle deg\n:root\n  order TX TY TZ RX RY RZ\n"
      "  axis XYZ\n  position 0 0 0\n  orientation 0 0 0\n:bonedata\n";
  for (int i = 1; i <= kBones; ++i) {
    asf += "  begin\n    id " + std::to_string(i) + "\n    name b" + std::to_string(i) +
           "\n    direction 0 1 0\n    length 1\n    axis 0 0 0 XYZ\n    dof rx\n  end\n";
  }
  asf += ":hierarchy\n  begin\n    root b1\n";
  for (int i = 1; i < kBones; ++i) asf += "    b" + std::to_string(i) + " b" + std::to_string(i + 1) + "\n";
  asf += "  end\n";
  ASSERT_TRUE(write_file_atomic(dir_ / "chain.asf", asf).ok());
  ASSERT_TRUE(write_file_atomic(dir_ / "chain.amc", ":FULLY-SPECIFIED\n:DEGREES\n1\nroot 0 0 0 0 0 0\nb2 5\n").ok());
  const auto r = gmr("info " + path("chain.amc") + " --asf " + path("chain.asf"));
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("joints:      40001"), std::string::npos) << r.out.substr(0, 400);
  EXPECT_NE(r.out.find("[depth 40000] b40000"), std::string::npos);
  EXPECT_LT(r.out.size(), 100u * kBones);
}

TEST_F(CliAsf, BrokenFilesGiveOneLocatedLine) {
  GMR_REQUIRE_DATA();
  const std::string amc = test::data_file("malformed/TRUNC_07_05-walk_mid_frame.amc").string();
  const std::string asf = test::data_file("asfamc/07/07-walk.asf").string();
  const std::string bad_asf = test::data_file("malformed/TRUNC_07-walk_in_bonedata.asf").string();
  const Outcome a = gmr("info " + shell_quote(amc) + " --asf " + shell_quote(asf));
  EXPECT_EQ(a.status, 1);
  EXPECT_EQ(a.err, "gmr: " + amc + ":2345:26: expected 6 values for bone 'root' (order TX TY TZ RX RY RZ), found 3\n");
  const Outcome b = gmr("positions " + shell_quote(amc) + " --asf " + shell_quote(bad_asf));
  EXPECT_EQ(b.status, 1);
  EXPECT_EQ(b.err, "gmr: " + bad_asf + ":147:12: expected 1 number after 'length', found 0\n");
  EXPECT_TRUE(b.out.empty());
}

}  // namespace
}  // namespace gmr
