#include "gmr/ops/convert.h"

#include <gtest/gtest.h>

#include "gmr/kinematics/forward_kinematics.h"
#include "ops_test_util.h"

namespace gmr {
namespace {

using test::position_error;
using test::random_motion;
using test::RandomMotionOptions;

TEST(ToPreRotation, KeepsPositionsOfRandomForests) {
  for (std::uint32_t seed = 1; seed <= 40; ++seed) {
    RandomMotionOptions o;
    o.roots = 1 + static_cast<int>(seed % 3);
    const Motion post = random_motion(seed, o);
    const Motion pre = to_pre_rotation(post).value();
    EXPECT_EQ(pre.convention, Convention::kPreRotation);
    EXPECT_LE(position_error(post, pre), 1e-12 * skeleton_size(post)) << "seed " << seed;
    // Roots carry no rotation; every other joint copies its parent's channels.
    for (int j = 0; j < static_cast<int>(pre.skeleton.size()); ++j) {
      const Joint& joint = pre.skeleton.joint(j);
      if (joint.parent == kNoParent) {
        EXPECT_FALSE(joint.has_rotation());
      } else {
        for (std::size_t f = 0; f < pre.frame_count; ++f) {
          EXPECT_EQ(pre.local_rotation(f, j), post.local_rotation(f, joint.parent));  // exact copy
        }
      }
    }
  }
}

TEST(ToPostRotation, RoundTripGivesSameStructureAndPositions) {
  for (std::uint32_t seed = 1; seed <= 40; ++seed) {
    RandomMotionOptions o;
    o.roots = 1 + static_cast<int>(seed % 2);
    const Motion post = random_motion(seed, o);
    const Motion back = to_post_rotation(to_pre_rotation(post).value()).value();
    ASSERT_EQ(back.skeleton.size(), post.skeleton.size()) << "no joint may be inserted, seed " << seed;
    for (int j = 0; j < static_cast<int>(post.skeleton.size()); ++j) {
      EXPECT_EQ(back.skeleton.joint(j).name, post.skeleton.joint(j).name);
      EXPECT_EQ(back.skeleton.joint(j).parent, post.skeleton.joint(j).parent);
      EXPECT_EQ(back.skeleton.joint(j).offset, post.skeleton.joint(j).offset);
      // Joints with children get their own rotation back, exactly.
      if (!post.skeleton.children(j).empty()) {
        for (std::size_t f = 0; f < post.frame_count; ++f) {
          EXPECT_EQ(back.local_rotation(f, j), post.local_rotation(f, j));
        }
      }
    }
    EXPECT_LE(position_error(post, back), 1e-12 * skeleton_size(post)) << "seed " << seed;
  }
}

TEST(ToPostRotation, InsertsZeroLengthJointsWhereChildrenRotateIndependently) {
  for (std::uint32_t seed = 1; seed <= 40; ++seed) {
    RandomMotionOptions o;
    o.convention = Convention::kPreRotation;  // children rotate independently
    o.roots = 1 + static_cast<int>(seed % 3);
    const Motion pre = random_motion(seed, o);
    const Motion post = to_post_rotation(pre).value();
    EXPECT_EQ(post.convention, Convention::kPostRotation);
    EXPECT_LE(position_error(pre, post), 1e-12 * skeleton_size(pre)) << "seed " << seed;
    // Every original joint keeps its name; inserted ones are zero-length, named *_gmr_pre*.
    for (const Joint& j : pre.skeleton.joints()) EXPECT_GE(post.skeleton.find(j.name), 0);
    for (const Joint& j : post.skeleton.joints()) {
      if (pre.skeleton.find(j.name) >= 0) continue;
      EXPECT_NE(j.name.find("_gmr_pre"), std::string::npos);
      EXPECT_EQ(j.offset, Eigen::Vector3d::Zero());
      EXPECT_FALSE(j.has_translation());
    }
    // And back to GMR: positions again.
    const Motion again = to_pre_rotation(post).value();
    EXPECT_LE(position_error(pre, again), 1e-12 * skeleton_size(pre)) << "seed " << seed;
  }
}

TEST(ToPostRotation, InsertedNamesAreUnique) {
  // Root r with children a (rotates) and b (rotates differently), and a joint
  // already named a_gmr_pre.
  std::vector<Joint> joints(4);
  joints[0].name = "r";
  joints[1].name = "a";
  joints[1].parent = 0;
  joints[1].offset = {1, 0, 0};
  joints[1].channels = {ChannelType::kZrotation};
  joints[2].name = "b";
  joints[2].parent = 0;
  joints[2].offset = {0, 1, 0};
  joints[2].channels = {ChannelType::kXrotation};
  joints[3].name = "a_gmr_pre";
  joints[3].parent = 1;
  joints[3].offset = {0, 0, 1};
  Motion pre;
  pre.skeleton = Skeleton::create(joints).value();
  pre.frame_count = 1;
  pre.values = {30.0, 40.0};
  const Motion post = to_post_rotation(pre).value();
  ASSERT_EQ(post.skeleton.size(), 6u);
  EXPECT_GE(post.skeleton.find("a_gmr_pre2"), 0);
  EXPECT_GE(post.skeleton.find("b_gmr_pre"), 0);
  EXPECT_LE(position_error(pre, post), 1e-14);
}

TEST(Convert, SameConventionIsUnchanged) {
  const Motion post = random_motion(7);
  const Motion same = to_post_rotation(post).value();
  EXPECT_EQ(same.values, post.values);
  RandomMotionOptions o;
  o.convention = Convention::kPreRotation;
  const Motion pre = random_motion(7, o);
  EXPECT_EQ(to_pre_rotation(pre).value().values, pre.values);
}

TEST(Convert, EmptyAndSingleJoint) {
  Motion empty;
  empty.convention = Convention::kPostRotation;
  const Motion e = to_pre_rotation(empty).value();
  EXPECT_TRUE(e.skeleton.empty());
  EXPECT_TRUE(to_post_rotation(e).value().skeleton.empty());

  RandomMotionOptions o;
  o.joints = 1;
  const Motion one = random_motion(3, o);
  const Motion pre = to_pre_rotation(one).value();
  EXPECT_LE(position_error(one, pre), 1e-12);
  const Motion back = to_post_rotation(pre).value();
  EXPECT_EQ(back.skeleton.size(), 1u);
  EXPECT_LE(position_error(one, back), 1e-12);

  RandomMotionOptions z;
  z.frames = 0;
  const Motion none = random_motion(4, z);
  const Motion pre0 = to_pre_rotation(none).value();
  EXPECT_EQ(pre0.frame_count, 0u);
  EXPECT_EQ(to_post_rotation(pre0).value().skeleton.size(), none.skeleton.size());
}

TEST(Convert, RejectsInvalidMotion) {
  Motion m = random_motion(5);
  m.values.pop_back();
  EXPECT_FALSE(to_pre_rotation(m).ok());
  m = random_motion(5);
  m.values[0] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(to_pre_rotation(m).ok());
}

}  // namespace
}  // namespace gmr
