// Split tree (paper 4.1.2): a joint becomes the root of a tree of its own.
// Like every operation in gmr/ops, it fails without touching its input for a
// post-rotation motion, an invalid one (Motion::validate) or a joint index
// out of range (ErrorKind::kNotFound). Results keep parents before children
// (joints may be reordered, stably); names never change. Computed rotations
// are stored as Euler channels (decompose_euler, continuous over frames).
// docs/operations.md has the details; docs/gmr-math.md the formulas.
#pragma once

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

// Promotes `joint` to a root with a soft link to its parent: its world
// orientation becomes its rotation channels and its world position its
// Xposition Yposition Zposition channels; its subtree is unchanged.
// Fails when `joint` is already a root.
Result<Motion> split_tree(const Motion& motion, int joint);

}  // namespace gmr
