// The intrinsic viewpoint (gmr/view/viewpoint.h): the double path against its
// definition, and the float path against the double one.
#include "gmr/view/viewpoint.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <vector>

#include "gmr/fast/compiled_motion.h"
#include "gmr/fast/fast_fk.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/ops/convert.h"
#include "ops_test_util.h"

namespace gmr {
namespace {

using test::random_motion;
using test::RandomMotionOptions;

Motion random_pre(std::uint32_t seed, int roots) {
  RandomMotionOptions o;
  o.roots = roots;
  o.joints = 12;
  o.frames = 6;
  return to_pre_rotation(random_motion(seed, o)).value();
}

TEST(Viewpoint, WorldPassesValuesThroughUnchanged) {
  const Viewpoint world;
  EXPECT_TRUE(world.is_world());
  const Eigen::Vector3d p(-0.0, 1.5, -2.25);
  const Eigen::Vector3d q = world.position(p);
  EXPECT_TRUE(std::signbit(q.x()));  // not even -0 becomes +0
  EXPECT_EQ(q, p);
}

TEST(Viewpoint, ViewerSeesItselfAtTheOriginAndDistancesAreKept) {
  for (std::uint32_t seed = 1; seed <= 4; ++seed) {
    const Motion m = random_pre(seed, 1 + static_cast<int>(seed % 3));
    const std::size_t n = m.skeleton.size();
    std::vector<Eigen::Vector3d> world(n), seen(n);
    std::vector<Eigen::Matrix3d> world_o(n), seen_o(n);
    for (int v = 0; v < static_cast<int>(n); ++v) {
      for (std::size_t f = 0; f < m.frame_count; ++f) {
        compute_frame(m, f, world, world_o);
        view_frame(m, v, f, seen, seen_o);
        const auto vi = static_cast<std::size_t>(v);
        EXPECT_LE(seen[vi].norm(), 1e-12);
        EXPECT_TRUE(seen_o[vi].isIdentity(1e-12));
        for (std::size_t a = 0; a < n; ++a) {
          // p' = W_v^T (p - P_v) and W' = W_v^T W, by definition.
          const Eigen::Matrix3d wt = world_o[vi].transpose();
          EXPECT_LE((seen[a] - wt * (world[a] - world[vi])).norm(), 1e-12);
          EXPECT_LE((seen_o[a] - wt * world_o[a]).norm(), 1e-12);
          EXPECT_NEAR((seen[a] - seen[0]).norm(), (world[a] - world[0]).norm(), 1e-9);
        }
      }
    }
  }
}

TEST(Viewpoint, WorldViewEqualsForwardKinematics) {
  const Motion m = random_pre(7, 2);
  const std::size_t n = m.skeleton.size();
  std::vector<Eigen::Vector3d> p(n), q(n);
  for (std::size_t f = 0; f < m.frame_count; ++f) {
    compute_frame(m, f, p);
    view_frame(m, -1, f, q);
    EXPECT_EQ(p, q);
  }
}

// The float path (FkFrameJob, then view_frame_float) agrees with the double
// path to float round-off, for every viewer, for a subset of joints in any
// order, with and without quaternions (then the same positions, bit for bit).
TEST(Viewpoint, FloatPathMatchesDoublePath) {
  for (std::uint32_t seed = 11; seed <= 13; ++seed) {
    const Motion m = random_pre(seed, 1 + static_cast<int>(seed % 2));
    const std::size_t n = m.skeleton.size();
    auto cm = fast::CompiledMotion::compile(m);
    ASSERT_TRUE(cm.ok()) << cm.error().to_string();
    std::vector<float> fk_p(3 * n), fk_o(9 * n), ws(fast::fk_workspace_size(*cm));
    const std::vector<int> joints = {5, 0, 11, 3};
    std::vector<float> out_p(3 * joints.size()), out_q(4 * joints.size());
    std::vector<Eigen::Vector3d> dp(n);
    std::vector<Eigen::Matrix3d> dorient(n);
    const double tol = 1e-5 * skeleton_size(m);
    for (int v = -1; v < static_cast<int>(n); ++v) {
      for (std::size_t f = 0; f < m.frame_count; ++f) {
        fast::FkFrameJob job{&*cm, f, fk_p, fk_o, ws};
        ASSERT_TRUE(job.run()) << job.check().error().to_string();
        view_frame_float(fk_p, fk_o, v, joints, out_p, out_q);
        view_frame(m, v, f, dp, dorient);
        if (v < 0) {
          // World positions alone (a shorter path) are the same floats.
          std::vector<float> alone(3 * joints.size(), -1.0f);
          view_frame_float(fk_p, {}, -1, joints, alone, {});
          EXPECT_EQ(alone, out_p) << "frame " << f;
        }
        for (std::size_t i = 0; i < joints.size(); ++i) {
          const auto j = static_cast<std::size_t>(joints[i]);
          const Eigen::Vector3d got(out_p[3 * i], out_p[3 * i + 1], out_p[3 * i + 2]);
          EXPECT_LE((got - dp[j]).norm(), tol) << "viewer " << v << " frame " << f << " joint " << j;
          const Eigen::Quaterniond want(dorient[j]);
          const Eigen::Quaterniond q(out_q[4 * i + 3], out_q[4 * i], out_q[4 * i + 1], out_q[4 * i + 2]);
          EXPECT_NEAR(std::abs(q.dot(want)), 1.0, 1e-5) << "viewer " << v << " frame " << f << " joint " << j;
        }
      }
    }
    // World positions alone are copied run by run of consecutive joints:
    // every joint in order (one run), and runs cut anywhere.
    std::vector<int> every(n);
    for (std::size_t j = 0; j < n; ++j) every[j] = static_cast<int>(j);
    for (const std::vector<int>& list : {every, std::vector<int>{2, 3, 4, 0, 1, 7}, std::vector<int>{9, 10, 3, 4, 5}}) {
      std::vector<float> alone(3 * list.size()), with_q(3 * list.size()), q(4 * list.size());
      view_frame_float(fk_p, {}, -1, list, alone, {});
      view_frame_float(fk_p, fk_o, -1, list, with_q, q);
      EXPECT_EQ(alone, with_q) << list.size() << " joints";
    }
    // Without quaternions only positions are written.
    std::vector<float> only_p(3 * joints.size(), -1.0f);
    view_frame_float(fk_p, {}, -1, joints, only_p, {});
    EXPECT_EQ(only_p[0], fk_p[3 * 5]);
  }
}

}  // namespace
}  // namespace gmr
