#include "gmr/ops/join_tree.h"
#include "gmr/ops/set_roots.h"
#include "gmr/ops/shift_root.h"
#include "gmr/ops/split_tree.h"
#include "gmr/ops/strip_dummies.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include "gmr/ops/convert.h"
#include "kinematics/fk_stats.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "ops_test_util.h"

namespace gmr {
namespace {

using test::position_error;
using test::random_motion;
using test::RandomMotionOptions;
using test::same_local_data;

Motion random_pre(std::uint32_t seed, int roots = 1, int joints = 12, std::size_t frames = 5) {
  RandomMotionOptions o;
  o.roots = roots;
  o.joints = joints;
  o.frames = frames;
  return to_pre_rotation(random_motion(seed, o)).value();
}

int index_of(const Motion& m, const std::string& name) { return m.skeleton.find(name); }

// Parents come before children and names are unique (Skeleton::create checks both).
void expect_valid(const Motion& m) {
  EXPECT_TRUE(Skeleton::create(m.skeleton.joints()).ok());
  EXPECT_TRUE(m.validate().ok());
  EXPECT_EQ(m.convention, Convention::kPreRotation);
}

TEST(ShiftRoot, ToEveryJointKeepsPositions) {
  for (std::uint32_t seed = 1; seed <= 10; ++seed) {
    const Motion m = random_pre(seed, 1 + static_cast<int>(seed % 2));
    const double tol = 1e-11 * skeleton_size(m);
    for (int j = 0; j < static_cast<int>(m.skeleton.size()); ++j) {
      const Motion s = shift_root(m, j).value();
      expect_valid(s);
      const int k = index_of(s, m.skeleton.joint(j).name);
      EXPECT_TRUE(s.skeleton.is_root(k));
      EXPECT_EQ(s.skeleton.roots().size(), m.skeleton.roots().size());
      EXPECT_LE(position_error(m, s), tol) << "seed " << seed << " joint " << j;
    }
  }
}

TEST(ShiftRoot, StaticOffsetsStayStatic) {
  const Motion m = random_pre(3, 1, 15);
  for (int j = 0; j < static_cast<int>(m.skeleton.size()); ++j) {
    const Motion s = shift_root(m, j).value();
    for (const Joint& joint : s.skeleton.joints()) {
      if (joint.parent == kNoParent) continue;
      const Joint& before = m.skeleton.joint(index_of(m, joint.name));
      // A non-root has translation channels only if a joint of the path had them.
      if (joint.has_translation()) {
        bool source = before.has_translation();
        for (const Joint& other : m.skeleton.joints())
          source = source || (other.parent != kNoParent && other.has_translation());
        EXPECT_TRUE(source) << joint.name;
      }
    }
  }
}

TEST(ShiftRoot, ThereAndBackRestoresLocalData) {
  for (std::uint32_t seed = 1; seed <= 10; ++seed) {
    const Motion m = random_pre(seed);
    const int root = m.skeleton.roots()[0];
    for (int j = 0; j < static_cast<int>(m.skeleton.size()); ++j) {
      const Motion there = shift_root(m, j).value();
      const Motion back = shift_root(there, index_of(there, m.skeleton.joint(root).name)).value();
      EXPECT_TRUE(same_local_data(m, back, 1e-12, 1e-12 * skeleton_size(m))) << "seed " << seed << " joint " << j;
    }
  }
}

TEST(ShiftRoot, PlainCopiesAreExact) {
  // J0 (root) -> J1: R1' = R0 and R0' = R1 are channel copies.
  const Motion m = random_pre(11, 1, 6);
  const int j1 = m.skeleton.children(0)[0];
  const Motion s = shift_root(m, j1).value();
  const int n0 = index_of(s, m.skeleton.joint(0).name), n1 = index_of(s, m.skeleton.joint(j1).name);
  for (std::size_t f = 0; f < m.frame_count; ++f) {
    EXPECT_EQ(s.local_rotation(f, n1), m.local_rotation(f, 0));
    EXPECT_EQ(s.local_rotation(f, n0), m.local_rotation(f, j1));
    EXPECT_EQ(s.local_offset(f, n0), Eigen::Vector3d(-m.local_offset(f, j1)));
  }
}

TEST(SplitJoin, RestoresLocalDataAndReportsRigidOffset) {
  for (std::uint32_t seed = 1; seed <= 10; ++seed) {
    const Motion m = random_pre(seed, 2);
    for (int j = 0; j < static_cast<int>(m.skeleton.size()); ++j) {
      if (m.skeleton.is_root(j)) continue;
      const Motion split = split_tree(m, j).value();
      expect_valid(split);
      const int k = index_of(split, m.skeleton.joint(j).name);
      ASSERT_TRUE(split.skeleton.is_root(k));
      EXPECT_EQ(split.skeleton.joint(split.skeleton.joint(k).soft_parent).name,
                m.skeleton.joint(m.skeleton.joint(j).parent).name);
      EXPECT_LE(position_error(m, split), 1e-11 * skeleton_size(m));
      JoinReport report;
      const Motion joined = join_tree(split, k, &report).value();
      // Rigid unless the joint had per-frame position channels of its own.
      const bool moves = m.skeleton.joint(j).has_translation();
      EXPECT_EQ(report.translation_channels, moves);
      if (!moves) {
        EXPECT_LE(report.offset_spread, 1e-9 * skeleton_size(m));
      }
      EXPECT_TRUE(same_local_data(m, joined, 1e-12, 1e-12 * skeleton_size(m))) << "seed " << seed << " joint " << j;
    }
  }
}

TEST(Join, MovedRootKeepsPositionsWithTranslationChannels) {
  const Motion m = random_pre(5, 1, 8, 6);
  const int j = 3;
  Motion split = split_tree(m, j).value();
  const int k = index_of(split, m.skeleton.joint(j).name);
  // Move the split root on its own in frame 2 (an edit).
  split.frame(2)[static_cast<std::size_t>(split.skeleton.channel_offset(k))] += 0.5;
  JoinReport report;
  const Motion joined = join_tree(split, k, &report).value();
  EXPECT_TRUE(report.translation_channels);
  EXPECT_GT(report.offset_spread, 0.1);
  EXPECT_LE(position_error(split, joined), 1e-11 * skeleton_size(m));
  EXPECT_TRUE(joined.skeleton.joint(index_of(joined, m.skeleton.joint(j).name)).has_translation());
}

TEST(Join, Errors) {
  const Motion m = random_pre(2, 2);
  // Not a root.
  const int child = m.skeleton.children(0)[0];
  auto r = join_tree(m, child);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("not a root"), std::string::npos) << r.error().message;
  // A root with no soft link.
  r = join_tree(m, 0);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("no soft link"), std::string::npos) << r.error().message;
  // The last root.
  const Motion one = random_pre(2, 1);
  r = join_tree(one, 0);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("last root"), std::string::npos) << r.error().message;
  // A soft link into its own tree (hand-made file).
  Motion own = m;
  std::vector<Joint> js = m.skeleton.joints();
  js[0].soft_parent = m.skeleton.children(0)[0];
  own.skeleton = Skeleton::create(js).value();
  r = join_tree(own, 0);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("own tree"), std::string::npos) << r.error().message;
  // Out of range and post-rotation.
  EXPECT_FALSE(join_tree(m, -1).ok());
  EXPECT_FALSE(join_tree(m, 1000).ok());
  EXPECT_FALSE(join_tree(random_motion(2), 0).ok());
}

TEST(Split, Errors) {
  const Motion m = random_pre(2);
  auto r = split_tree(m, 0);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("already a root"), std::string::npos);
  EXPECT_FALSE(split_tree(m, 99).ok());
  EXPECT_FALSE(split_tree(random_motion(2), 1).ok());
  EXPECT_FALSE(shift_root(m, -3).ok());
  EXPECT_FALSE(shift_root(random_motion(2), 1).ok());
}

TEST(SetRoots, RandomSetsKeepPositions) {
  std::mt19937 rng(42);
  for (std::uint32_t seed = 1; seed <= 12; ++seed) {
    const int trees = 1 + static_cast<int>(seed % 3);
    const Motion m = random_pre(seed, trees, 14);
    const double tol = 1e-9 * skeleton_size(m);
    Motion cur = m;
    for (int step = 0; step < 4; ++step) {
      // A random set with at least one joint per tree of the original.
      std::vector<int> set;
      for (int t = 0; t < trees; ++t) set.push_back(t);  // the original roots' trees: pick a joint in each
      for (int& r : set) {
        std::vector<int> in_tree;
        for (int j = 0; j < static_cast<int>(m.skeleton.size()); ++j) {
          if (m.skeleton.root_of(j) == m.skeleton.roots()[static_cast<std::size_t>(r)]) in_tree.push_back(j);
        }
        r = in_tree[std::uniform_int_distribution<std::size_t>(0, in_tree.size() - 1)(rng)];
      }
      // Even steps keep the original roots in the set (then the result is path
      // independent in local data too); odd steps may move them.
      if (step % 2 == 0) set = std::vector<int>(m.skeleton.roots().begin(), m.skeleton.roots().end());
      for (int j = 0; j < static_cast<int>(m.skeleton.size()); ++j) {
        if (std::find(set.begin(), set.end(), j) == set.end() && rng() % 3 == 0) set.push_back(j);
      }
      std::vector<std::string> names;
      std::vector<int> idx;
      for (int j : set) names.push_back(m.skeleton.joint(j).name);
      for (const auto& n : names) idx.push_back(index_of(cur, n));
      cur = set_roots(cur, idx).value();
      expect_valid(cur);
      ASSERT_EQ(cur.skeleton.roots().size(), set.size());
      for (const auto& n : names) EXPECT_TRUE(cur.skeleton.is_root(index_of(cur, n))) << n;
      EXPECT_LE(position_error(m, cur), tol) << "seed " << seed << " step " << step;
      // Path independence: from any configuration whose trees have the
      // original roots, the result equals going straight from the original.
      std::vector<int> direct_idx;
      for (const auto& n : names) direct_idx.push_back(index_of(m, n));
      const Motion direct = set_roots(m, direct_idx).value();
      EXPECT_TRUE(same_local_data(direct, cur, 1e-9, 1e-9 * skeleton_size(m))) << "seed " << seed << " step " << step;
      if (step % 2 == 1) {
        // This set may have moved a tree's root: going back to the original
        // roots restores the original local data (and the next step starts there).
        std::vector<int> orig;
        for (int r : m.skeleton.roots()) orig.push_back(index_of(cur, m.skeleton.joint(r).name));
        cur = set_roots(cur, orig).value();
        EXPECT_TRUE(same_local_data(m, cur, 1e-9, 1e-9 * skeleton_size(m))) << "seed " << seed << " step " << step;
      }
    }
    // Back to the original roots restores the original local data.
    std::vector<int> orig;
    for (int r : m.skeleton.roots()) orig.push_back(index_of(cur, m.skeleton.joint(r).name));
    const Motion back = set_roots(cur, orig).value();
    EXPECT_TRUE(same_local_data(m, back, 1e-9, 1e-9 * skeleton_size(m))) << "seed " << seed;
  }
}

TEST(SetRoots, AllJointsAreRootsAndPositionsAreRead) {
  const Motion m = random_pre(9, 2, 20, 7);
  std::vector<int> all(m.skeleton.size());
  std::iota(all.begin(), all.end(), 0);
  const Motion t = set_roots(m, all).value();
  ASSERT_EQ(t.skeleton.roots().size(), m.skeleton.size());
  for (const Joint& j : t.skeleton.joints()) EXPECT_EQ(j.parent, kNoParent);
  reset_fk_rotation_evaluations();
  const auto p = compute_positions(t);
  EXPECT_EQ(fk_rotation_evaluations(), 0u) << "the fully translational configuration must do no rotation math";
  EXPECT_LE(test::compare_positions(p, test::positions_by_name(m, t.skeleton), t.skeleton.size()).max_error,
            1e-9 * skeleton_size(m));
  // The original configuration does rotation work (the counter counts).
  reset_fk_rotation_evaluations();
  (void)compute_positions(m);
  EXPECT_GT(fk_rotation_evaluations(), 0u);
  // And back to one root per tree.
  std::vector<int> roots;
  for (int r : m.skeleton.roots()) roots.push_back(index_of(t, m.skeleton.joint(r).name));
  EXPECT_TRUE(same_local_data(m, set_roots(t, roots).value(), 1e-9, 1e-9 * skeleton_size(m)));
}

TEST(SetRoots, Errors) {
  const Motion m = random_pre(4, 2);
  auto r = set_roots(m, std::vector<int>{});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("empty"), std::string::npos);
  // Only joints of the first tree: the second has no root.
  std::vector<int> first;
  for (int j = 0; j < static_cast<int>(m.skeleton.size()); ++j) {
    if (m.skeleton.root_of(j) == 0) first.push_back(j);
  }
  r = set_roots(m, first);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("no root given"), std::string::npos) << r.error().message;
  r = set_roots(m, std::vector<int>{0, 1, 0});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("twice"), std::string::npos);
  EXPECT_FALSE(set_roots(m, std::vector<int>{0, 77}).ok());
  EXPECT_FALSE(set_roots(random_motion(4), std::vector<int>{0}).ok());
  // A split tree is connected to its parent by the soft link: one root per
  // original tree suffices.
  const Motion split = split_tree(m, m.skeleton.children(0)[0]).value();
  ASSERT_EQ(split.skeleton.roots().size(), 3u);
  std::vector<int> two{index_of(split, "j0"), index_of(split, "j1")};
  EXPECT_EQ(set_roots(split, two).value().skeleton.roots().size(), 2u);
  // Soft links that form a cycle (hand-made): tree A linked into B and B into A.
  std::vector<Joint> js = m.skeleton.joints();
  js[0].soft_parent = m.skeleton.children(1).empty() ? 1 : m.skeleton.children(1)[0];
  js[1].soft_parent = m.skeleton.children(0)[0];
  Motion cyc = m;
  cyc.skeleton = Skeleton::create(js).value();
  r = set_roots(cyc, std::vector<int>{0});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("cycle"), std::string::npos) << r.error().message;
}

TEST(SetRoots, EmptyAndSingleJoint) {
  Motion empty;
  EXPECT_FALSE(set_roots(empty, std::vector<int>{}).ok());
  EXPECT_TRUE(strip_dummies(empty).ok());
  EXPECT_TRUE(constant_rotation_joints(empty).empty());
  const Motion one = random_pre(8, 1, 1);
  const Motion same = set_roots(one, std::vector<int>{0}).value();
  EXPECT_TRUE(same_local_data(one, same, 0.0, 0.0));
  EXPECT_TRUE(shift_root(one, 0).ok());
  EXPECT_FALSE(split_tree(one, 0).ok());
  EXPECT_FALSE(join_tree(one, 0).ok());
}

TEST(Operations, ZeroFramesKeepStructure) {
  const Motion m = random_pre(6, 1, 10, 0);
  std::vector<int> all(m.skeleton.size());
  std::iota(all.begin(), all.end(), 0);
  const Motion t = set_roots(m, all).value();
  EXPECT_EQ(t.frame_count, 0u);
  EXPECT_EQ(t.skeleton.roots().size(), m.skeleton.size());
  EXPECT_TRUE(shift_root(m, 5).ok());
  EXPECT_TRUE(strip_dummies(m).ok());
}

TEST(Operations, LargeAndDeepSkeletons) {
  // A 2000-joint chain (no recursion anywhere) and a 600-joint random tree.
  std::vector<Joint> chain(2000);
  for (std::size_t j = 0; j < chain.size(); ++j) {
    chain[j].name = std::to_string(j);
    chain[j].name.insert(0, 1, 'c');
    chain[j].parent = static_cast<int>(j) - 1;
    chain[j].offset = {0.01, 0.0, 0.0};
    chain[j].channels = {ChannelType::kZrotation, ChannelType::kXrotation};
  }
  Motion m;
  m.skeleton = Skeleton::create(chain).value();
  m.convention = Convention::kPreRotation;
  m.frame_count = 2;
  m.values.resize(2 * m.stride());
  for (std::size_t i = 0; i < m.values.size(); ++i) m.values[i] = std::sin(static_cast<double>(i)) * 3.0;
  const double tol = 1e-9 * skeleton_size(m);
  const Motion s = shift_root(m, 1999).value();
  EXPECT_TRUE(s.skeleton.is_root(s.skeleton.find("c1999")));
  EXPECT_LE(position_error(m, s), tol);
  std::vector<int> every_other;
  for (int j = 0; j < 2000; j += 2) every_other.push_back(j);
  EXPECT_LE(position_error(m, set_roots(m, every_other).value()), tol);

  const Motion big = random_pre(13, 3, 600, 3);
  std::vector<int> all(big.skeleton.size());
  std::iota(all.begin(), all.end(), 0);
  const Motion t = set_roots(big, all).value();
  EXPECT_EQ(t.skeleton.roots().size(), 600u);
  EXPECT_LE(position_error(big, t), 1e-9 * skeleton_size(big));
}

// Hips -> Dummy (zero offset) -> {Leg, Spine}; Leg -> Foot.
Motion with_dummy() {
  std::vector<Joint> j(5);
  j[0].name = "Hips";
  j[0].channels = {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition,
                   ChannelType::kZrotation, ChannelType::kYrotation, ChannelType::kXrotation};
  j[1].name = "Dummy";
  j[1].parent = 0;
  j[1].channels = {ChannelType::kZrotation, ChannelType::kYrotation, ChannelType::kXrotation};
  j[2].name = "Leg";
  j[2].parent = 1;
  j[2].offset = {0, -4, 0};
  j[2].channels = {ChannelType::kZrotation, ChannelType::kXrotation};
  j[3].name = "Spine";
  j[3].parent = 1;
  j[3].offset = {0, 3, 0};
  j[4].name = "Foot";
  j[4].parent = 2;
  j[4].offset = {0, -4, 0};
  j[4].channels = {ChannelType::kXrotation};
  Motion m;
  m.skeleton = Skeleton::create(j).value();
  m.convention = Convention::kPostRotation;
  m.frame_count = 3;
  m.values = {1,  2, 3, 10, 20, 30, 5,  6,  7,  40, 50, 60,  //
              0,  0, 0, 0,  0,  0,  0,  0,  0,  0,  0,  0,   //
              -1, 2, 9, 15, 25, 35, -5, 16, 17, 4,  5,  70};
  return m;
}

TEST(StripDummies, RemovesZeroLengthJointsExactly) {
  // Hips (one bone) and Dummy (three: Hips, Leg, Spine) are one place: the
  // joint with more bones keeps its name.
  const Motion pre = to_pre_rotation(with_dummy()).value();
  std::vector<RemovedJoint> removed;
  const Motion s = strip_dummies(pre, &removed).value();
  expect_valid(s);
  ASSERT_EQ(removed.size(), 1u);
  EXPECT_EQ(removed[0].name, "Hips");
  EXPECT_EQ(removed[0].merged_into, "Dummy");
  EXPECT_EQ(s.skeleton.find("Hips"), -1);
  EXPECT_EQ(s.skeleton.size(), pre.skeleton.size() - 1);
  EXPECT_EQ(s.skeleton.joint(s.skeleton.find("Leg")).parent, s.skeleton.find("Dummy"));
  EXPECT_EQ(s.skeleton.joint(s.skeleton.find("Dummy")).parent, kNoParent);
  EXPECT_LE(position_error(s, pre), 1e-12 * skeleton_size(pre));
  // Stripping again finds nothing.
  std::vector<RemovedJoint> again;
  EXPECT_EQ(strip_dummies(s, &again).value().skeleton.size(), s.skeleton.size());
  EXPECT_TRUE(again.empty());
  // Post-rotation input is refused.
  EXPECT_FALSE(strip_dummies(with_dummy()).ok());
}

TEST(StripDummies, RandomForestsKeepPositions) {
  for (std::uint32_t seed = 1; seed <= 20; ++seed) {
    RandomMotionOptions o;
    o.zero_offset_chance = 0.4;
    o.roots = 1 + static_cast<int>(seed % 2);
    const Motion pre = to_pre_rotation(random_motion(seed, o)).value();
    std::vector<RemovedJoint> removed;
    const Motion s = strip_dummies(pre, &removed).value();
    expect_valid(s);
    EXPECT_EQ(s.skeleton.size() + removed.size(), pre.skeleton.size());
    // Each removed joint stood where the joint it was merged into stands.
    const auto all = test::positions_by_name(pre, pre.skeleton);
    const std::size_t n = pre.skeleton.size();
    for (const auto& r : removed) {
      const int d = pre.skeleton.find(r.name), k = pre.skeleton.find(r.merged_into);
      ASSERT_GE(d, 0);
      ASSERT_GE(k, 0);
      EXPECT_GE(s.skeleton.find(r.merged_into), 0);
      for (std::size_t f = 0; f < pre.frame_count; ++f) EXPECT_EQ(all[f * n + d], all[f * n + k]) << r.name;
    }
    // Positions of the kept joints are unchanged.
    EXPECT_LE(position_error(s, pre), 1e-12 * skeleton_size(pre)) << "seed " << seed;
  }
}

TEST(ConstantRotationJoints, ReportsJointsThatNeverRotate) {
  const Motion post = with_dummy();  // Spine has no channels; Dummy rotates
  auto c = constant_rotation_joints(post);
  EXPECT_TRUE(c.empty());
  Motion still = post;
  for (std::size_t f = 0; f < still.frame_count; ++f) {
    auto v = still.frame(f);
    v[9] = 1.0, v[10] = 2.0, v[11] = 3.0;  // Leg's two channels and Foot's one: constant
  }
  c = constant_rotation_joints(still);
  EXPECT_EQ(c, (std::vector<std::string>{"Leg", "Foot"}));
}

TEST(FindJoints, NamesUnknownJoint) {
  const Motion m = random_pre(1);
  const std::vector<std::string> names{"j0", "nope"};
  auto r = find_joints(m.skeleton, names);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().message, "unknown joint 'nope'");
  EXPECT_EQ(r.error().kind, ErrorKind::kNotFound);
}

}  // namespace
}  // namespace gmr
