#include "gmr/ops/convert.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include "gmr/io/motion_file.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "ops_test_util.h"
#include "test_data.h"

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
  // Root r with children a (rotates, the larger subtree: it rides on r) and b
  // (rotates differently: it gets an inserted joint), and a joint already
  // named b_gmr_pre.
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
  joints[3].name = "b_gmr_pre";
  joints[3].parent = 1;
  joints[3].offset = {0, 0, 1};
  Motion pre;
  pre.skeleton = Skeleton::create(joints).value();
  pre.frame_count = 1;
  pre.values = {30.0, 40.0};
  const Motion post = to_post_rotation(pre).value();
  ASSERT_EQ(post.skeleton.size(), 5u);
  EXPECT_GE(post.skeleton.find("b_gmr_pre2"), 0);
  EXPECT_LE(position_error(pre, post), 1e-14);
}

// A joint with three children that each rotate their own way needs two
// inserted joints, not three; children whose channels hold only whole turns
// rotate like children without channels and need none.
TEST(ToPostRotation, InsertsTheFewestJoints) {
  using C = ChannelType;
  auto joint = [](std::string name, int parent, Eigen::Vector3d off, std::vector<ChannelType> ch) {
    Joint j;
    j.name = std::move(name);
    j.parent = parent;
    j.offset = off;
    j.channels = std::move(ch);
    return j;
  };
  // r -> x -> {a, b, c} rotating; x -> {z1 (no channels), z2 (Xrotation 0 or 360)}.
  const std::vector<Joint> rotating = {
      joint("r", -1, {0, 0, 0}, {C::kXposition, C::kYposition, C::kZposition}),
      joint("x", 0, {0, 1, 0}, {C::kZrotation, C::kXrotation, C::kYrotation}),
      joint("a", 1, {1, 0, 0}, {C::kZrotation}),
      joint("b", 1, {0, 1, 0}, {C::kXrotation, C::kYrotation}),
      joint("c", 1, {0, 0, 1}, {C::kYrotation, C::kZrotation, C::kXrotation}),
      joint("a1", 2, {1, 0, 0}, {}),
  };
  Motion pre;
  pre.skeleton = Skeleton::create(rotating).value();
  pre.frame_count = 3;
  for (int f = 0; f < 3; ++f)
    for (int c = 0; c < pre.skeleton.channel_count(); ++c) pre.values.push_back(7.0 * f + 11.0 * c - 20.0);
  const Motion post = to_post_rotation(pre).value();
  EXPECT_EQ(post.skeleton.size(), pre.skeleton.size() + 2);
  EXPECT_LT(post.skeleton.find("a_gmr_pre"), 0) << "a has the largest subtree: it rides on x";
  EXPECT_GE(post.skeleton.find("b_gmr_pre"), 0);
  EXPECT_GE(post.skeleton.find("c_gmr_pre"), 0);
  EXPECT_LE(position_error(pre, post), 1e-12 * skeleton_size(pre));
  EXPECT_LE(position_error(pre, to_pre_rotation(post).value()), 1e-12 * skeleton_size(pre));

  const std::vector<Joint> still = {
      joint("r", -1, {0, 0, 0}, {C::kXposition, C::kYposition, C::kZposition}),
      joint("x", 0, {0, 1, 0}, {C::kZrotation}),
      joint("z1", 1, {1, 0, 0}, {}),
      joint("z2", 1, {0, 1, 0}, {C::kXrotation}),
  };
  Motion quiet;
  quiet.skeleton = Skeleton::create(still).value();
  quiet.frame_count = 2;
  quiet.values = {1, 2, 3, 25, 0, 4, 5, 6, 35, 360};
  const Motion qpost = to_post_rotation(quiet).value();
  EXPECT_EQ(qpost.skeleton.size(), quiet.skeleton.size()) << "z1 and z2 rotate alike: no inserted joint";
  EXPECT_LE(position_error(quiet, qpost), 1e-12 * skeleton_size(quiet));
}

// What every common BVH reader reads alike: 0 or 3 distinct rotation axes,
// position channels none or all three with OFFSET 0, and the same positions.
TEST(ToBvhInterchange, ChannelLayoutsEveryReaderTakes) {
  int forests = 0;
  for (std::uint32_t seed = 1; seed <= 60; ++seed) {
    RandomMotionOptions o;
    o.roots = 1 + static_cast<int>(seed % 3);
    o.convention = seed % 2 ? Convention::kPreRotation : Convention::kPostRotation;
    o.position_channel_chance = 0.3;
    const Motion m = random_motion(seed, o);
    for (const bool single : {false, true}) {
      BvhExportOptions opt;
      opt.single_root = single;
      const Motion out = to_bvh_interchange(m, opt).value();
      EXPECT_EQ(out.convention, Convention::kPostRotation);
      EXPECT_LE(position_error(m, out), 1e-12 * skeleton_size(m)) << "seed " << seed;
      int roots = 0;
      for (const Joint& j : out.skeleton.joints()) {
        roots += j.parent == kNoParent ? 1 : 0;
        EXPECT_EQ(j.soft_parent, kNoParent);
        std::set<Axis> rot, pos;
        int nrot = 0, npos = 0;
        for (ChannelType c : j.channels) {
          (is_rotation(c) ? rot : pos).insert(axis_of(c));
          (is_rotation(c) ? nrot : npos) += 1;
        }
        EXPECT_TRUE(nrot == 0 || (nrot == 3 && rot.size() == 3)) << j.name << " seed " << seed;
        EXPECT_TRUE(npos == 0 || (npos == 3 && pos.size() == 3 && nrot == 3)) << j.name << " seed " << seed;
        if (npos != 0) {
          EXPECT_EQ(j.offset, Eigen::Vector3d::Zero()) << j.name;
        }
      }
      if (single) {
        EXPECT_EQ(roots, 1);
        if (o.roots > 1) {
          EXPECT_EQ(out.skeleton.joint(out.skeleton.roots().front()).name, "gmr_world");
          ++forests;
        }
      } else {
        EXPECT_EQ(roots, o.roots);
      }
    }
  }
  EXPECT_EQ(forests, 40);
}

// A non-root joint whose position channels never change gets them as OFFSET
// (readers that add channels to OFFSET would count them twice).
TEST(ToBvhInterchange, ConstantPositionChannelsBecomeTheOffset) {
  using C = ChannelType;
  std::vector<Joint> joints(2);
  joints[0].name = "hip";
  joints[0].offset = {9, 9, 9};
  joints[0].channels = {C::kXposition, C::kYposition, C::kZposition, C::kZrotation, C::kYrotation};
  joints[1].name = "knee";
  joints[1].parent = 0;
  joints[1].offset = {5, 5, 5};
  joints[1].channels = {C::kYposition, C::kXrotation};
  Motion m;
  m.skeleton = Skeleton::create(joints).value();
  m.convention = Convention::kPostRotation;
  m.frame_count = 2;
  m.values = {1, 2, 3, 10, 20, -4, 30, 4, 5, 6, 15, 25, -4, 40};
  const Motion out = to_bvh_interchange(m).value();
  const Joint& hip = out.skeleton.joint(out.skeleton.find("hip"));
  EXPECT_EQ(hip.offset, Eigen::Vector3d::Zero());
  EXPECT_EQ(hip.channels.size(), 6u);  // its two rotation axes padded to three
  const Joint& knee = out.skeleton.joint(out.skeleton.find("knee"));
  EXPECT_EQ(knee.offset, Eigen::Vector3d(5, -4, 5));
  EXPECT_EQ(knee.channels.size(), 3u);
  EXPECT_LE(position_error(m, out), 1e-12);
}

// World poses of random motions (positions and bone-frame orientations from
// forward kinematics) become an all-roots motion with the same poses, each
// joint soft-linked to its parent; bad sizes and links are refused.
TEST(MotionFromWorldPoses, GivesBackThePosesOfRandomMotions) {
  for (std::uint32_t seed = 1; seed <= 20; ++seed) {
    const Motion m = to_pre_rotation(random_motion(seed)).value();
    const std::size_t n = m.skeleton.size();
    std::vector<std::string> names;
    std::vector<int> soft;
    for (const Joint& j : m.skeleton.joints()) {
      names.push_back(j.name);
      soft.push_back(j.parent);
    }
    std::vector<Eigen::Vector3d> positions, p(n);
    std::vector<Eigen::Quaterniond> orientations;
    std::vector<Eigen::Matrix3d> o(n);
    for (std::size_t f = 0; f < m.frame_count; ++f) {
      compute_frame(m, f, p, o);
      positions.insert(positions.end(), p.begin(), p.end());
      for (const auto& r : o) orientations.emplace_back(r);
    }
    auto r = motion_from_world_poses(names, soft, m.frame_time, positions, orientations);
    ASSERT_TRUE(r.ok()) << r.error().to_string();
    EXPECT_EQ(r->skeleton.roots().size(), n);
    EXPECT_LE(position_error(m, *r), 1e-12 * skeleton_size(m)) << "seed " << seed;
    std::vector<Eigen::Vector3d> rp(n);
    std::vector<Eigen::Matrix3d> ro(n);
    for (std::size_t f = 0; f < m.frame_count; ++f) {
      compute_frame(m, f, p, o);
      compute_frame(*r, f, rp, ro);
      for (std::size_t j = 0; j < n; ++j) EXPECT_LT((ro[j] - o[j]).norm(), 1e-12) << "seed " << seed;
    }
    for (std::size_t j = 0; j < n; ++j) EXPECT_EQ(r->skeleton.joint(static_cast<int>(j)).soft_parent, soft[j]);
  }
  const std::vector<Eigen::Vector3d> two(2, Eigen::Vector3d::Zero());
  EXPECT_FALSE(motion_from_world_poses({"a", "b"}, {kNoParent, kNoParent}, 0.1, std::span(two).first(1), {}).ok());
  EXPECT_FALSE(motion_from_world_poses({"a", "b"}, {1, kNoParent}, 0.1, two, {}).ok());
  EXPECT_FALSE(motion_from_world_poses({"a", "a"}, {kNoParent, kNoParent}, 0.1, two, {}).ok());
  const std::vector<Eigen::Quaterniond> one(1, Eigen::Quaterniond::Identity());
  EXPECT_FALSE(motion_from_world_poses({"a", "b"}, {kNoParent, 0}, 0.1, two, one).ok());
  auto positions_only = motion_from_world_poses({"a", "b"}, {kNoParent, 0}, 0.1, two, {});
  ASSERT_TRUE(positions_only.ok());
  EXPECT_EQ(positions_only->stride(), 6u);
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

namespace gmr {
namespace {

// The gather a live view converts its frames with gives what to_pre_rotation
// gives, value for value, on real rigs and takes (first 200 frames each).
TEST(PreRotationGather, EqualsToPreRotationOnRealFiles) {
  GMR_REQUIRE_DATA();
  int files = 0;
  for (const char* relative : {"bvh/cmu/01_01.bvh", "bvh/mixamo/Beta_jump.bvh", "bvh/cmu_iclone/001_01.bvh"}) {
    SCOPED_TRACE(relative);
    auto m = load_motion(test::data_file(relative));
    ASSERT_TRUE(m.ok()) << m.error().to_string();
    m->frame_count = std::min<std::size_t>(m->frame_count, 200);
    m->values.resize(m->frame_count * m->stride());
    auto want = to_pre_rotation(*m);
    ASSERT_TRUE(want.ok());
    auto gather = PreRotationGather::make(m->skeleton);
    ASSERT_TRUE(gather.has_value());
    const Motion got = gather->apply(m->values, m->frame_count, m->frame_time);
    ASSERT_EQ(got.skeleton.size(), want->skeleton.size());
    for (int j = 0; j < static_cast<int>(got.skeleton.size()); ++j) {
      EXPECT_EQ(got.skeleton.joint(j).name, want->skeleton.joint(j).name);
      EXPECT_EQ(got.skeleton.joint(j).parent, want->skeleton.joint(j).parent);
      EXPECT_EQ(got.skeleton.joint(j).channels, want->skeleton.joint(j).channels);
      EXPECT_EQ(got.skeleton.joint(j).offset, want->skeleton.joint(j).offset);
    }
    EXPECT_EQ(got.convention, Convention::kPreRotation);
    EXPECT_EQ(got.frame_count, want->frame_count);
    EXPECT_EQ(got.values, want->values);
    ++files;
  }
  EXPECT_EQ(files, 3);
}

}  // namespace
}  // namespace gmr
