// Exact removal of zero-length ("dummy") joints, and the converse report.
// Like every operation in gmr/ops, it fails without touching its input for a
// post-rotation motion, an invalid one (Motion::validate) or a joint index
// out of range (ErrorKind::kNotFound). Results keep parents before children
// (joints may be reordered, stably). Computed rotations
// are stored as Euler channels (decompose_euler, continuous over frames).
// docs/operations.md has the details; docs/gmr-math.md the formulas.
#pragma once

#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

// A joint that was merged into another at the same place.
struct RemovedJoint {
  std::string name;
  std::string merged_into;  // the name of the joint that stands for it now
};
// Merges each group of joints joined by zero-length bones (a child with an
// offset of exactly zero and no position channels) into one joint, whatever
// joints are the roots: the group's joint with the most bones (ties: the name
// that sorts first, bytewise) keeps its name, every other member goes. On
// CMU skeletons: Hips stays and LHipJoint, RHipJoint, LowerBack go, rooted at
// Hips or at Head alike. Exact: the group's top joint (nearest the root) is the
// one kept in the tree, under the chosen name; each removed joint's children
// c take R_d * R_c and its parent. A soft link to a removed joint moves to the
// kept one. Reports removed joints in index order.
Result<Motion> strip_dummies(const Motion& motion, std::vector<RemovedJoint>* out_removed = nullptr);

// The converse report: joints that have rotation channels whose local rotation
// is the same in every frame (within `tolerance_degrees` of frame 0), by name
// in index order. Any convention. Empty for a motion with no frames.
std::vector<std::string> constant_rotation_joints(const Motion& motion, double tolerance_degrees = 1e-9);

}  // namespace gmr
