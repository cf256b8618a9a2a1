#include "gmr/demo/demo_library.h"

#include <gtest/gtest.h>

#include "gmr/kinematics/forward_kinematics.h"

namespace gmr {
namespace {

TEST(DemoLibrary, SkeletonHasIndependentMultiChildJoints) {
  const Skeleton s = demo_skeleton();
  // pelvis and chest each carry three children: the case post-rotation formats
  // can only express with dummy joints.
  EXPECT_EQ(s.children(s.find("pelvis")).size(), 3u);
  EXPECT_EQ(s.children(s.find("chest")).size(), 3u);
  EXPECT_EQ(s.roots(), std::vector<int>{0});
}

TEST(DemoLibrary, MotionsAreValidAndPlausible) {
  const auto library = demo_library();
  ASSERT_GE(library.size(), 3u);
  for (const NamedMotion& m : library) {
    SCOPED_TRACE(m.name);
    ASSERT_TRUE(m.motion.validate().ok());
    EXPECT_EQ(m.motion.convention, Convention::kPreRotation);
    EXPECT_GT(m.motion.frame_count, 100u);
    EXPECT_GT(m.motion.frame_time, 0.0);
    const auto p = compute_positions(m.motion);
    const std::size_t n = m.motion.skeleton.size();
    const int head_top = m.motion.skeleton.find("head_top");
    const int l_toe = m.motion.skeleton.find("l_toe");
    for (std::size_t f = 0; f < m.motion.frame_count; ++f) {
      // The feet stay near or above the ground, the head well above it.
      EXPECT_GT(p[f * n + l_toe].y(), -15.0) << "frame " << f;
      EXPECT_GT(p[f * n + head_top].y(), 100.0) << "frame " << f;
    }
    // The motion actually moves: some joint travels more than 10 cm.
    double travel = 0.0;
    for (std::size_t i = 0; i < p.size(); ++i) travel = std::max(travel, (p[i] - p[i % n]).norm());
    EXPECT_GT(travel, 10.0);
  }
}

TEST(DemoLibrary, Deterministic) {
  const auto a = demo_library(), b = demo_library();
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i].motion.values, b[i].motion.values);
}

}  // namespace
}  // namespace gmr
