// Reference forward kinematics, in double precision.
//
// This is the plain path every faster one is tested against. For each joint it
// gives the world position and the world orientation W_j:
//   post-rotation: W_j = W_p R_j,  P_j = P_p + W_p t_j  (W_j is the frame j's children hang in)
//   pre-rotation:  W_j = W_p R_j,  P_j = P_p + W_j t_j  (W_j is the frame of the bone p(j) -> j)
//   roots, both:   W_r = R_r,      P_r = t_r
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <span>
#include <vector>

#include "gmr/motion/motion.h"

namespace gmr {

// World positions (and, if out_orientations is not empty, orientations) of
// every joint in frame f. Both spans must have motion.skeleton.size() entries
// (orientations may be empty). Requires f < motion.frame_count.
void compute_frame(const Motion& motion, std::size_t f, std::span<Eigen::Vector3d> out_positions,
                   std::span<Eigen::Matrix3d> out_orientations = {});

// Positions of frames [begin, end), frame-major: result[(f - begin) * joints + j].
std::vector<Eigen::Vector3d> compute_positions(const Motion& motion, std::size_t begin, std::size_t end);

// Positions of every frame.
inline std::vector<Eigen::Vector3d> compute_positions(const Motion& motion) {
  return compute_positions(motion, 0, motion.frame_count);
}

// Largest distance between any joint and the first root over frame 0, at least
// 1e-9: the "size" used for relative tolerances in tests and tools.
double skeleton_size(const Motion& motion);

}  // namespace gmr
