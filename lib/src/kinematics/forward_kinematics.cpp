#include "gmr/kinematics/forward_kinematics.h"

#include <algorithm>
#include <cassert>

#include "kinematics/fk_stats.h"

namespace gmr {
namespace {

thread_local std::uint64_t t_rotation_evaluations = 0;

// One frame. `world` is scratch (or the caller's output when want_orientations).
// A joint's rotation is evaluated only when something reads it:
//   - the caller asked for orientations, or
//   - the joint has children (their frames and positions hang on W_j), or
//   - pre-rotation and the joint is not a root (P_j = P_p + W_j t_j).
// So a pre-rotation root with no children (every joint of the fully
// translational configuration) is read, not computed: P = t_root.
void frame_impl(const Motion& motion, std::size_t f, std::span<Eigen::Vector3d> out_positions,
                std::span<Eigen::Matrix3d> world, bool want_orientations) {
  const Skeleton& s = motion.skeleton;
  const int n = static_cast<int>(s.size());
  const bool pre = motion.convention == Convention::kPreRotation;
  std::uint64_t evaluations = 0;
  for (int j = 0; j < n; ++j) {
    const int p = s.joint(j).parent;
    const Eigen::Vector3d t = motion.local_offset(f, j);
    const bool need_rotation = want_orientations || !s.children(j).empty() || (pre && p != kNoParent);
    if (need_rotation) {
      ++evaluations;
      const Eigen::Matrix3d r = motion.local_rotation(f, j);
      world[j] = p == kNoParent ? r : Eigen::Matrix3d(world[p] * r);
    }
    if (p == kNoParent) {
      out_positions[j] = t;
    } else {
      out_positions[j] = out_positions[p] + (pre ? world[j] : world[p]) * t;
    }
  }
  t_rotation_evaluations += evaluations;
}

}  // namespace

std::uint64_t fk_rotation_evaluations() { return t_rotation_evaluations; }
void reset_fk_rotation_evaluations() { t_rotation_evaluations = 0; }

void compute_frame(const Motion& motion, std::size_t f, std::span<Eigen::Vector3d> out_positions,
                   std::span<Eigen::Matrix3d> out_orientations) {
  const Skeleton& s = motion.skeleton;
  assert(f < motion.frame_count);
  assert(out_positions.size() == s.size());
  assert(out_orientations.empty() || out_orientations.size() == s.size());
  if (!out_orientations.empty()) {
    frame_impl(motion, f, out_positions, out_orientations, true);
    return;
  }
  std::vector<Eigen::Matrix3d> scratch(s.size());
  frame_impl(motion, f, out_positions, scratch, false);
}

std::vector<Eigen::Vector3d> compute_positions(const Motion& motion, std::size_t begin, std::size_t end) {
  const std::size_t n = motion.skeleton.size();
  end = std::min(end, motion.frame_count);
  begin = std::min(begin, end);
  std::vector<Eigen::Vector3d> out((end - begin) * n);
  std::vector<Eigen::Matrix3d> world(n);
  for (std::size_t f = begin; f < end; ++f) {
    frame_impl(motion, f, std::span<Eigen::Vector3d>(out).subspan((f - begin) * n, n), world, false);
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
