#include "gmr/kinematics/forward_kinematics.h"

#include <gtest/gtest.h>

namespace gmr {
namespace {

// A root at (1, 2, 3) with a Z rotation, and one child 1 unit along x.
Motion two_joints(Convention c, double root_angle, double child_angle) {
  Joint root;
  root.name = "root";
  root.offset = {1, 2, 3};
  root.channels = {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition, ChannelType::kZrotation};
  Joint child;
  child.name = "child";
  child.parent = 0;
  child.offset = {1, 0, 0};
  child.channels = {ChannelType::kZrotation};
  Motion m;
  m.skeleton = Skeleton::create({root, child}).value();
  m.convention = c;
  m.frame_time = 0.1;
  m.frame_count = 1;
  m.values = {1, 2, 3, root_angle, child_angle};
  return m;
}

TEST(PostRotation, OwnRotationMovesChildrenOnly) {
  Motion m = two_joints(Convention::kPostRotation, 90.0, 45.0);
  std::vector<Eigen::Vector3d> p(2);
  std::vector<Eigen::Matrix3d> w(2);
  compute_frame(m, 0, p, w);
  EXPECT_TRUE(p[0].isApprox(Eigen::Vector3d(1, 2, 3)));
  // Only the root's 90 degrees move the child; the child's own 45 do not.
  EXPECT_TRUE(p[1].isApprox(Eigen::Vector3d(1, 3, 3), 1e-15));
  EXPECT_TRUE(w[1].isApprox(axis_rotation(Axis::kZ, 135.0), 1e-15));
}

TEST(PreRotation, OwnRotationMovesTheJoint) {
  Motion m = two_joints(Convention::kPreRotation, 90.0, 45.0);
  std::vector<Eigen::Vector3d> p(2);
  compute_frame(m, 0, p);
  // Root 90 then child 45: the bone points at 135 degrees.
  const double c = std::sqrt(0.5);
  EXPECT_TRUE(p[1].isApprox(Eigen::Vector3d(1 - c, 2 + c, 3), 1e-15));
}

TEST(PositionChannels, ReplaceOffsetComponents) {
  Motion m = two_joints(Convention::kPostRotation, 0.0, 0.0);
  m.values[0] = 10.0;  // Xposition replaces offset x = 1
  std::vector<Eigen::Vector3d> p(2);
  compute_frame(m, 0, p);
  EXPECT_DOUBLE_EQ(p[0].x(), 10.0);
}

TEST(Range, ComputePositions) {
  Motion m = two_joints(Convention::kPreRotation, 0.0, 0.0);
  m.frame_count = 3;
  m.values = {0, 0, 0, 0, 0, 0, 0, 0, 90, 0, 0, 0, 0, 0, 180};
  auto all = compute_positions(m);
  ASSERT_EQ(all.size(), 6u);
  EXPECT_TRUE(all[3].isApprox(Eigen::Vector3d(0, 1, 0), 1e-15));
  EXPECT_TRUE(all[5].isApprox(Eigen::Vector3d(-1, 0, 0), 1e-15));
  auto mid = compute_positions(m, 1, 2);
  ASSERT_EQ(mid.size(), 2u);
  EXPECT_TRUE(mid[1].isApprox(all[3]));
  EXPECT_TRUE(compute_positions(m, 5, 9).empty());
  EXPECT_TRUE(m.validate().ok());
  m.values.pop_back();
  EXPECT_FALSE(m.validate().ok());
}

}  // namespace
}  // namespace gmr
