#include "gmr/core/rotation.h"

#include <gtest/gtest.h>

#include <random>

namespace gmr {
namespace {

const Axis kOrders[6][3] = {{Axis::kX, Axis::kY, Axis::kZ}, {Axis::kX, Axis::kZ, Axis::kY},
                            {Axis::kY, Axis::kX, Axis::kZ}, {Axis::kY, Axis::kZ, Axis::kX},
                            {Axis::kZ, Axis::kX, Axis::kY}, {Axis::kZ, Axis::kY, Axis::kX}};

Eigen::Matrix3d compose(const Axis order[3], const Eigen::Vector3d& a) {
  return axis_rotation(order[0], a[0]) * axis_rotation(order[1], a[1]) * axis_rotation(order[2], a[2]);
}

TEST(ComposeRotation, ListedOrderIsIntrinsic) {
  // Zrotation Xrotation Yrotation is Rz * Rx * Ry.
  const ChannelType ch[] = {ChannelType::kZrotation, ChannelType::kXrotation, ChannelType::kYrotation};
  const double v[] = {30.0, -45.0, 60.0};
  const Eigen::Matrix3d expected =
      axis_rotation(Axis::kZ, 30) * axis_rotation(Axis::kX, -45) * axis_rotation(Axis::kY, 60);
  EXPECT_TRUE(compose_rotation(ch, v).isApprox(expected, 1e-15));
  // A point on x rotated 90 degrees about z goes to y.
  EXPECT_TRUE((axis_rotation(Axis::kZ, 90) * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY(), 1e-15));
}

TEST(ComposeRotation, SkipsPositionsAndMissingAxesAreZero) {
  const ChannelType ch[] = {ChannelType::kXposition, ChannelType::kYrotation, ChannelType::kZposition};
  const double v[] = {5.0, 20.0, 7.0};
  EXPECT_TRUE(compose_rotation(ch, v).isApprox(axis_rotation(Axis::kY, 20), 1e-15));
  EXPECT_TRUE(compose_rotation({}, {}).isIdentity());
}

TEST(DecomposeEuler, ReconstructsEveryOrder) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-180.0, 180.0);
  for (const auto& order : kOrders) {
    for (int i = 0; i < 2000; ++i) {
      const Eigen::Vector3d a(u(rng), u(rng) / 2, u(rng));
      const Eigen::Matrix3d r = compose(order, a);
      const Eigen::Vector3d d = decompose_euler(r, order);
      EXPECT_LT((compose(order, d) - r).cwiseAbs().maxCoeff(), 1e-14);
    }
  }
}

TEST(DecomposeEuler, GimbalLockStillReconstructs) {
  for (const auto& order : kOrders) {
    for (double b : {90.0, -90.0, 90.0 - 1e-7, -90.0 + 1e-9}) {
      const Eigen::Vector3d a(37.0, b, -121.0);
      const Eigen::Matrix3d r = compose(order, a);
      const Eigen::Vector3d d = decompose_euler(r, order);
      EXPECT_LT((compose(order, d) - r).cwiseAbs().maxCoeff(), 1e-14) << "b=" << b;
    }
  }
}

TEST(DecomposeEuler, HintKeepsAnglesContinuous) {
  const Axis* order = kOrders[4];
  const Eigen::Vector3d a(170.0, 120.0, -400.0);  // middle angle past 90, last past a turn
  const Eigen::Matrix3d r = compose(order, a);
  const Eigen::Vector3d d = decompose_euler(r, order, &a);
  EXPECT_LT((d - a).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(ParseChannel, BvhSpellings) {
  EXPECT_EQ(parse_channel("Xrotation"), ChannelType::kXrotation);
  EXPECT_EQ(parse_channel("ZPOSITION"), ChannelType::kZposition);
  EXPECT_EQ(parse_channel("Wrotation"), std::nullopt);
  EXPECT_EQ(channel_name(ChannelType::kYposition), "Yposition");
}

}  // namespace
}  // namespace gmr
