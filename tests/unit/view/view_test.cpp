#include "gmr/view/view.h"

#include <gtest/gtest.h>

#include "gmr/ops/convert.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "ops_test_util.h"

namespace gmr {
namespace {

using test::random_motion;
using test::RandomMotionOptions;

Motion source() {
  RandomMotionOptions o;
  o.joints = 10;
  o.zero_offset_chance = 0.3;
  return random_motion(21, o);  // post-rotation, like a BVH
}

TEST(View, DefaultIsTheSourceInWorldCoordinates) {
  const Motion src = source();
  const MotionView v = apply_view(src, ViewSpec{}).value();
  EXPECT_EQ(v.viewer, -1);
  ASSERT_EQ(v.order.size(), src.skeleton.size());
  const auto p = view_positions(v, 0, src.frame_count);
  const auto expected = compute_positions(src);
  EXPECT_POSITIONS_NEAR(src.skeleton, p, expected, 1e-12 * skeleton_size(src));
  const Skeleton names = view_names(v);
  for (std::size_t j = 0; j < names.size(); ++j)
    EXPECT_EQ(names.joint(static_cast<int>(j)).name, src.skeleton.joint(static_cast<int>(j)).name);
}

TEST(View, RootsAndStripKeepRowsInSourceOrder) {
  const Motion src = source();
  ViewSpec spec;
  spec.roots = {"j4", "j0", "j7"};
  spec.strip_dummies = true;
  const MotionView v = apply_view(src, spec).value();
  EXPECT_TRUE(v.motion.skeleton.is_root(v.motion.skeleton.find("j4")));
  EXPECT_EQ(v.order.size() + v.removed.size(), src.skeleton.size());
  const Skeleton names = view_names(v);
  const auto p = view_positions(v, 1, 4);
  ASSERT_EQ(p.size(), 3 * names.size());
  const auto world = compute_positions(src, 1, 4);
  const std::size_t n = src.skeleton.size(), k = names.size();
  int prev = -1;
  for (std::size_t i = 0; i < k; ++i) {
    const int j = src.skeleton.find(names.joint(static_cast<int>(i)).name);
    EXPECT_GT(j, prev) << "rows follow the source's joint order";
    prev = j;
    for (std::size_t f = 0; f < 3; ++f) {
      EXPECT_LE((p[f * k + i] - world[f * n + static_cast<std::size_t>(j)]).norm(), 1e-9 * skeleton_size(src));
    }
  }
}

TEST(View, RelativeToGivesTheJointsFrame) {
  const Motion src = source();
  ViewSpec spec;
  spec.relative_to = "j3";
  const MotionView v = apply_view(src, spec).value();
  const auto p = view_positions(v, 0, src.frame_count);
  const std::size_t k = v.order.size();
  for (std::size_t f = 0; f < src.frame_count; ++f) EXPECT_LE(p[f * k + 3].norm(), 1e-12);
}

TEST(View, Errors) {
  const Motion src = source();
  ViewSpec spec;
  spec.roots = {"j0", "nobody"};
  auto r = apply_view(src, spec);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().message, "unknown joint 'nobody'");
  spec = ViewSpec{};
  spec.relative_to = "ghost";
  r = apply_view(src, spec);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().message, "unknown joint 'ghost'");
  spec.roots = {"j1", "j1"};
  spec.relative_to.clear();
  EXPECT_FALSE(apply_view(src, spec).ok());
}

TEST(View, RelativeToRemovedDummyIsNamed) {
  // Root -> Dummy (zero offset) -> Child: Root and Dummy are one place, kept
  // under Dummy's name (two bones against Root's one).
  std::vector<Joint> j(3);
  j[0].name = "Root";
  j[0].channels = {ChannelType::kZrotation};
  j[1].name = "Dummy";
  j[1].parent = 0;
  j[1].channels = {ChannelType::kXrotation};
  j[2].name = "Child";
  j[2].parent = 1;
  j[2].offset = {1, 0, 0};
  Motion m;
  m.skeleton = Skeleton::create(j).value();
  m.convention = Convention::kPostRotation;
  m.frame_count = 1;
  m.values = {10, 20};
  ViewSpec spec;
  spec.strip_dummies = true;
  spec.relative_to = "Root";
  auto r = apply_view(m, spec);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("merged into 'Dummy' by strip-dummies"), std::string::npos) << r.error().message;
  spec.relative_to = "Dummy";
  EXPECT_TRUE(apply_view(m, spec).ok());
}

}  // namespace
}  // namespace gmr
