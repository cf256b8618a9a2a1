#include "gmr/io/positions_csv.h"

#include <gtest/gtest.h>

#include <sstream>

namespace gmr {
namespace {

Skeleton two(std::string a, std::string b) {
  Joint r;
  r.name = std::move(a);
  Joint c;
  c.name = std::move(b);
  c.parent = 0;
  return Skeleton::create({r, c}).value();
}

TEST(PositionsCsv, HeaderAndRows) {
  std::ostringstream out;
  write_positions_csv_header(out);
  const Skeleton sk = two("Hips", "Left Hand.1:x");
  const std::vector<Eigen::Vector3d> p = {{1.5, 90.25, -3}, {0.1 + 0.2, 1e-7, 1e21}, {0, -0.0, 2}, {-1, -2, -3}};
  write_positions_csv_rows(out, sk, p, 7);
  EXPECT_EQ(out.str(),
            "frame,joint,x,y,z\n"
            "7,Hips,1.5,90.25,-3\n"
            "7,Left Hand.1:x,0.30000000000000004,1e-07,1e+21\n"
            "8,Hips,0,0,2\n"  // -0 prints as 0
            "8,Left Hand.1:x,-1,-2,-3\n");
}

TEST(PositionsCsv, NamesThatNeedQuoting) {
  std::ostringstream out;
  const Skeleton sk = two("a,b", "say \"hi\"");
  const std::vector<Eigen::Vector3d> p = {{1, 2, 3}, {4, 5, 6}};
  write_positions_csv_rows(out, sk, p, 0);
  EXPECT_EQ(out.str(), "0,\"a,b\",1,2,3\n0,\"say \"\"hi\"\"\",4,5,6\n");
}

TEST(PositionsCsv, ManyFramesAreAllWritten) {
  std::ostringstream out;
  const Skeleton sk = two("A", "B");
  std::vector<Eigen::Vector3d> p(2 * 5000, Eigen::Vector3d(1.25, 2.5, 3.75));
  write_positions_csv_rows(out, sk, p, 0);
  const std::string s = out.str();
  EXPECT_EQ(std::count(s.begin(), s.end(), '\n'), 10000);
  EXPECT_NE(s.find("\n4999,B,1.25,2.5,3.75\n"), std::string::npos);
}

// What `gmr positions` (and --orientations) writes reads back exactly: the
// shortest round-tripping numbers parse to the same doubles.
TEST(PositionsCsv, ReadsBackWhatItWrites) {
  const Skeleton sk = two("a,b", "say \"hi\"");
  std::vector<Eigen::Vector3d> p;
  std::vector<Eigen::Matrix3d> r;
  for (int f = 0; f < 3; ++f) {
    for (int j = 0; j < 2; ++j) {
      p.emplace_back(0.1 * f + j, 1e-7 * (f + 1), -1e21 + f);
      r.push_back(Eigen::AngleAxisd(0.3 * f + j, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix());
    }
  }
  for (int kind = 0; kind < 3; ++kind) {
    SCOPED_TRACE(kind);
    std::ostringstream out;
    if (kind == 0) {
      write_positions_csv_header(out);
      write_positions_csv_rows(out, sk, p, 4);
    } else {
      const auto columns = kind == 1 ? OrientationColumns::kQuaternion : OrientationColumns::kMatrix;
      write_poses_csv_header(out, columns);
      write_poses_csv_rows(out, sk, p, r, 4, columns);
    }
    auto t = parse_positions_csv(out.str(), "p.csv");
    ASSERT_TRUE(t.ok()) << t.error().to_string();
    EXPECT_EQ(t->joints, (std::vector<std::string>{"a,b", "say \"hi\""}));
    EXPECT_EQ(t->first_frame, 4u);
    EXPECT_EQ(t->frames, 3u);
    ASSERT_EQ(t->positions.size(), p.size());
    for (std::size_t k = 0; k < p.size(); ++k) EXPECT_EQ(t->positions[k], p[k]);
    ASSERT_EQ(t->orientations.size(), kind == 0 ? 0u : p.size());
    for (std::size_t k = 0; k < t->orientations.size(); ++k) {
      EXPECT_LT((t->orientations[k].toRotationMatrix() - r[k]).cwiseAbs().maxCoeff(), 1e-12);
    }
  }
}

// Found by the csv fuzzer: a file whose last line is a lone carriage return
// without a line break threw std::out_of_range (the end-of-file check read
// past the text) instead of ending the table.
TEST(PositionsCsv, ALastLineOfOnlyACarriageReturnEndsTheTable) {
  for (const std::string tail : {"\r", "\r\n", "\r\n\r", "\n\r"}) {
    SCOPED_TRACE(static_cast<int>(tail.size()));
    auto t = parse_positions_csv("frame,joint,x,y,z\r\n0,a,1,2,3\r\n" + tail, "p.csv");
    ASSERT_TRUE(t.ok()) << t.error().to_string();
    EXPECT_EQ(t->frames, 1u);
  }
}

TEST(PositionsCsv, BadFilesSayWhereAndWhat) {
  struct Case {
    std::string text;
    std::string says;  // "line:column: message" part
  };
  const std::string h = "frame,joint,x,y,z\n";
  const std::vector<Case> cases = {
      {"", "p.csv:1:1: an empty file"},
      {"frame,joint,x,y\n0,a,1,2\n", "p.csv:1:1: not a positions CSV"},
      {h, "p.csv:1:1: no rows after the header"},
      {h + "0,a,1,2,3\nx,a,1,2,3\n", "p.csv:3:1: frame 'x' is not a frame number"},
      {h + "0,a,1,2,nan\n", "p.csv:2:9: 'nan' is not a finite number"},
      {h + "0,a,1,2e400,3\n", "p.csv:2:7: '2e400' is not a finite number"},
      {h + "0,a,1,2\n", "p.csv:2:1: 4 fields; the header has 5"},
      {h + "0,\"a,1,2,3\n", "p.csv:2:3: a quoted joint name that is not closed"},
      {h + "0,a,1,2,3\n0,a,1,2,3\n", "p.csv:3:3: joint 'a' twice in frame 0"},
      {h + "0,a,1,2,3\n2,a,1,2,3\n", "p.csv:3:1: frame 2 after frame 0: frames follow one another"},
      {h + "0,a,1,2,3\n0,b,1,2,3\n1,a,1,2,3\n2,a,1,2,3\n", "p.csv:5:1: frame 1 has 1 rows; the first frame has 2"},
      {h + "0,a,1,2,3\n0,b,1,2,3\n1,b,1,2,3\n", "p.csv:4:3: frame 1 row 1 is 'b'; the first frame has 'a'"},
      {h + "0,a,1,2,3\n0,b,1,2,3\n1,a,1,2,3\n", "p.csv:4:1: the last frame, 1, has 1 rows"},
      {h + "0,a,1,2,3\n\n1,a,1,2,3\n", "p.csv:3:1: an empty row"},
      {"frame,joint,x,y,z,qw,qx,qy,qz\n0,a,1,2,3,2,0,0,0\n", "p.csv:2:11: the quaternion is not of unit length"},
      {"frame,joint,x,y,z,r00,r01,r02,r10,r11,r12,r20,r21,r22\n0,a,1,2,3,1,0,0,0,1,0,0,0,-1\n",
       "p.csv:2:11: the orientation is not a rotation matrix"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.text);
    auto t = parse_positions_csv(c.text, "p.csv");
    ASSERT_FALSE(t.ok());
    EXPECT_EQ(t.error().to_string().rfind(c.says, 0), 0u) << t.error().to_string();
  }
  // Blank lines at the end and CRLF line ends are fine.
  auto t = parse_positions_csv("frame,joint,x,y,z\r\n3,a,1,2,3\r\n\r\n\n", "p.csv");
  ASSERT_TRUE(t.ok()) << t.error().to_string();
  EXPECT_EQ(t->frames, 1u);
  EXPECT_EQ(t->first_frame, 3u);
}

}  // namespace
}  // namespace gmr
