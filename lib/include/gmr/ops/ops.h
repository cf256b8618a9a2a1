// The GMR operations on a whole motion (every frame), paper section 4.1 with
// the primes restored in ../shared/GMR-MATH.md. Every operation keeps every
// joint's world position in every frame. They take and return pre-rotation
// motions (a post-rotation one is an error: convert it with to_pre_rotation).
// Joints are named by index; joint names never change.
#pragma once

#include <span>
#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

// Moves the root of the tree holding `joint` to `joint`, by repeated swaps of a
// root with one of its children along the path. Static offsets stay static.
// No-op when `joint` is already a root.
Result<Motion> shift_root(const Motion& motion, int joint);

// Promotes `joint` (not a root) to a root with a soft link to its parent.
Result<Motion> split_tree(const Motion& motion, int joint);

// What a join found about the offset it recovered.
struct JoinReport {
  double offset_spread = 0.0;      // largest distance of a frame's recovered offset from their mean
  bool translation_channels = false;  // true when the offset varied and became per-frame channels
};
// Demotes root `root` back under its soft-link parent. Fails for the last root
// of the skeleton, a joint that is not a root, or a root with no soft link.
Result<Motion> join_tree(const Motion& motion, int root, JoinReport* out_report = nullptr);

// Moves from the current roots to exactly the roots `roots` (any non-empty set
// of joints that keeps at least one root per original connected skeleton),
// by a sequence of shift, split and join. The result does not depend on the path.
Result<Motion> set_roots(const Motion& motion, std::span<const int> roots);

// A zero-length joint that was removed.
struct RemovedJoint {
  std::string name;
  std::string parent;  // its parent's name
};
// Removes every joint d with a zero offset (and no position channels) that has
// a parent: each child c takes R_d * R_c. Roots and leaves are kept.
Result<Motion> strip_dummies(const Motion& motion, std::vector<RemovedJoint>* out_removed = nullptr);

// Joints whose local rotation is the same in every frame (within `tolerance`
// degrees), by name: candidates for a static bone.
std::vector<std::string> constant_rotation_joints(const Motion& motion, double tolerance_degrees = 1e-9);

// The intrinsic viewpoint: positions (and orientations, if requested) of every
// joint in the frame of joint `viewer`, for frames [begin, end), frame-major:
//   p' = W_v^T (p - P_v),  W' = W_v^T W
void intrinsic_positions(const Motion& motion, int viewer, std::size_t begin, std::size_t end,
                         std::vector<Eigen::Vector3d>& out_positions,
                         std::vector<Eigen::Matrix3d>* out_orientations = nullptr);

}  // namespace gmr
