// Engine bones: one frame per joint, and each joint's rotation and
// translation relative to its parent's frame (what Unity, Unreal, Godot and
// Blender put on a bone). docs/protocol.md, "Local transforms and rest pose".
//
// GMR gives a frame to every bone: in pre-rotation a joint's rotation belongs
// to its incoming bone p(j) -> j, so W_j (what forward kinematics and the
// `orientations` field report) is the frame of the bone that ends at j, and
// siblings may have different frames. An engine wants one frame O_j per joint
// with
//
//   O_j = O_p Q_j        P_j = P_p + O_p T_j
//
// (Q_j, T_j: j's local rotation and translation; for a root, p is the output
// frame: world, or the viewer joint's frame). gmr takes as j's own frame the
// frame of one of its outgoing bones, that of the child with the largest
// subtree (the first in index order on a tie), and for a leaf the frame of its
// incoming bone:
//
//   O_j = W_c (c: that child of j)       O_leaf = W_leaf
//   Q_j = O_p^T O_j                      T_j = O_p^T (P_j - P_p)
//
// For a motion read from BVH or ASF/AMC every child of j has the same frame,
// the file's frame of j: T_j is then the file's offset of j (constant over the
// frames) and Q_j the file's rotation of j. Where a joint's outgoing bones have
// different frames (after a shift root, or a GMR file built so), the other
// children's T varies from frame to frame; positions stay exact either way. A
// post-rotation motion's W_j already is j's own frame (O_j = W_j).
//
// Computed from world positions and orientations already seen from the
// viewpoint and put in an engine's conventions (p' = s B p, W' = B W B^T), the
// locals come out in those conventions too: Q' = B Q B^T, T' = s B T.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <span>
#include <vector>

#include "gmr/motion/motion.h"
#include "gmr/view/conventions.h"

namespace gmr {

// For each joint, the joint whose W is its own frame O_j (the rule above).
std::vector<int> own_frame_sources(const Motion& motion);

// Q_j (as a unit quaternion) and T_j of each joint in `joints`, in that order,
// from every joint's `positions` and `orientations` (W, one per joint of the
// skeleton) of one frame. `sources` from own_frame_sources. Requires every
// span large enough and every index in range (asserted in debug builds).
void engine_locals(const Skeleton& skeleton, std::span<const int> sources, std::span<const Eigen::Vector3d> positions,
                   std::span<const Eigen::Matrix3d> orientations, std::span<const int> joints,
                   std::span<Eigen::Quaterniond> out_rotations, std::span<Eigen::Vector3d> out_translations);

// The rest (bind) pose in the engine form: the locals of the pose with every
// channel zero, in world coordinates and the conventions of `basis`. One
// entry per joint of the skeleton.
struct RestPose {
  std::vector<Eigen::Quaterniond> rotations;
  std::vector<Eigen::Vector3d> translations;
};
RestPose engine_rest_pose(const Motion& motion, const OutputBasis& basis = {});

}  // namespace gmr
