#include "gmr/kinematics/forward_kinematics.h"

#include <algorithm>
#include <cassert>

namespace gmr {

void compute_frame(const Motion& motion, std::size_t f, std::span<Eigen::Vector3d> out_positions,
                   std::span<Eigen::Matrix3d> out_orientations) {
  const Skeleton& s = motion.skeleton;
  const int n = static_cast<int>(s.size());
  assert(f < motion.frame_count);
  assert(out_positions.size() == s.size());
  assert(out_orientations.empty() || out_orientations.size() == s.size());

  // Orientations are needed for every parent even when the caller wants none.
  std::vector<Eigen::Matrix3d> local_world;
  std::span<Eigen::Matrix3d> world = out_orientations;
  if (world.empty()) {
    local_world.resize(s.size());
    world = local_world;
  }
  const bool pre = motion.convention == Convention::kPreRotation;
  for (int j = 0; j < n; ++j) {
    const Eigen::Matrix3d r = motion.local_rotation(f, j);
    const Eigen::Vector3d t = motion.local_offset(f, j);
    const int p = s.joint(j).parent;
    if (p == kNoParent) {
      world[j] = r;
      out_positions[j] = t;
    } else {
      world[j] = world[p] * r;
      out_positions[j] = out_positions[p] + (pre ? world[j] : world[p]) * t;
    }
  }
}

std::vector<Eigen::Vector3d> compute_positions(const Motion& motion, std::size_t begin, std::size_t end) {
  const std::size_t n = motion.skeleton.size();
  end = std::min(end, motion.frame_count);
  begin = std::min(begin, end);
  std::vector<Eigen::Vector3d> out((end - begin) * n);
  std::vector<Eigen::Matrix3d> world(n);
  for (std::size_t f = begin; f < end; ++f) {
    compute_frame(motion, f, std::span<Eigen::Vector3d>(out).subspan((f - begin) * n, n), world);
  }
  return out;
}

double skeleton_size(const Motion& motion) {
  double size = 1e-9;
  if (motion.frame_count == 0 || motion.skeleton.empty()) return size;
  std::vector<Eigen::Vector3d> p(motion.skeleton.size());
  compute_frame(motion, 0, p);
  for (const auto& q : p) size = std::max(size, (q - p[0]).norm());
  return size;
}

}  // namespace gmr
