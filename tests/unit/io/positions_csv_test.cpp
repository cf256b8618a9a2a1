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

}  // namespace
}  // namespace gmr
