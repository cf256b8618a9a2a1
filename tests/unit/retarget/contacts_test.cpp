// Foot contacts kept after a retarget (gmr::keep_contacts): CMU 02_01, a walk,
// put on the Mixamo rig. Judged by what a viewer sees, measured here without
// the method's own bookkeeping: how far the ankles slide along the floor
// while they are down, the feet's world orientations, and every joint above
// the legs untouched.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "gmr/io/motion_file.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/ops/convert.h"
#include "gmr/retarget/retarget.h"
#include "test_data.h"

namespace gmr {
namespace {

using Vec = Eigen::Vector3d;
using Mat = Eigen::Matrix3d;

Motion load(const std::string& relative) {
  auto m = load_motion(test::data_file(relative));
  EXPECT_TRUE(m.ok()) << relative << ": " << (m.ok() ? "" : m.error().to_string());
  return m.ok() ? std::move(m).value() : Motion{};
}

struct Poses {
  std::vector<std::vector<Vec>> p;
  std::vector<std::vector<Mat>> w;
};

Poses poses(const Motion& m) {
  Poses out;
  out.p.assign(m.frame_count, std::vector<Vec>(m.skeleton.size()));
  out.w.assign(m.frame_count, std::vector<Mat>(m.skeleton.size()));
  for (std::size_t f = 0; f < m.frame_count; ++f) compute_frame(m, f, out.p[f], out.w[f]);
  return out;
}

// Foot skate: the distance an ankle travels along the floor between
// consecutive frames in which it is low (within 10% of the hip height of its
// 10th-percentile height in `reference`, the plain retarget) and slow there
// (under a third of the hip height per second), summed over the take.
double skate(const Poses& m, const Poses& reference, int ankle, const Vec& up, double hip_height, double frame_time) {
  const auto a = static_cast<std::size_t>(ankle);
  std::vector<double> heights;
  for (const auto& p : reference.p) heights.push_back(p[a].dot(up));
  std::sort(heights.begin(), heights.end());
  const double floor = heights[heights.size() / 10];
  auto down = [&](std::size_t f) {
    const Vec d = reference.p[std::min(f + 1, reference.p.size() - 1)][a] - reference.p[f > 0 ? f - 1 : f][a];
    return reference.p[f][a].dot(up) - floor < 0.1 * hip_height &&
           (d - d.dot(up) * up).norm() / (2 * frame_time) < hip_height / 3;
  };
  double travel = 0;
  for (std::size_t f = 1; f < m.p.size(); ++f) {
    if (!down(f) || !down(f - 1)) continue;
    const Vec d = m.p[f][a] - m.p[f - 1][a];
    travel += (d - d.dot(up) * up).norm();
  }
  return travel;
}

TEST(Contacts, AWalkOnMixamoKeepsItsRestingFeetWhereTheyRest) {
  GMR_REQUIRE_DATA();
  const Motion source = load("bvh/cmu/02_01.bvh");
  const Motion rig = load("bvh/mixamo/Beta_jump.bvh");
  ASSERT_GT(source.frame_count, 100u);
  RetargetPlan plan;
  auto plain = retarget(source, rig, {}, &plan);
  ASSERT_TRUE(plain.ok()) << plain.error().to_string();
  ContactReport report;
  auto kept = keep_contacts(*plain, plan, {}, &report);
  ASSERT_TRUE(kept.ok()) << kept.error().to_string();
  ASSERT_EQ(kept->skeleton.size(), plain->skeleton.size());
  ASSERT_EQ(kept->frame_count, plain->frame_count);
  for (double v : kept->values) ASSERT_TRUE(std::isfinite(v));

  const double h = plan.target_hip_height;
  const Vec up = plan.target_up;
  const Poses a = poses(*plain), b = poses(*kept);
  const int left = plan.target[Role::kLeftFoot], right = plan.target[Role::kRightFoot];
  const double dt = kept->frame_time;
  const double skate_before = skate(a, a, left, up, h, dt) + skate(a, a, right, up, h, dt);
  const double skate_after = skate(b, a, left, up, h, dt) + skate(b, a, right, up, h, dt);
  std::printf(
      "02_01 on Mixamo, %zu frames: %zu contacts, %zu foot-frames pinned, %zu out of reach; "
      "ankle slide from the pin %.4g -> %.4g; body lowered up to %.4g; foot skate %.4g -> %.4g "
      "(hip height %.4g)\n",
      kept->frame_count, report.contacts, report.frames_pinned, report.out_of_reach, report.slide_before,
      report.slide_after, report.lowest, skate_before, skate_after, h);
  // A walk of several steps: each foot rests more than once.
  EXPECT_GE(report.contacts, 4u);
  EXPECT_GE(report.frames_pinned, kept->frame_count / 4);
  // Pinned exactly (the body lowered where a straight leg fell short); the
  // plain retarget slid, and the skate is mostly gone.
  EXPECT_GT(report.slide_before, 1e-2 * h);
  EXPECT_LT(report.slide_after, 1e-9 * h);
  EXPECT_LT(report.lowest, 0.05 * h);
  EXPECT_LT(skate_after, 0.5 * skate_before);

  // The feet keep their world orientation in every frame, every bone its
  // length (the offsets are the rig's), and nothing above the legs turns.
  std::vector<bool> leg(kept->skeleton.size(), false);
  for (Role r : {Role::kLeftUpperLeg, Role::kLeftLowerLeg, Role::kLeftFoot, Role::kRightUpperLeg, Role::kRightLowerLeg,
                 Role::kRightFoot}) {
    leg[static_cast<std::size_t>(plan.target[r])] = true;
  }
  double foot_turn = 0;
  std::size_t changed_frames = 0;
  for (std::size_t f = 0; f < kept->frame_count; ++f) {
    for (int ankle : {left, right}) {
      const auto k = static_cast<std::size_t>(ankle);
      foot_turn = std::max(foot_turn, (b.w[f][k] - a.w[f][k]).norm());
    }
    bool changed = false;
    for (int j = 0; j < static_cast<int>(kept->skeleton.size()); ++j) {
      const Joint& joint = kept->skeleton.joint(j);
      const auto at = static_cast<std::size_t>(kept->skeleton.channel_offset(j));
      const auto x = plain->frame(f).subspan(at, joint.channels.size());
      const auto y = kept->frame(f).subspan(at, joint.channels.size());
      const bool same = std::equal(x.begin(), x.end(), y.begin());
      changed = changed || !same;
      if (leg[static_cast<std::size_t>(j)]) continue;
      // Above the legs nothing turns; the root may only go down, along up,
      // by at most what the report says.
      Vec moved = Vec::Zero();
      for (std::size_t c = 0; c < joint.channels.size(); ++c) {
        if (is_position(joint.channels[c])) {
          moved[static_cast<int>(axis_of(joint.channels[c]))] = y[c] - x[c];
        } else {
          ASSERT_EQ(x[c], y[c]) << joint.name << " turned in frame " << f;
        }
      }
      if (moved.isZero()) continue;
      ASSERT_EQ(joint.parent, kNoParent) << joint.name << " moved in frame " << f;
      EXPECT_LT((moved - moved.dot(up) * up).norm(), 1e-9 * h) << "the root moved sideways in frame " << f;
      EXPECT_LE(-moved.dot(up), report.lowest * (1 + 1e-9)) << f;
      EXPECT_GT(-moved.dot(up), 0.0) << "the root went up in frame " << f;
    }
    if (changed) ++changed_frames;
  }
  EXPECT_LT(foot_turn, 1e-9);
  // Only frames in or near a contact change.
  EXPECT_GE(changed_frames, report.frames_pinned / 2);
  EXPECT_LE(changed_frames, kept->frame_count);
}

// Refusals, and a take without frames (nothing to pin, not a crash).
TEST(Contacts, AMotionThatIsNotARetargetsOutputIsRefused) {
  GMR_REQUIRE_DATA();
  const Motion source = load("bvh/cmu/02_01.bvh");
  RetargetPlan plan;
  auto plain = retarget(source, load("bvh/mixamo/Beta_jump.bvh"), {}, &plan);
  ASSERT_TRUE(plain.ok());
  auto pre = to_pre_rotation(*plain);
  ASSERT_TRUE(pre.ok());
  auto wrong = keep_contacts(*pre, plan);
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.error().message.find("post-rotation"), std::string::npos);
  Motion empty = *plain;
  empty.frame_count = 0;
  empty.values.clear();
  ContactReport none;
  auto nothing = keep_contacts(empty, plan, {}, &none);
  ASSERT_TRUE(nothing.ok()) << nothing.error().to_string();
  EXPECT_EQ(nothing->frame_count, 0u);
  EXPECT_EQ(none.contacts, 0u);
  RetargetPlan no_height = plan;
  no_height.target_hip_height = 0;
  auto unknown = keep_contacts(*plain, no_height);
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.error().message.find("hip height"), std::string::npos);
}

}  // namespace
}  // namespace gmr
