#include "gmr/acclaim/kinematics.h"

#include "acclaim_model.h"

namespace gmr {

using namespace acclaim_detail;

Eigen::Matrix3d acclaim_local_rotation(const AsfSkeleton& skeleton, const AmcMotion& motion, std::size_t frame, int b) {
  const Prepared prep = prepare(skeleton);
  return bone_state(skeleton.bones[static_cast<std::size_t>(b)], prep.c[static_cast<std::size_t>(b)],
                    bone_values(skeleton, motion, frame, b, prep), motion.degrees)
      .local;
}

void acclaim_compute_frame(const AsfSkeleton& skeleton, const AmcMotion& motion, std::size_t frame,
                           std::span<Eigen::Vector3d> out_positions, std::span<Eigen::Matrix3d> out_orientations) {
  assert(frame < motion.frame_count && out_positions.size() == skeleton.bones.size());
  std::vector<Eigen::Matrix3d> world;
  compute_frame_impl(skeleton, motion, frame, prepare(skeleton), world, out_positions, out_orientations);
}

std::vector<Eigen::Vector3d> acclaim_positions(const AsfSkeleton& skeleton, const AmcMotion& motion) {
  const std::size_t n = skeleton.bones.size();
  std::vector<Eigen::Vector3d> out(n * motion.frame_count);
  const Prepared prep = prepare(skeleton);
  std::vector<Eigen::Matrix3d> world;
  for (std::size_t f = 0; f < motion.frame_count; ++f) {
    compute_frame_impl(skeleton, motion, f, prep, world, std::span<Eigen::Vector3d>(out).subspan(f * n, n), {});
  }
  return out;
}

}  // namespace gmr
