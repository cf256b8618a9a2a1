// The operations and conversions on real data: every BVH of ../shared/data/bvh, every frame.
//
// Tolerances are relative to skeleton_size(): 1e-6 for the conversions and the
// file round trip, 1e-9 for the operations.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <numeric>
#include <random>
#include <unistd.h>

#include "gmr/ops/convert.h"
#include "gmr/io/bvh.h"
#include "gmr/io/gmr_file.h"
#include "kinematics/fk_stats.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/ops/join_tree.h"
#include "gmr/ops/set_roots.h"
#include "gmr/ops/shift_root.h"
#include "gmr/ops/split_tree.h"
#include "gmr/ops/strip_dummies.h"
#include "gmr/view/engine_pose.h"
#include "gmr/view/viewpoint.h"
#include "ops_test_util.h"
#include "test_data.h"

namespace gmr {
namespace {

namespace fs = std::filesystem;
using test::positions_by_name;
using test::same_local_data;

struct Loaded {
  fs::path path;
  Motion post;
  Motion pre;
  std::vector<Eigen::Vector3d> reference;  // post-rotation positions, frame-major, post's joint order
  double size = 0.0;
};

// Loads every BVH once for the whole program (the suite reads each file once).
const std::vector<Loaded>& corpus() {
  static const std::vector<Loaded> all = [] {
    std::vector<Loaded> out;
    for (const fs::path& p : test::data_files("bvh", ".bvh")) {
      auto m = read_bvh(p);
      if (!m) {
        ADD_FAILURE() << "cannot read " << p << ": " << m.error().to_string();
        continue;
      }
      Loaded l;
      l.path = p;
      l.post = std::move(m).value();
      auto pre = to_pre_rotation(l.post);
      if (!pre) {
        ADD_FAILURE() << p << ": " << pre.error().to_string();
        continue;
      }
      l.pre = std::move(pre).value();
      l.reference = compute_positions(l.post);
      l.size = skeleton_size(l.post);
      out.push_back(std::move(l));
    }
    return out;
  }();
  return all;
}

std::string label(const Loaded& l) { return l.path.filename().string(); }

double error_vs_reference(const Loaded& l, const Motion& m) {
  const auto p = positions_by_name(m, l.post.skeleton);
  if (p.size() != l.reference.size()) return 1e300;
  return test::compare_positions(l.reference, p, l.post.skeleton.size()).max_error;
}

std::vector<int> indices_of(const Motion& m, const std::vector<std::string>& names) {
  std::vector<int> out;
  for (const auto& n : names) out.push_back(m.skeleton.find(n));
  return out;
}

TEST(BvhToGmrOnCorpus, KeepsEveryPosition) {
  GMR_REQUIRE_DATA();
  ASSERT_FALSE(corpus().empty());
  for (const Loaded& l : corpus()) {
    SCOPED_TRACE(label(l));
    EXPECT_LE(error_vs_reference(l, l.pre), 1e-6 * l.size);
    // GMR -> BVH gives back the same structure (no inserted joints) and positions.
    const Motion back = to_post_rotation(l.pre).value();
    ASSERT_EQ(back.skeleton.size(), l.post.skeleton.size());
    for (int j = 0; j < static_cast<int>(back.skeleton.size()); ++j) {
      EXPECT_EQ(back.skeleton.joint(j).name, l.post.skeleton.joint(j).name);
      EXPECT_EQ(back.skeleton.joint(j).parent, l.post.skeleton.joint(j).parent);
      EXPECT_EQ(back.skeleton.joint(j).offset, l.post.skeleton.joint(j).offset);
    }
    EXPECT_LE(error_vs_reference(l, back), 1e-6 * l.size);
  }
}

TEST(GmrAndBvhFilesOnCorpus, RoundTripKeepsPositions) {
  GMR_REQUIRE_DATA();
  const fs::path dir = fs::temp_directory_path() / ("gmr_ops_data_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  for (const Loaded& l : corpus()) {
    SCOPED_TRACE(label(l));
    const fs::path g = dir / "m.gmr", b = dir / "m.bvh";
    ASSERT_TRUE(write_gmr(l.pre, g).ok());
    auto read_back = read_gmr(g);
    ASSERT_TRUE(read_back.ok()) << read_back.error().to_string();
    const Motion post = to_post_rotation(*read_back).value();
    ASSERT_TRUE(write_bvh(post, b).ok());
    auto again = read_bvh(b);
    ASSERT_TRUE(again.ok()) << again.error().to_string();
    EXPECT_LE(error_vs_reference(l, *again), 1e-6 * l.size);
  }
  fs::remove_all(dir);
}

TEST(OperationSequencesOnCorpus, KeepEveryPosition) {
  GMR_REQUIRE_DATA();
  std::uint32_t seed = 2012;
  for (const Loaded& l : corpus()) {
    SCOPED_TRACE(label(l));
    std::mt19937 rng(seed++);
    const double tol = 1e-9 * l.size;
    const int n = static_cast<int>(l.pre.skeleton.size());
    // Two sequences of four operations per file keep the suite's run time sane
    // (files have up to 4511 frames); every frame of every step is checked.
    for (int sequence = 0; sequence < 2; ++sequence) {
      Motion m = l.pre;
      for (int step = 0; step < 4; ++step) {
        const int op = static_cast<int>(rng() % 4);
        const int j = static_cast<int>(rng() % static_cast<unsigned>(n));
        std::string what;
        if (op == 0) {
          what = "shift to " + l.pre.skeleton.joint(j).name;
          m = shift_root(m, m.skeleton.find(l.pre.skeleton.joint(j).name)).value();
        } else if (op == 1) {
          const int k = m.skeleton.find(l.pre.skeleton.joint(j).name);
          if (m.skeleton.is_root(k)) continue;
          what = "split at " + l.pre.skeleton.joint(j).name;
          m = split_tree(m, k).value();
        } else if (op == 2) {
          std::vector<int> linked;
          for (int r : m.skeleton.roots()) {
            if (m.skeleton.joint(r).soft_parent != kNoParent) linked.push_back(r);
          }
          if (linked.empty()) continue;
          const int r = linked[rng() % linked.size()];
          what = "join " + m.skeleton.joint(r).name;
          JoinReport report;
          auto joined = join_tree(m, r, &report);
          ASSERT_TRUE(joined.ok()) << what << ": " << joined.error().to_string();
          m = std::move(joined).value();
        } else {
          // A random target set (sometimes every joint), always with one root per skeleton.
          std::vector<std::string> names;
          const bool all = rng() % 4 == 0;
          for (int k = 0; k < n; ++k) {
            if (all || rng() % 5 == 0 || k == j) names.push_back(l.pre.skeleton.joint(k).name);
          }
          what = "set " + std::to_string(names.size()) + " roots";
          auto r = set_roots(m, indices_of(m, names));
          ASSERT_TRUE(r.ok()) << what << ": " << r.error().to_string();
          m = std::move(r).value();
          EXPECT_EQ(m.skeleton.roots().size(), names.size());
        }
        ASSERT_TRUE(Skeleton::create(m.skeleton.joints()).ok());
        EXPECT_LE(error_vs_reference(l, m), tol) << "sequence " << sequence << " step " << step << ": " << what;
      }
    }
  }
}

TEST(AllRootsOnCorpus, ReadsPositionsWithoutRotations) {
  GMR_REQUIRE_DATA();
  for (const Loaded& l : corpus()) {
    SCOPED_TRACE(label(l));
    std::vector<int> all(l.pre.skeleton.size());
    std::iota(all.begin(), all.end(), 0);
    const Motion t = set_roots(l.pre, all).value();
    ASSERT_EQ(t.skeleton.roots().size(), t.skeleton.size());
    reset_fk_rotation_evaluations();
    EXPECT_LE(error_vs_reference(l, t), 1e-9 * l.size);
    EXPECT_EQ(fk_rotation_evaluations(), 0u);
    // And back to the original root: the original local data.
    const std::vector<int> root{t.skeleton.find(l.pre.skeleton.joint(0).name)};
    EXPECT_TRUE(same_local_data(l.pre, set_roots(t, root).value(), 1e-9, 1e-9 * l.size));
  }
}

TEST(SplitJoinShiftOnCorpus, ThereAndBackRestoreLocalData) {
  GMR_REQUIRE_DATA();
  std::uint32_t seed = 77;
  for (const Loaded& l : corpus()) {
    SCOPED_TRACE(label(l));
    std::mt19937 rng(seed++);
    const int n = static_cast<int>(l.pre.skeleton.size());
    if (n < 2) continue;
    const int j = 1 + static_cast<int>(rng() % static_cast<unsigned>(n - 1));  // not the root
    const std::string name = l.pre.skeleton.joint(j).name;
    const Motion split = split_tree(l.pre, j).value();
    JoinReport report;
    const Motion joined = join_tree(split, split.skeleton.find(name), &report).value();
    // Rigid (static offset again) unless the joint's own position channels vary.
    bool varies = false;
    for (std::size_t f = 1; f < l.pre.frame_count && !varies; ++f) {
      varies = (l.pre.local_offset(f, j) - l.pre.local_offset(0, j)).norm() > 1e-9 * l.size;
    }
    EXPECT_EQ(report.translation_channels, varies) << name << " spread " << report.offset_spread;
    EXPECT_TRUE(same_local_data(l.pre, joined, 1e-9, 1e-9 * l.size)) << "split/join at " << name;

    const Motion there = shift_root(l.pre, j).value();
    const Motion back = shift_root(there, there.skeleton.find(l.pre.skeleton.joint(0).name)).value();
    EXPECT_TRUE(same_local_data(l.pre, back, 1e-9, 1e-9 * l.size)) << "shift to " << name << " and back";
  }
}

TEST(StripDummiesOnCmuFiles, RemovesOnlyZeroLengthJoints) {
  GMR_REQUIRE_DATA();
  int cmu_files = 0;
  for (const Loaded& l : corpus()) {
    if (l.pre.skeleton.find("LHipJoint") < 0) continue;  // CMU-style skeletons
    SCOPED_TRACE(label(l));
    ++cmu_files;
    std::vector<RemovedJoint> removed;
    const Motion s = strip_dummies(l.pre, &removed).value();
    std::vector<std::string> names;
    for (const auto& r : removed) names.push_back(r.name);
    EXPECT_NE(std::find(names.begin(), names.end(), "LHipJoint"), names.end());
    EXPECT_NE(std::find(names.begin(), names.end(), "RHipJoint"), names.end());
    EXPECT_GE(s.skeleton.find("Hips"), 0);
    // Only joints at the place of another went (every frame), and every
    // other joint stays where it was.
    const std::size_t n = l.pre.skeleton.size();
    const auto all = positions_by_name(l.pre, l.pre.skeleton);
    for (const auto& r : removed) {
      const int d = l.pre.skeleton.find(r.name), k = l.pre.skeleton.find(r.merged_into);
      ASSERT_GE(k, 0) << r.merged_into;
      for (std::size_t f = 0; f < l.pre.frame_count; ++f) ASSERT_EQ(all[f * n + d], all[f * n + k]) << r.name;
    }
    EXPECT_EQ(s.skeleton.size() + removed.size(), n);
    const auto p = positions_by_name(s, s.skeleton);
    const auto q = positions_by_name(l.pre, s.skeleton);
    EXPECT_LE(test::compare_positions(p, q, s.skeleton.size()).max_error, 1e-9 * l.size);

    // The rule does not depend on where a tree's root is: rooted at the head,
    // or at the end of a limb, the same joints go and the rest stand as before.
    // (Several roots would split the tree: a split root is a tree of its own.)
    const int head = l.pre.skeleton.find("Head");
    ASSERT_GE(head, 0);
    const int last = static_cast<int>(n) - 1;  // a joint at the end of some limb
    for (const std::vector<int>& idx : {std::vector<int>{head}, std::vector<int>{last}}) {
      const std::string roots = l.pre.skeleton.joint(idx.front()).name;
      auto moved = set_roots(l.pre, idx);
      ASSERT_TRUE(moved.ok()) << moved.error().to_string();
      std::vector<RemovedJoint> removed_there;
      auto stripped = strip_dummies(*moved, &removed_there);
      ASSERT_TRUE(stripped.ok()) << stripped.error().to_string();
      const Motion& t = *stripped;
      ASSERT_EQ(t.skeleton.size(), s.skeleton.size()) << roots;
      for (const Joint& j : s.skeleton.joints())
        EXPECT_GE(t.skeleton.find(j.name), 0) << j.name << " rooted at " << roots;
      const auto there = positions_by_name(t, s.skeleton);
      EXPECT_LE(test::compare_positions(p, there, s.skeleton.size()).max_error, 1e-9 * l.size) << roots;
    }
  }
  EXPECT_GE(cmu_files, 5);
}

// Engine bones (gmr/view/engine_pose.h): on a motion read from BVH, each
// joint's local translation is the file's offset (position channels
// substituted) and its local rotation the file's rotation, every frame; the
// rest pose is the offsets with no rotation.
TEST(EngineLocalsOnCorpus, AreTheFilesOffsetsAndRotations) {
  GMR_REQUIRE_DATA();
  ASSERT_FALSE(corpus().empty());
  std::size_t files = 0, checked = 0;
  for (const Loaded& l : corpus()) {
    SCOPED_TRACE(label(l));
    const Motion& m = l.pre;
    const std::size_t n = m.skeleton.size();
    const auto sources = own_frame_sources(m);
    std::vector<int> all(n), post_index(n);
    for (std::size_t j = 0; j < n; ++j) {
      all[j] = static_cast<int>(j);
      post_index[j] = l.post.skeleton.find(m.skeleton.joint(static_cast<int>(j)).name);
      ASSERT_GE(post_index[j], 0);
    }
    std::vector<Eigen::Vector3d> pos(n), t(n);
    std::vector<Eigen::Matrix3d> rot(n);
    std::vector<Eigen::Quaterniond> q(n);
    double worst_t = 0.0, worst_q = 0.0;
    for (std::size_t f = 0; f < m.frame_count; ++f) {
      view_frame(m, -1, f, pos, rot);
      engine_locals(m.skeleton, sources, pos, rot, all, q, t);
      for (std::size_t j = 0; j < n; ++j) {
        worst_t = std::max(worst_t, (t[j] - l.post.local_offset(f, post_index[j])).norm());
        // A BVH leaf's rotation moves no position and GMR keeps none: identity.
        const Eigen::Matrix3d file_rotation = l.post.skeleton.children(post_index[j]).empty()
                                                  ? Eigen::Matrix3d::Identity()
                                                  : l.post.local_rotation(f, post_index[j]);
        worst_q = std::max(worst_q, (q[j].toRotationMatrix() - file_rotation).cwiseAbs().maxCoeff());
        ++checked;
      }
    }
    EXPECT_LE(worst_t, 1e-9 * l.size);
    EXPECT_LE(worst_q, 1e-9);
    const RestPose rest = engine_rest_pose(m);
    for (std::size_t j = 0; j < n; ++j) {
      const Joint& pj = l.post.skeleton.joint(post_index[j]);
      Eigen::Vector3d expected = pj.offset;
      for (std::size_t c = 0; c < pj.channels.size(); ++c) {  // zero position channels replace the offset
        if (pj.channels[c] == ChannelType::kXposition) expected.x() = 0;
        if (pj.channels[c] == ChannelType::kYposition) expected.y() = 0;
        if (pj.channels[c] == ChannelType::kZposition) expected.z() = 0;
      }
      EXPECT_LE((rest.translations[j] - expected).norm(), 1e-12 * l.size) << pj.name;
      EXPECT_LE(rest.rotations[j].angularDistance(Eigen::Quaterniond::Identity()), 1e-12) << pj.name;
    }
    ++files;
  }
  EXPECT_EQ(files, test::expected_data_files("bvh", ".bvh"));
  EXPECT_GT(checked, 0u);
}

// Composing the locals, O_j = O_p Q_j and P_j = P_p + O_p T_j from the roots
// down, gives back every position of views whose joints have outgoing bones
// in different frames (re-rooted, several roots), seen from a joint and in
// Unreal's conventions; every frame.
TEST(EngineLocalsOnCorpus, ComposeToEveryPositionOfReRootedViews) {
  GMR_REQUIRE_DATA();
  Conventions unreal;
  unreal.preset = ConventionPreset::kUnreal;
  unreal.source_metres_per_unit = 0.0254;
  const OutputBasis basis = output_basis(unreal).value();
  std::size_t views = 0, small = 0;
  for (const Loaded& l : corpus()) {
    SCOPED_TRACE(label(l));
    const int n = static_cast<int>(l.pre.skeleton.size());
    if (n < 4) {  // parser fixtures of one to three joints
      ++small;
      continue;
    }
    auto shifted_r = shift_root(l.pre, n - 1);  // a leaf's end, usually
    ASSERT_TRUE(shifted_r.ok()) << shifted_r.error().to_string();
    std::vector<int> three{1, n / 2, n - 2};
    three.erase(std::unique(three.begin(), three.end()), three.end());
    auto forest_r = set_roots(l.pre, three);
    ASSERT_TRUE(forest_r.ok()) << forest_r.error().to_string();
    const Motion shifted = std::move(shifted_r).value(), forest = std::move(forest_r).value();
    for (const Motion* m : {&shifted, &forest}) {
      const auto sources = own_frame_sources(*m);
      std::vector<int> all(static_cast<std::size_t>(n));
      std::iota(all.begin(), all.end(), 0);
      std::vector<Eigen::Vector3d> pos(all.size()), t(all.size());
      std::vector<Eigen::Matrix3d> rot(all.size());
      std::vector<Eigen::Quaterniond> q(all.size());
      const int viewer = n / 4;
      double worst = 0.0;
      for (std::size_t f = 0; f < m->frame_count; ++f) {
        view_frame(*m, viewer, f, pos, rot, basis);
        engine_locals(m->skeleton, sources, pos, rot, all, q, t);
        worst = std::max(worst,
                         test::compare_positions(test::compose_locals(m->skeleton, q, t), pos, all.size()).max_error);
      }
      EXPECT_LE(worst, 1e-9 * l.size * basis.scale);
      ++views;
    }
  }
  EXPECT_EQ(views + 2 * small, 2 * test::expected_data_files("bvh", ".bvh"));
  EXPECT_LE(small, 2u);
}

}  // namespace
}  // namespace gmr
