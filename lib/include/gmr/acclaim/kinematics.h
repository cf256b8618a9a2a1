// Forward kinematics of the Acclaim model itself.
//
// The Acclaim model (CMU mocap semantics, as in CMU's mocapPlayer and the
// amc_parser conventions), for a bone b with parent p:
//
//   C_b  = axis rotation: the `axis a b c ORDER` values are the x, y, z angles;
//          they are applied in ORDER ("XYZ": first about x), so C = Rz*Ry*Rx.
//   M_b  = the dof rotations in `dof` order, applied first to last
//          ("dof rx ry rz" gives M = Rz*Ry*Rx; "dof rz rx" gives M = Rx*Rz).
//   L_b  = C_b * M_b * C_b^-1            (local rotation)
//   W_b  = W_p * L_b                      (world rotation; W_root = L_root)
//   tip_b = tip_p + W_p * C_b * t_b + W_b * direction_b * (length_b + l_b)
//
// where t_b = (tx, ty, tz) dof values (0 when absent; a translation in the
// bone's axis frame, not rotated by M_b) and l_b the `l` dof (0 when absent;
// added to the length). The root: C_root from `orientation` (in the root's
// `axis` order), M_root from the RX/RY/RZ entries of `order` (in that order),
// and its position = `position` + (TX, TY, TZ) in world axes.
//
// Directions are global (rest pose) and used as written (not normalised).
// Lengths and translations are in file units (`units length` is recorded but
// not applied: for CMU files, 1 unit = (1/0.45) inch = 5.644 cm, and CMU's BVH
// conversions use the same units, scale 1). Angles follow `units angle` in
// the ASF and :DEGREES / :RADIANS in the AMC (default: the ASF's unit).
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <span>
#include <vector>

#include "gmr/acclaim/amc.h"
#include "gmr/acclaim/asf.h"

namespace gmr {

// Local rotation L_b = C_b M_b C_b^-1 of bone b for one frame's AMC values.
Eigen::Matrix3d acclaim_local_rotation(const AsfSkeleton& skeleton, const AmcMotion& motion, std::size_t frame, int b);

// Forward kinematics of the Acclaim model (double): for every bone, the
// position of its tip (the root: its position) and, if out_orientations is not
// empty, its world rotation W_b. Both spans have skeleton.bones.size() entries.
// Requires frame < motion.frame_count.
void acclaim_compute_frame(const AsfSkeleton& skeleton, const AmcMotion& motion, std::size_t frame,
                           std::span<Eigen::Vector3d> out_positions, std::span<Eigen::Matrix3d> out_orientations = {});
// Positions of every frame, frame-major (bones.size() per frame).
std::vector<Eigen::Vector3d> acclaim_positions(const AsfSkeleton& skeleton, const AmcMotion& motion);

}  // namespace gmr
