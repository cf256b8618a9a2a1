// The file commands of the `gmr` binary: info, convert, positions.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <sys/wait.h>
#include <map>
#include <sstream>
#include <filesystem>
#include <string>

#include <Eigen/Geometry>
#include <vector>

#include "gmr/core/file_util.h"
#include "gmr/io/bvh.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "cli_test_util.h"
#include "test_data.h"

namespace gmr {
namespace {
namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::StartsWith;

using Outcome = test::CliOutcome;
using test::shell_quote;

class CliFiles : public test::CliTest {};

// "frame,joint" -> position, from `gmr positions` output (names without quotes).
std::map<std::string, Eigen::Vector3d> parse_csv(const std::string& csv) {
  std::map<std::string, Eigen::Vector3d> out;
  std::istringstream in(csv);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    const auto c2 = line.find(',', line.find(',') + 1);
    Eigen::Vector3d p;
    std::sscanf(line.c_str() + c2 + 1, "%lf,%lf,%lf", &p.x(), &p.y(), &p.z());
    out[line.substr(0, c2)] = p;
  }
  return out;
}

std::size_t lines(const std::string& s) { return static_cast<std::size_t>(std::count(s.begin(), s.end(), '\n')); }

TEST_F(CliFiles, PositionsOfARealFile) {
  GMR_REQUIRE_DATA();
  const std::string file = shell_quote(test::data_file("bvh/cmu/02_01.bvh").string());
  const Outcome all = gmr("positions " + file);
  ASSERT_EQ(all.status, 0) << all.err;
  EXPECT_THAT(all.out, StartsWith("frame,joint,x,y,z\n0,Hips,10.4194,16.7048,-30.1003\n"));
  EXPECT_EQ(lines(all.out), 1 + 344u * 38u);  // every frame x (31 joints + 7 End Sites)
  EXPECT_TRUE(all.err.empty()) << all.err;

  const Outcome some = gmr("positions " + file + " --frames 10:20");
  ASSERT_EQ(some.status, 0) << some.err;
  EXPECT_EQ(lines(some.out), 1 + 10u * 38u);
  EXPECT_THAT(some.out, StartsWith("frame,joint,x,y,z\n10,Hips,"));
  EXPECT_NE(some.out.find("\n19,LeftToeBase_End,"), std::string::npos);
  EXPECT_EQ(some.out.find("\n20,"), std::string::npos);

  const Outcome tail = gmr("positions " + file + " --frames 340:");
  EXPECT_EQ(lines(tail.out), 1 + 4u * 38u);
}

// --orientations: GMR's W_j (the frame of the bone parent -> j). For a BVH,
// that is the BVH frame of j's parent, computed here by the reference FK of
// the file as read (post-rotation), a different path from the command's.
TEST_F(CliFiles, PositionsWithOrientations) {
  GMR_REQUIRE_DATA();
  const fs::path path = test::data_file("bvh/cmu/02_01.bvh");
  const std::string file = shell_quote(path.string());
  const Outcome q = gmr("positions " + file + " --frames 100:103 --orientations quat");
  const Outcome m = gmr("positions " + file + " --frames 100:103 --orientations matrix");
  const Outcome plain = gmr("positions " + file + " --frames 100:103");
  ASSERT_EQ(q.status, 0) << q.err;
  ASSERT_EQ(m.status, 0) << m.err;
  EXPECT_THAT(q.out, StartsWith("frame,joint,x,y,z,qw,qx,qy,qz\n100,Hips,"));
  EXPECT_THAT(m.out, StartsWith("frame,joint,x,y,z,r00,r01,r02,r10,r11,r12,r20,r21,r22\n100,Hips,"));
  const Motion bvh = read_bvh(path).value();
  const std::size_t joints = bvh.skeleton.size();
  std::vector<Eigen::Vector3d> p(joints);
  std::vector<Eigen::Matrix3d> w(joints);
  std::istringstream qin(q.out), min(m.out), pin(plain.out);
  std::string ql, ml, pl;
  std::getline(qin, ql);
  std::getline(min, ml);
  std::getline(pin, pl);
  std::size_t rows = 0;
  for (std::size_t f = 100; f < 103; ++f) {
    compute_frame(bvh, f, p, w);
    for (std::size_t j = 0; j < joints; ++j) {
      ASSERT_TRUE(std::getline(qin, ql) && std::getline(min, ml) && std::getline(pin, pl));
      // The position columns are those of plain `gmr positions`.
      EXPECT_EQ(ql.substr(0, pl.size() + 1), pl + ",");
      const int parent = bvh.skeleton.joint(static_cast<int>(j)).parent;
      const Eigen::Matrix3d want = parent < 0 ? Eigen::Matrix3d::Identity() : w[static_cast<std::size_t>(parent)];
      auto tail = [](const std::string& line, int n) {  // the last n numbers of a row
        std::vector<double> v;
        std::size_t at = line.size();
        for (int i = 0; i < n; ++i) at = line.rfind(',', at - 1);
        std::istringstream s(line.substr(at + 1));
        std::string cell;
        while (std::getline(s, cell, ',')) v.push_back(std::stod(cell));
        return v;
      };
      const auto qv = tail(ql, 4);
      const auto mv = tail(ml, 9);
      ASSERT_EQ(qv.size(), 4u);
      ASSERT_EQ(mv.size(), 9u);
      EXPECT_GE(qv[0], 0.0);
      const Eigen::Matrix3d from_q = Eigen::Quaterniond(qv[0], qv[1], qv[2], qv[3]).toRotationMatrix();
      Eigen::Matrix3d from_m;
      from_m << mv[0], mv[1], mv[2], mv[3], mv[4], mv[5], mv[6], mv[7], mv[8];
      EXPECT_LE((from_q - want).cwiseAbs().maxCoeff(), 1e-12) << ql;
      EXPECT_LE((from_m - want).cwiseAbs().maxCoeff(), 1e-12) << ml;
      ++rows;
    }
  }
  EXPECT_EQ(rows, 3u * 38u);
  EXPECT_FALSE(std::getline(qin, ql));
  // With a view option too (before: refused). Seen from the Head, the Head
  // is at the origin with no rotation, in every frame.
  const Outcome both = gmr("positions " + file + " --frames 0:3 --orientations quat --relative-to Head");
  ASSERT_EQ(both.status, 0) << both.err;
  std::istringstream seen(both.out);
  std::size_t heads = 0;
  for (std::string line; std::getline(seen, line);) {
    if (line.find(",Head,") == std::string::npos) continue;
    std::vector<double> v;
    std::istringstream cells(line.substr(line.find(",Head,") + 6));
    for (std::string cell; std::getline(cells, cell, ',');) v.push_back(std::stod(cell));
    ASSERT_EQ(v.size(), 7u) << line;
    for (int k : {0, 1, 2, 4, 5, 6}) EXPECT_NEAR(v[static_cast<std::size_t>(k)], 0.0, 1e-9) << line;
    EXPECT_NEAR(v[3], 1.0, 1e-12) << line;
    ++heads;
  }
  EXPECT_EQ(heads, 3u);
}

TEST_F(CliFiles, MalformedFileGivesOneLineWithTheLocation) {
  GMR_REQUIRE_DATA();
  const std::string path = test::data_file("malformed/TRUNC_02_01_mid_frame.bvh").string();
  for (const char* cmd : {"positions", "info"}) {
    const Outcome r = gmr(std::string(cmd) + " " + shell_quote(path));
    EXPECT_EQ(r.status, 1) << cmd;
    EXPECT_EQ(lines(r.err), 1u) << r.err;
    EXPECT_THAT(r.err, StartsWith("gmr: " + path + ":317:375: file ends in frame 129")) << r.err;
    EXPECT_TRUE(r.out.empty() || std::string(cmd) == "info");
  }
  const Outcome fused = gmr("info " + shell_quote(test::data_file("malformed/TRUNC_02_01_in_hierarchy.bvh").string()));
  EXPECT_EQ(fused.status, 1);
  EXPECT_EQ(lines(fused.err), 1u);
  EXPECT_THAT(fused.err, HasSubstr("TRUNC_02_01_in_hierarchy.bvh:"));
}

TEST_F(CliFiles, RunningOutOfMemoryIsOneClearLine) {
  // A 38 MB BVH (31 joints, 100,000 frames) converted by a process allowed
  // 200 MB of address space: the allocation fails, and the user reads what
  // happened instead of "std::bad_alloc".
  std::string text =
      "HIERARCHY\nROOT A\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation "
      "Xrotation Yrotation\n";
  for (int j = 0; j < 30; ++j) {
    text += " JOINT J" + std::to_string(j) + "\n {\n  OFFSET 0 1 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n";
  }
  text += "  End Site\n  {\n   OFFSET 0 1 0\n  }\n" + std::string(30, '}') +
          "\n}\nMOTION\nFrames: 100000\nFrame Time: 0.01\n";
  std::string row;
  for (int v = 0; v < 96; ++v) row += v == 0 ? "1.5" : " 1.5";
  row += '\n';
  text.reserve(text.size() + row.size() * 100000);
  for (int f = 0; f < 100000; ++f) text += row;
  ASSERT_TRUE(write_file_atomic(dir_ / "big.bvh", text).ok());
  const std::string cmd = "ulimit -v 200000; exec " + shell_quote(GMR_CLI_PATH) + " convert " + path("big.bvh") + " " +
                          path("big.gmr") + " 2>" + path("err");
  const int raw = std::system(("sh -c " + shell_quote(cmd)).c_str());
  ASSERT_TRUE(WIFEXITED(raw));
  EXPECT_EQ(WEXITSTATUS(raw), 1);
  const std::string err = read_file(dir_ / "err").value();
  EXPECT_EQ(err, "gmr: convert: out of memory (the input needs more than this process may use)\n");
  EXPECT_FALSE(std::filesystem::exists(dir_ / "big.gmr"));
}

TEST_F(CliFiles, AWriteCutShortLeavesNoTemporary) {
  // The file size limit stops `gmr convert` mid-write: one line, exit 1, and
  // neither the output nor its temporary is left (without gmr's handling the
  // limit's signal would end the process and leave the temporary).
  std::string text =
      "HIERARCHY\nROOT A\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}\n"
      "MOTION\nFrames: 20000\nFrame Time: 0.01\n";
  for (int f = 0; f < 20000; ++f) text += "1.25 2.5 " + std::to_string(f) + "\n";
  ASSERT_TRUE(write_file_atomic(dir_ / "in.bvh", text).ok());
  const std::string cmd = "ulimit -f 64; exec " + shell_quote(GMR_CLI_PATH) + " convert " + path("in.bvh") + " " +
                          path("out.gmr") + " 2>" + path("err");
  const int raw = std::system(("sh -c " + shell_quote(cmd)).c_str());
  ASSERT_TRUE(WIFEXITED(raw)) << "ended by a signal";
  EXPECT_EQ(WEXITSTATUS(raw), 1);
  const std::string err = read_file(dir_ / "err").value();
  EXPECT_THAT(err, StartsWith("gmr: " + (dir_ / "out.gmr").string() + ": cannot write file: File too large")) << err;
  std::vector<std::string> left;
  for (const auto& e : std::filesystem::directory_iterator(dir_)) left.push_back(e.path().filename().string());
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left, (std::vector<std::string>{"err", "in.bvh"}));
}

TEST_F(CliFiles, WarningsGoToStderrAndTheCommandSucceeds) {
  GMR_REQUIRE_DATA();
  const Outcome r = gmr("info " + shell_quote(test::data_file("malformed/Boxing_Toes_frames_off_by_one.bvh").string()));
  EXPECT_EQ(r.status, 0);
  EXPECT_THAT(r.out, HasSubstr("frames:      3070\n"));
  EXPECT_THAT(r.err, HasSubstr("gmr: warning: "));
  EXPECT_THAT(r.err, HasSubstr(":128:1: 'Frames: 3069' but the file holds 3070"));
}

TEST_F(CliFiles, Info) {
  GMR_REQUIRE_DATA();
  const Outcome r = gmr("info " + shell_quote(test::data_file("bvh/cmu/02_01.bvh").string()));
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("joints:      38"));
  EXPECT_THAT(r.out, HasSubstr("roots:       1 (Hips)"));
  EXPECT_THAT(r.out, HasSubstr("channels:    96 per frame"));
  EXPECT_THAT(r.out, HasSubstr("frames:      344"));
  EXPECT_THAT(r.out, HasSubstr("frame time:  0.0083333 s (120"));
  EXPECT_THAT(r.out, HasSubstr("duration:    2.86666 s"));
  EXPECT_THAT(r.out, HasSubstr("\n    LHipJoint  [Zrotation Yrotation Xrotation]\n"));
}

TEST_F(CliFiles, ConvertBvhToGmrAndBackKeepsPositions) {
  GMR_REQUIRE_DATA();
  const std::string src = shell_quote(test::data_file("bvh/cmu/02_01.bvh").string());
  const std::string gmr_file = shell_quote((dir_ / "walk.gmr").string());
  const std::string bvh_file = shell_quote((dir_ / "walk.bvh").string());
  ASSERT_EQ(gmr("convert " + src + " " + gmr_file).status, 0);
  ASSERT_EQ(gmr("convert " + gmr_file + " " + bvh_file).status, 0);
  EXPECT_THAT(read_file(dir_ / "walk.gmr").value(), StartsWith("GMR 1\nHIERARCHY\n"));
  const Outcome a = gmr("positions " + src + " --frames 0:50");
  const Outcome b = gmr("positions " + gmr_file + " --frames 0:50");
  const Outcome c = gmr("positions " + bvh_file + " --frames 0:50");
  ASSERT_EQ(a.status, 0);
  ASSERT_EQ(b.status, 0) << b.err;
  ASSERT_EQ(c.status, 0) << c.err;
  // Every row of the source is in both conversions with the same position
  // (the conversions may add zero-length joints: extra rows are allowed).
  EXPECT_EQ(lines(a.out), 1 + 50u * 38u);
  const auto pa = parse_csv(a.out), pb = parse_csv(b.out), pc = parse_csv(c.out);
  ASSERT_EQ(pa.size(), 50u * 38u);
  for (const auto& [key, p] : pa) {
    ASSERT_TRUE(pb.count(key)) << key;
    ASSERT_TRUE(pc.count(key)) << key;
    EXPECT_LE((pb.at(key) - p).norm(), 1e-9) << key;
    EXPECT_LE((pc.at(key) - p).norm(), 1e-9) << key;
  }
}

TEST_F(CliFiles, BadArgumentsFailWithOneLine) {
  GMR_REQUIRE_DATA();
  const std::string src = shell_quote(test::data_file("bvh/cmu/02_01.bvh").string());
  const Outcome range = gmr("positions " + src + " --frames 5");
  EXPECT_EQ(range.status, 1);
  EXPECT_EQ(lines(range.err), 1u);
  EXPECT_THAT(range.err, HasSubstr("expected A:B"));
  const Outcome past = gmr("positions " + src + " --frames 400:");
  EXPECT_EQ(past.status, 1);
  EXPECT_THAT(past.err, HasSubstr("frames [400, end) are not within the motion's 344 frames"));
  // One rule with the protocol's QueryFrames: a range that reaches past the
  // last frame, or holds none, is refused, never clamped.
  const Outcome over = gmr("positions " + src + " --frames 300:400");
  EXPECT_EQ(over.status, 1);
  EXPECT_EQ(lines(over.err), 1u);
  EXPECT_THAT(over.err, HasSubstr("frames [300, 400) are not within the motion's 344 frames"));
  EXPECT_TRUE(over.out.empty());
  EXPECT_EQ(gmr("positions " + src + " --frames 5:5").status, 1);
  const Outcome last = gmr("positions " + src + " --frames 343:344");
  EXPECT_EQ(last.status, 0);
  EXPECT_EQ(lines(last.out), 1u + 38u);  // header + one frame of 38 joints (31 and 7 End Sites)
  const Outcome ext = gmr("convert " + src + " " + shell_quote((dir_ / "out.xyz").string()));
  EXPECT_EQ(ext.status, 1);
  EXPECT_EQ(lines(ext.err), 1u);
  EXPECT_THAT(ext.err, HasSubstr("cannot write '.xyz' files"));
  EXPECT_FALSE(fs::exists(dir_ / "out.xyz"));
  const Outcome missing = gmr("info " + shell_quote((dir_ / "nope.bvh").string()));
  EXPECT_EQ(missing.status, 1);
  EXPECT_THAT(missing.err, HasSubstr("nope.bvh: cannot open file"));
}

}  // namespace
}  // namespace gmr
