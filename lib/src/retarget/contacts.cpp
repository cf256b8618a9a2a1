// Foot contacts kept after a retarget (docs/retarget.md, "Foot contacts"):
// stretches where an ankle rests on the floor are found in the retargeted
// take, each gets one pin on the floor, and a two-bone IK on the leg (hip
// joint and knee, bending in the knee's own plane) puts the ankle there while
// the foot keeps its world orientation. Pins ease in and out over a few
// frames so the leg does not jump.
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "gmr/core/rotation.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/retarget/retarget.h"
#include "rig_joints.h"

namespace gmr {
namespace {

using Mat = Eigen::Matrix3d;
using Vec = Eigen::Vector3d;

struct Leg {
  int hip, knee, ankle;  // joints of the roles upper_leg, lower_leg, foot
};

// A stretch of frames [begin, end) where one foot rests, and where it rests.
struct Stretch {
  std::size_t begin, end;
  Vec pin;
};

void write_rotation(const Skeleton& s, int j, const Mat& local, std::span<double> values) {
  Axis order[3];
  int slots[3];
  detail::rotation_slots(s, j, order, slots);
  // Continuous with the angles the frame had (the retarget kept them continuous).
  const Vec hint(values[static_cast<std::size_t>(slots[0])], values[static_cast<std::size_t>(slots[1])],
                 values[static_cast<std::size_t>(slots[2])]);
  const Vec angles = decompose_euler(local, order, &hint);
  for (int i = 0; i < 3; ++i) values[static_cast<std::size_t>(slots[i])] = angles[i];
}

// The rotation about `axis` (unit) that brings the knee's interior angle to
// the one whose hip-to-ankle distance is `reach`: of the two turns that give
// that distance, the one that keeps the knee bending the way it bends.
Mat bend(const Vec& hip, const Vec& knee, const Vec& ankle, const Vec& axis, double reach) {
  const Vec thigh = hip - knee, shin = ankle - knee;
  const double l1 = thigh.norm(), l2 = shin.norm();
  const double now = std::acos(std::clamp(thigh.dot(shin) / (l1 * l2), -1.0, 1.0));
  const double want = std::acos(std::clamp((l1 * l1 + l2 * l2 - reach * reach) / (2 * l1 * l2), -1.0, 1.0));
  Mat best = Mat::Identity();
  double miss = INFINITY;
  for (double sign : {1.0, -1.0}) {
    const Mat r = Eigen::AngleAxisd(sign * (want - now), axis).toRotationMatrix();
    const double d = std::abs((knee + r * shin - hip).norm() - reach);
    if (d < miss) miss = d, best = r;
  }
  return best;
}

}  // namespace

Result<Motion> keep_contacts(const Motion& retargeted, const RetargetPlan& plan, const ContactOptions& options,
                             ContactReport* report) {
  if (auto s = retargeted.validate(); !s.ok()) return s.error();
  if (retargeted.convention != Convention::kPostRotation) {
    return make_error("keep contacts: the motion is not a retarget's output (post-rotation)");
  }
  const Skeleton& sk = retargeted.skeleton;
  const HumanoidMap& T = plan.target;
  const double h = plan.target_hip_height;
  if (!(h > 0.0) || !std::isfinite(h)) return make_error("keep contacts: the rig's hip height is unknown");
  std::vector<Leg> legs;
  for (auto [hip, knee, ankle] : {std::array{Role::kLeftUpperLeg, Role::kLeftLowerLeg, Role::kLeftFoot},
                                  std::array{Role::kRightUpperLeg, Role::kRightLowerLeg, Role::kRightFoot}}) {
    Leg leg{T[hip], T[knee], T[ankle]};
    if (leg.hip < 0 || leg.knee < 0 || leg.ankle < 0 || leg.hip >= static_cast<int>(sk.size()) ||
        leg.knee >= static_cast<int>(sk.size()) || leg.ankle >= static_cast<int>(sk.size())) {
      return make_error("keep contacts: the plan's leg roles are not joints of this motion");
    }
    if (!detail::below(sk, leg.hip, leg.knee) || !detail::below(sk, leg.knee, leg.ankle)) {
      return make_error("keep contacts: '" + sk.joint(leg.ankle).name + "' does not hang from '" +
                        sk.joint(leg.knee).name + "' and '" + sk.joint(leg.hip).name + "'");
    }
    for (int j : {leg.hip, leg.knee, leg.ankle}) {
      Axis order[3];
      int slots[3];
      if (!detail::rotation_slots(sk, j, order, slots)) {
        return make_error("keep contacts: '" + sk.joint(j).name + "' has fewer than three rotation channels");
      }
    }
    legs.push_back(leg);
  }

  const std::size_t frames = retargeted.frame_count;
  if (frames == 0) {  // nothing rests in no frame
    if (report != nullptr) *report = {};
    return retargeted;
  }
  const Vec up = plan.target_up.normalized();
  std::vector<std::vector<Vec>> p(frames, std::vector<Vec>(sk.size()));
  std::vector<std::vector<Mat>> w(frames, std::vector<Mat>(sk.size()));
  for (std::size_t f = 0; f < frames; ++f) compute_frame(retargeted, f, p[f], w[f]);
  auto along_floor = [&](const Vec& v) { return Vec(v - v.dot(up) * up); };

  ContactReport r;
  Motion out = retargeted;
  // Per leg: the stretches, then per frame the eased target.
  std::vector<std::vector<Vec>> target(legs.size(), std::vector<Vec>(frames));
  std::vector<std::vector<double>> weight(legs.size(), std::vector<double>(frames, 0.0));
  for (std::size_t l = 0; l < legs.size(); ++l) {
    const auto a = static_cast<std::size_t>(legs[l].ankle);
    // The floor: the ankle's height in the lowest 5% of the take's frames
    // (robust to a first frame in another pose, as cgspeed's T-pose).
    std::vector<double> heights(frames);
    for (std::size_t f = 0; f < frames; ++f) heights[f] = p[f][a].dot(up);
    std::nth_element(heights.begin(), heights.begin() + static_cast<long>(frames / 20), heights.end());
    const double floor = heights[frames / 20];
    std::vector<bool> down(frames, false);
    for (std::size_t f = 0; f < frames; ++f) {
      const std::size_t g = f + 1 < frames ? f + 1 : f, e = f > 0 ? f - 1 : f;
      const double dt = static_cast<double>(g - e) * retargeted.frame_time;
      const double speed = dt > 0 ? along_floor(p[g][a] - p[e][a]).norm() / dt : 0.0;
      down[f] = p[f][a].dot(up) - floor < options.height * h && speed < options.speed * h;
    }
    std::vector<Stretch> stretches;
    for (std::size_t f = 0; f < frames;) {
      if (!down[f]) {
        ++f;
        continue;
      }
      std::size_t e = f;
      while (e < frames && down[e]) ++e;
      if (e - f >= options.min_frames) {
        Vec mean = Vec::Zero();
        for (std::size_t k = f; k < e; ++k) mean += along_floor(p[k][a]);
        stretches.push_back({f, e, mean / static_cast<double>(e - f)});
      }
      f = e;
    }
    for (const Stretch& s : stretches) {
      ++r.contacts;
      r.frames_pinned += s.end - s.begin;
      const std::size_t blend = options.blend_frames;
      const std::size_t from = s.begin > blend ? s.begin - blend : 0, to = std::min(frames, s.end + blend);
      for (std::size_t f = from; f < to; ++f) {
        double wgt = 1.0;
        if (f < s.begin) wgt = 1.0 - static_cast<double>(s.begin - f) / static_cast<double>(blend + 1);
        if (f >= s.end) wgt = 1.0 - static_cast<double>(f - s.end + 1) / static_cast<double>(blend + 1);
        if (f >= s.begin && f < s.end) {
          r.slide_before = std::max(r.slide_before, (along_floor(p[f][a]) - s.pin).norm());
        }
        if (wgt <= weight[l][f]) continue;  // two stretches' eases overlap: the nearer pin wins
        weight[l][f] = wgt;
        // The pin is on the floor plane; the height stays the frame's own.
        const Vec pinned = s.pin + p[f][a].dot(up) * up;
        target[l][f] = p[f][a] + wgt * (pinned - p[f][a]);
      }
    }
  }

  // A pin a straight leg cannot reach lowers the body: the root goes down
  // along up by the least that brings every pinned ankle within reach (a
  // horizontal distance beyond the leg's length stays out of reach), eased
  // over the same frames as the pins so the body does not drop at once.
  int root = T[Role::kHips];
  while (sk.joint(root).parent != kNoParent) root = sk.joint(root).parent;
  std::vector<double> need(frames, 0.0);
  for (std::size_t f = 0; f < frames; ++f) {
    for (std::size_t l = 0; l < legs.size(); ++l) {
      if (weight[l][f] <= 0.0) continue;
      const Vec hip = p[f][static_cast<std::size_t>(legs[l].hip)];
      const Vec knee = p[f][static_cast<std::size_t>(legs[l].knee)];
      const Vec ankle = p[f][static_cast<std::size_t>(legs[l].ankle)];
      const double longest = ((knee - hip).norm() + (ankle - knee).norm()) * (1.0 - 1e-6);
      // |v + d up| = longest, v = target - hip: the smaller root d >= 0.
      const Vec v = target[l][f] - hip;
      const double b = v.dot(up), c = v.squaredNorm() - longest * longest;
      if (c <= 0.0) continue;
      need[f] = std::max(need[f], b * b >= c ? -b - std::sqrt(b * b - c) : -b);
    }
  }
  std::vector<double> drop(frames, 0.0);
  const auto ease = static_cast<std::ptrdiff_t>(options.blend_frames) + 1;
  for (std::size_t g = 0; g < frames; ++g) {
    if (need[g] <= 0.0) continue;
    for (std::ptrdiff_t k = 1 - ease; k < ease; ++k) {
      const auto f = static_cast<std::ptrdiff_t>(g) + k;
      if (f < 0 || f >= static_cast<std::ptrdiff_t>(frames)) continue;
      const double eased = need[g] * (1.0 - static_cast<double>(std::abs(k)) / static_cast<double>(ease));
      drop[static_cast<std::size_t>(f)] = std::max(drop[static_cast<std::size_t>(f)], eased);
    }
  }
  const Joint& root_joint = sk.joint(root);
  const bool movable = std::count_if(root_joint.channels.begin(), root_joint.channels.end(),
                                     [](ChannelType c) { return is_position(c); }) == 3;
  for (std::size_t f = 0; movable && f < frames; ++f) {
    if (drop[f] <= 0.0) continue;
    std::span<double> values = out.frame(f);
    for (std::size_t c = 0; c < root_joint.channels.size(); ++c) {
      if (is_position(root_joint.channels[c])) {
        values[static_cast<std::size_t>(sk.channel_offset(root)) + c] -=
            drop[f] * up[static_cast<int>(axis_of(root_joint.channels[c]))];
      }
    }
    compute_frame(out, f, p[f], w[f]);
    r.lowest = std::max(r.lowest, drop[f]);
  }

  for (std::size_t f = 0; f < frames; ++f) {
    std::span<double> values = out.frame(f);
    for (std::size_t l = 0; l < legs.size(); ++l) {
      if (weight[l][f] <= 0.0) continue;
      const Leg& leg = legs[l];
      const auto hi = static_cast<std::size_t>(leg.hip), kn = static_cast<std::size_t>(leg.knee),
                 an = static_cast<std::size_t>(leg.ankle);
      const Vec hip = p[f][hi], knee = p[f][kn], ankle = p[f][an], want = target[l][f];
      const double l1 = (knee - hip).norm(), l2 = (ankle - knee).norm();
      double reach = (want - hip).norm();
      const double longest = (l1 + l2) * (1.0 - 1e-9), shortest = std::abs(l1 - l2) * (1.0 + 1e-9);
      if (reach > longest || reach < shortest) {
        ++r.out_of_reach;
        reach = std::clamp(reach, shortest, longest);
      }
      // The knee bends about its own axis; a straight leg bends about the
      // axis across the leg and the way to the pin (or any across the leg).
      Vec axis = (hip - knee).cross(ankle - knee);
      if (axis.norm() < 1e-9 * l1 * l2) axis = (knee - hip).cross(want - hip);
      if (axis.norm() < 1e-9 * l1 * l2) axis = (knee - hip).unitOrthogonal();
      const Mat b = bend(hip, knee, ankle, axis.normalized(), reach);
      const Vec bent = knee + b * (ankle - knee);
      const Mat s = Eigen::Quaterniond::FromTwoVectors(bent - hip, want - hip).toRotationMatrix();
      // World turns: the thigh's subtree by s (about the hip), the shin's by
      // s b; the foot keeps its world orientation.
      const int hip_parent = sk.joint(leg.hip).parent, knee_parent = sk.joint(leg.knee).parent,
                ankle_parent = sk.joint(leg.ankle).parent;
      const Mat wp_hip = hip_parent == kNoParent ? Mat::Identity() : w[f][static_cast<std::size_t>(hip_parent)];
      const Mat& wp_knee = w[f][static_cast<std::size_t>(knee_parent)];
      const Mat& wp_ankle = w[f][static_cast<std::size_t>(ankle_parent)];
      write_rotation(sk, leg.hip, wp_hip.transpose() * s * w[f][hi], values);
      write_rotation(sk, leg.knee, wp_knee.transpose() * b * w[f][kn], values);
      write_rotation(sk, leg.ankle, (s * b * wp_ankle).transpose() * w[f][an], values);
    }
  }

  // What the ankles did after, in the stretches (the eases are not contacts).
  std::vector<Vec> q(sk.size());
  std::vector<Mat> wq(sk.size());
  for (std::size_t f = 0; f < frames; ++f) {
    bool pinned = false;
    for (std::size_t l = 0; l < legs.size(); ++l) pinned = pinned || weight[l][f] >= 1.0;
    if (!pinned) continue;
    compute_frame(out, f, q, wq);
    for (std::size_t l = 0; l < legs.size(); ++l) {
      if (weight[l][f] < 1.0) continue;
      const auto an = static_cast<std::size_t>(legs[l].ankle);
      r.slide_after = std::max(r.slide_after, along_floor(q[an] - target[l][f]).norm());
    }
  }
  if (auto s = out.validate(); !s.ok()) return s.error();
  if (report != nullptr) *report = r;
  return out;
}

}  // namespace gmr
