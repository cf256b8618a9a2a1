// Exact removal of zero-length ("dummy") joints, and the converse report.
// Like every operation in gmr/ops, it fails without touching its input for a
// post-rotation motion, an invalid one (Motion::validate) or a joint index
// out of range (ErrorKind::kNotFound). Results keep parents before children
// (joints may be reordered, stably); names never change. Computed rotations
// are stored as Euler channels (decompose_euler, continuous over frames).
// docs/operations.md has the details; docs/gmr-math.md the formulas.
#pragma once

#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

// A zero-length joint that was removed.
struct RemovedJoint {
  std::string name;
  std::string parent;  // its parent's name
};
// Removes every joint d with an offset of exactly zero and no position
// channels that has a parent and children (CMU's LHipJoint, RHipJoint, ...):
// each child c takes R_d * R_c and d's parent. Roots and leaves are kept; a
// soft link to d moves to d's parent. Reports removed joints in index order.
Result<Motion> strip_dummies(const Motion& motion, std::vector<RemovedJoint>* out_removed = nullptr);

// The converse report: joints that have rotation channels whose local rotation
// is the same in every frame (within `tolerance_degrees` of frame 0), by name
// in index order. Any convention. Empty for a motion with no frames.
std::vector<std::string> constant_rotation_joints(const Motion& motion, double tolerance_degrees = 1e-9);

}  // namespace gmr
