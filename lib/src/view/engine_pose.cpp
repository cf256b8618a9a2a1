#include "gmr/view/engine_pose.h"

#include <cassert>

#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/view/viewpoint.h"

namespace gmr {

std::vector<int> own_frame_sources(const Motion& motion) {
  const Skeleton& s = motion.skeleton;
  const auto n = static_cast<int>(s.size());
  std::vector<int> sources(s.size());
  for (int j = 0; j < n; ++j) sources[static_cast<std::size_t>(j)] = j;
  if (motion.convention != Convention::kPreRotation) return sources;
  // Subtree sizes: children come after their parents, so one backward pass.
  std::vector<int> subtree(s.size(), 1);
  for (int j = n - 1; j >= 0; --j) {
    const int p = s.joint(j).parent;
    if (p != kNoParent) subtree[static_cast<std::size_t>(p)] += subtree[static_cast<std::size_t>(j)];
  }
  for (int j = 0; j < n; ++j) {
    int best = -1;
    for (int c : s.children(j)) {
      if (best < 0 || subtree[static_cast<std::size_t>(c)] > subtree[static_cast<std::size_t>(best)]) best = c;
    }
    if (best >= 0) sources[static_cast<std::size_t>(j)] = best;
  }
  return sources;
}

void engine_locals(const Skeleton& skeleton, std::span<const int> sources, std::span<const Eigen::Vector3d> positions,
                   std::span<const Eigen::Matrix3d> orientations, std::span<const int> joints,
                   std::span<Eigen::Quaterniond> out_rotations, std::span<Eigen::Vector3d> out_translations) {
  assert(sources.size() == skeleton.size() && positions.size() == skeleton.size());
  assert(orientations.size() == skeleton.size());
  assert(out_rotations.size() >= joints.size() && out_translations.size() >= joints.size());
  for (std::size_t i = 0; i < joints.size(); ++i) {
    const int j = joints[i];
    const Eigen::Matrix3d& own = orientations[static_cast<std::size_t>(sources[static_cast<std::size_t>(j)])];
    const int p = skeleton.joint(j).parent;
    if (p == kNoParent) {
      out_rotations[i] = Eigen::Quaterniond(own);
      out_translations[i] = positions[static_cast<std::size_t>(j)];
      continue;
    }
    const Eigen::Matrix3d& parent = orientations[static_cast<std::size_t>(sources[static_cast<std::size_t>(p)])];
    out_rotations[i] = Eigen::Quaterniond(Eigen::Matrix3d(parent.transpose() * own));
    out_translations[i] =
        parent.transpose() * (positions[static_cast<std::size_t>(j)] - positions[static_cast<std::size_t>(p)]);
  }
}

RestPose engine_rest_pose(const Motion& motion, const OutputBasis& basis) {
  const std::size_t n = motion.skeleton.size();
  Motion rest;
  rest.skeleton = motion.skeleton;
  rest.convention = motion.convention;
  rest.frame_time = motion.frame_time;
  rest.frame_count = 1;
  rest.values.assign(motion.stride(), 0.0);
  std::vector<Eigen::Vector3d> positions(n);
  std::vector<Eigen::Matrix3d> orientations(n);
  view_frame(rest, -1, 0, positions, orientations, basis);
  std::vector<int> all(n);
  for (std::size_t j = 0; j < n; ++j) all[j] = static_cast<int>(j);
  RestPose out;
  out.rotations.resize(n);
  out.translations.resize(n);
  engine_locals(motion.skeleton, own_frame_sources(motion), positions, orientations, all, out.rotations,
                out.translations);
  return out;
}

}  // namespace gmr
