// Helpers for the ops tests: random motions and comparisons of local data.
#pragma once

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <random>
#include <string>
#include <vector>

#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/motion/motion.h"
#include "test_data.h"

namespace gmr::test {

struct RandomMotionOptions {
  int joints = 12;
  int roots = 1;  // trees in the forest
  std::size_t frames = 5;
  Convention convention = Convention::kPostRotation;
  double zero_offset_chance = 0.2;        // zero-length bones (dummies)
  double position_channel_chance = 0.15;  // position channels on non-roots
};

// A random forest with random rotation channel subsets and orders (0 to 3
// axes), random offsets, some zero-length bones and some position channels on
// non-roots; roots have Xposition Yposition Zposition + 3 rotations.
inline Motion random_motion(std::uint32_t seed, const RandomMotionOptions& o = {}) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_real_distribution<double> angle(-180.0, 180.0);
  std::uniform_real_distribution<double> chance(0.0, 1.0);
  std::vector<Joint> joints;
  for (int j = 0; j < o.joints; ++j) {
    Joint joint;
    joint.name = std::to_string(j);
    joint.name.insert(0, 1, 'j');
    if (j >= o.roots) joint.parent = std::uniform_int_distribution<int>(0, j - 1)(rng);
    if (joint.parent == kNoParent) {
      joint.offset = Eigen::Vector3d(u(rng), u(rng), u(rng)) * 10.0;
      joint.channels = {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition};
    } else if (chance(rng) >= o.zero_offset_chance) {
      joint.offset = Eigen::Vector3d(u(rng), u(rng), u(rng));
    }
    std::vector<ChannelType> rot = {ChannelType::kXrotation, ChannelType::kYrotation, ChannelType::kZrotation};
    std::shuffle(rot.begin(), rot.end(), rng);
    const int k = joint.parent == kNoParent ? 3 : std::uniform_int_distribution<int>(0, 3)(rng);
    if (joint.parent != kNoParent && chance(rng) < o.position_channel_chance) {
      joint.channels.push_back(ChannelType::kYposition);
      joint.channels.push_back(ChannelType::kXposition);
    }
    joint.channels.insert(joint.channels.end(), rot.begin(), rot.begin() + k);
    joints.push_back(std::move(joint));
  }
  Motion m;
  m.skeleton = Skeleton::create(std::move(joints)).value();
  m.convention = o.convention;
  m.frame_time = 1.0 / 30.0;
  m.frame_count = o.frames;
  m.values.resize(m.frame_count * m.stride());
  for (std::size_t f = 0; f < m.frame_count; ++f) {
    for (int j = 0; j < static_cast<int>(m.skeleton.size()); ++j) {
      const Joint& joint = m.skeleton.joint(j);
      auto v = m.frame(f).subspan(static_cast<std::size_t>(m.skeleton.channel_offset(j)), joint.channels.size());
      for (std::size_t i = 0; i < joint.channels.size(); ++i) {
        v[i] = is_rotation(joint.channels[i])
                   ? angle(rng)
                   : joint.offset[static_cast<int>(axis_of(joint.channels[i]))] + 0.1 * u(rng);
      }
    }
  }
  return m;
}

// Positions of every joint, every frame, frame-major, ordered by the joint
// names of `order` (so motions whose joints were reordered compare).
inline std::vector<Eigen::Vector3d> positions_by_name(const Motion& m, const Skeleton& order) {
  const auto all = compute_positions(m);
  const std::size_t n = m.skeleton.size(), k = order.size();
  std::vector<Eigen::Vector3d> out(m.frame_count * k, Eigen::Vector3d::Constant(1e300));
  for (std::size_t i = 0; i < k; ++i) {
    const int j = m.skeleton.find(order.joint(static_cast<int>(i)).name);
    if (j < 0) continue;
    for (std::size_t f = 0; f < m.frame_count; ++f) out[f * k + i] = all[f * n + static_cast<std::size_t>(j)];
  }
  return out;
}

// Largest difference of positions (by joint name) between two motions.
inline double position_error(const Motion& a, const Motion& b) {
  const auto pa = positions_by_name(a, a.skeleton);
  const auto pb = positions_by_name(b, a.skeleton);
  double e = 0.0;
  for (std::size_t i = 0; i < pa.size(); ++i) e = std::max(e, (pa[i] - pb[i]).norm());
  return pa.size() == pb.size() ? e : 1e300;
}

// Same joints (by name) with the same parents and soft links (by name), and
// per frame the same local rotation matrices and local offsets within `tol`.
inline ::testing::AssertionResult same_local_data(const Motion& a, const Motion& b, double rot_tol, double off_tol) {
  if (a.skeleton.size() != b.skeleton.size()) return ::testing::AssertionFailure() << "joint counts differ";
  if (a.frame_count != b.frame_count) return ::testing::AssertionFailure() << "frame counts differ";
  if (a.convention != b.convention) return ::testing::AssertionFailure() << "conventions differ";
  auto name_of = [](const Skeleton& s, int j) { return j == kNoParent ? std::string("-") : s.joint(j).name; };
  for (int ja = 0; ja < static_cast<int>(a.skeleton.size()); ++ja) {
    const Joint& x = a.skeleton.joint(ja);
    const int jb = b.skeleton.find(x.name);
    if (jb < 0) return ::testing::AssertionFailure() << "joint " << x.name << " missing";
    const Joint& y = b.skeleton.joint(jb);
    if (name_of(a.skeleton, x.parent) != name_of(b.skeleton, y.parent))
      return ::testing::AssertionFailure()
             << x.name << ": parent " << name_of(a.skeleton, x.parent) << " vs " << name_of(b.skeleton, y.parent);
    if (name_of(a.skeleton, x.soft_parent) != name_of(b.skeleton, y.soft_parent))
      return ::testing::AssertionFailure() << x.name << ": soft link differs";
    for (std::size_t f = 0; f < a.frame_count; ++f) {
      const double dr = (a.local_rotation(f, ja) - b.local_rotation(f, jb)).cwiseAbs().maxCoeff();
      const double dt = (a.local_offset(f, ja) - b.local_offset(f, jb)).norm();
      if (dr > rot_tol || dt > off_tol)
        return ::testing::AssertionFailure()
               << x.name << " frame " << f << ": rotation differs by " << dr << ", offset by " << dt;
    }
  }
  return ::testing::AssertionSuccess();
}

}  // namespace gmr::test
