// The intrinsic viewpoint: a motion seen from one of its joints (paper
// section 1; docs/gmr-math.md, "The intrinsic viewpoint"). With P_v, W_v the viewer's world
// position and orientation in the same frame,
//
//   p' = W_v^T (p - P_v)      W' = W_v^T W
//
// for every joint's world position p and orientation W. The viewer itself is
// at the origin with the identity orientation. This is the one place the
// formula is written: the CLI (`gmr positions --relative-to`), the server's
// queries and streams (double and float) all go through it.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <span>

#include "gmr/motion/motion.h"
#include "gmr/view/conventions.h"

namespace gmr {

class Viewpoint {
 public:
  // World coordinates: positions and orientations pass through unchanged.
  Viewpoint() = default;
  // Seen from a joint at `origin` with world orientation `orientation`.
  Viewpoint(const Eigen::Vector3d& origin, const Eigen::Matrix3d& orientation);
  // Seen from joint v of float forward-kinematics output (gmr::fast): 3
  // floats per joint position, 9 per orientation (row-major). Requires v to
  // index both.
  static Viewpoint of_joint(std::span<const float> positions, std::span<const float> orientations, std::size_t v);

  bool is_world() const { return world_; }
  // p' = W_v^T (p - P_v); p itself in world coordinates.
  Eigen::Vector3d position(const Eigen::Vector3d& p) const { return world_ ? p : Eigen::Vector3d(rt_ * (p - origin_)); }
  // W' = W_v^T W; W itself in world coordinates.
  Eigen::Matrix3d orientation(const Eigen::Matrix3d& w) const { return world_ ? w : Eigen::Matrix3d(rt_ * w); }

 private:
  bool world_ = true;
  Eigen::Matrix3d rt_ = Eigen::Matrix3d::Identity();  // W_v^T
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();  // P_v
};

// The double (reference) path. Positions and, when out_orientations is not
// empty, world orientations of every joint of frame f, seen from joint
// `viewer` (-1: world coordinates), by compute_frame. Both spans hold
// motion.skeleton.size() entries; a view from a joint needs out_orientations
// (the viewer's frame comes from it), a world view may leave it empty.
// Requires f < motion.frame_count and viewer < motion.skeleton.size().
// Last, `basis` puts the result in an engine's conventions (conventions.h).
void view_frame(const Motion& motion, int viewer, std::size_t f, std::span<Eigen::Vector3d> out_positions,
                std::span<Eigen::Matrix3d> out_orientations = {}, const OutputBasis& basis = {});

// The float path, after gmr::fast::FkFrameJob: `fk_positions` (3 floats per
// joint) and `fk_orientations` (9 per joint, row-major; may be empty for a
// world view without orientations) seen from joint `viewer` (-1: world), for
// the joints `joints` in that order: out_positions gets 3 floats per listed
// joint, out_quaternions (when not empty) 4 per listed joint (x, y, z, w).
// The viewpoint and the quaternions are computed in double from the float
// inputs and rounded once, so only storage is float. Requires every span to
// be large enough and every index in range (asserted in debug builds).
// `basis` as for view_frame.
void view_frame_float(std::span<const float> fk_positions, std::span<const float> fk_orientations, int viewer,
                      std::span<const int> joints, std::span<float> out_positions, std::span<float> out_quaternions,
                      const OutputBasis& basis = {});

}  // namespace gmr
