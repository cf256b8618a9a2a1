// The fast float path against the double reference on every BVH of the shared
// corpus, every frame: as read (post-rotation), converted to GMR with one root,
// with seeded random root sets, and with every joint a root. Tolerance: 1e-4 of
// the skeleton's size, compared by joint name because changing roots
// may reorder joints.
#include <gtest/gtest.h>

#include <random>
#include <string>
#include <unordered_map>
#include <vector>

#include "fast/frame_program.h"  // private: the per-joint plans
#include "fast_test_util.h"
#include "gmr/ops/convert.h"
#include "gmr/io/bvh.h"
#include "gmr/ops/join_tree.h"
#include "gmr/ops/set_roots.h"
#include "gmr/ops/shift_root.h"
#include "gmr/ops/split_tree.h"
#include "gmr/ops/strip_dummies.h"

namespace gmr::fast {
namespace {

using test::fast_positions;

// `got` (skeleton `gs`) reordered to the joint order of `want_skeleton`.
std::vector<Eigen::Vector3d> by_names(const Skeleton& gs, const std::vector<Eigen::Vector3d>& got,
                                      const Skeleton& want_skeleton) {
  const std::size_t n = gs.size();
  std::vector<int> map(want_skeleton.size());
  for (std::size_t j = 0; j < want_skeleton.size(); ++j)
    map[j] = gs.find(want_skeleton.joint(static_cast<int>(j)).name);
  const std::size_t frames = n == 0 ? 0 : got.size() / n;
  std::vector<Eigen::Vector3d> out(frames * want_skeleton.size());
  for (std::size_t f = 0; f < frames; ++f) {
    for (std::size_t j = 0; j < want_skeleton.size(); ++j) {
      EXPECT_GE(map[j], 0) << want_skeleton.joint(static_cast<int>(j)).name;
      if (map[j] >= 0) out[f * want_skeleton.size() + j] = got[f * n + static_cast<std::size_t>(map[j])];
    }
  }
  return out;
}

// Fast positions of `m` (all frames) against `want` (the BVH's reference).
void expect_fast_matches(const Motion& m, const Skeleton& want_skeleton, const std::vector<Eigen::Vector3d>& want,
                         double tolerance) {
  auto cm = CompiledMotion::compile(m);
  ASSERT_TRUE(cm.ok()) << cm.error().to_string();
  for (Layout layout : {Layout::kFrameMajor, Layout::kJointMajor}) {
    const auto got = by_names(m.skeleton, fast_positions(*cm, 0, m.frame_count, layout), want_skeleton);
    EXPECT_POSITIONS_NEAR(want_skeleton, got, want, tolerance);
  }
  // The one-frame kernel (its own per-motion program), positions only and
  // with orientations (which computes every world rotation).
  const std::size_t n = cm->joint_count();
  std::vector<float> ws(fk_workspace_size(*cm)), one(n * 3), ori(n * 9);
  for (bool with_orientations : {false, true}) {
    std::vector<Eigen::Vector3d> frames(m.frame_count * n);
    for (std::size_t f = 0; f < m.frame_count; ++f) {
      const FkFrameJob job{.motion = &*cm,
                           .frame = f,
                           .out_positions = one,
                           .out_orientations = with_orientations ? std::span<float>(ori) : std::span<float>(),
                           .workspace = ws};
      ASSERT_TRUE(job.run());
      for (std::size_t j = 0; j < n; ++j)
        frames[f * n + j] = Eigen::Vector3d(one[3 * j], one[3 * j + 1], one[3 * j + 2]);
    }
    SCOPED_TRACE(with_orientations ? "FkFrameJob with orientations" : "FkFrameJob");
    EXPECT_POSITIONS_NEAR(want_skeleton, by_names(m.skeleton, frames, want_skeleton), want, tolerance);
  }
}

class FastEveryBvh : public ::testing::Test {
 protected:
  void SetUp() override { GMR_REQUIRE_DATA(); }
};

TEST_F(FastEveryBvh, FastMatchesReferenceAsReadAndAsGmr) {
  const auto files = test::data_files("bvh", ".bvh");
  ASSERT_FALSE(files.empty());
  std::mt19937 rng(20120101);
  for (const auto& path : files) {
    SCOPED_TRACE(path.string());
    auto bvh = read_bvh(path);
    ASSERT_TRUE(bvh.ok()) << bvh.error().to_string();
    const Motion& m = *bvh;
    const auto want = test::reference_positions(m);
    const double tol = 1e-4 * skeleton_size(m);

    {
      SCOPED_TRACE("post-rotation as read");
      expect_fast_matches(m, m.skeleton, want, tol);
    }
    auto gmr = to_pre_rotation(m);
    ASSERT_TRUE(gmr.ok()) << gmr.error().to_string();
    {
      SCOPED_TRACE("GMR, roots as converted");
      expect_fast_matches(*gmr, m.skeleton, want, tol);
    }
    const int n = static_cast<int>(gmr->skeleton.size());
    std::vector<int> all(static_cast<std::size_t>(n));
    for (int j = 0; j < n; ++j) all[static_cast<std::size_t>(j)] = j;
    // Random root sets: each keeps the original roots (so every connected
    // skeleton has one) plus k random joints.
    for (int k : {1, 4, n / 2}) {
      std::vector<int> roots = gmr->skeleton.roots();
      std::vector<int> pick = all;
      std::shuffle(pick.begin(), pick.end(), rng);
      for (int j : pick) {
        if (static_cast<int>(roots.size()) >= static_cast<int>(gmr->skeleton.roots().size()) + k) break;
        if (std::find(roots.begin(), roots.end(), j) == roots.end()) roots.push_back(j);
      }
      auto moved = set_roots(*gmr, roots);
      ASSERT_TRUE(moved.ok()) << moved.error().to_string();
      SCOPED_TRACE("GMR with " + std::to_string(roots.size()) + " roots");
      expect_fast_matches(*moved, m.skeleton, want, tol);
    }
    auto every = set_roots(*gmr, all);
    ASSERT_TRUE(every.ok()) << every.error().to_string();
    {
      SCOPED_TRACE("GMR, every joint a root");
      auto cm = CompiledMotion::compile(*every);
      ASSERT_TRUE(cm.ok());
      EXPECT_TRUE(cm->all_roots());
      expect_fast_matches(*every, m.skeleton, want, tol);
    }
  }
}

TEST_F(FastEveryBvh, GmrTwinsShareOneRotation) {
  // The BVH -> GMR conversion copies a joint's rotation into each of its
  // children; the compiled form computes each copy once, so the one-root GMR
  // needs no more rotations than the BVH.
  auto bvh = read_bvh(test::data_file("bvh/cmu/01_01.bvh"));
  ASSERT_TRUE(bvh.ok()) << bvh.error().to_string();
  auto gmr = to_pre_rotation(*bvh);
  ASSERT_TRUE(gmr.ok());
  auto cb = CompiledMotion::compile(*bvh);
  auto cg = CompiledMotion::compile(*gmr);
  ASSERT_TRUE(cb.ok() && cg.ok());
  EXPECT_LE(cg->slot_count(), cb->slot_count());
  // LHipJoint and RHipJoint rotate by 0 in every frame: no rotation to compute.
  for (const char* dummy : {"LHipJoint", "RHipJoint"}) {
    EXPECT_FALSE(joint_plans(*cb)[static_cast<std::size_t>(bvh->skeleton.find(dummy))].owns_slot) << dummy;
  }
  std::size_t shared = 0;
  for (const JointPlan& p : joint_plans(*cg)) shared += (!p.owns_slot && p.world_slot != p.parent_slot) ? 1 : 0;
  EXPECT_GT(shared, 0u);
}

TEST_F(FastEveryBvh, SingleFrameEqualsRangeOnCmu) {
  auto bvh = read_bvh(test::data_file("bvh/cmu/01_01.bvh"));
  ASSERT_TRUE(bvh.ok()) << bvh.error().to_string();
  auto gmr = to_pre_rotation(*bvh);
  ASSERT_TRUE(gmr.ok());
  for (const Motion* m : {&*bvh, &*gmr}) {
    auto cm = CompiledMotion::compile(*m);
    ASSERT_TRUE(cm.ok());
    const std::size_t n = cm->joint_count();
    std::vector<float> ws(fk_workspace_size(*cm)), range(cm->frame_count() * n * 3), one(n * 3);
    ASSERT_TRUE(
        (FkRangeJob{.motion = &*cm, .begin = 0, .end = cm->frame_count(), .out_positions = range, .workspace = ws}
             .run()));
    const float tol = static_cast<float>(1e-5 * skeleton_size(*m));
    for (std::size_t f = 0; f < cm->frame_count(); ++f) {
      ASSERT_TRUE((FkFrameJob{.motion = &*cm, .frame = f, .out_positions = one, .workspace = ws}.run()));
      for (std::size_t k = 0; k < n * 3; ++k) ASSERT_NEAR(one[k], range[f * n * 3 + k], tol) << "frame " << f;
    }
  }
}

}  // namespace
}  // namespace gmr::fast
