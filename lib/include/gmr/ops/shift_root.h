// Shift root (paper 4.1.1): any joint becomes the root of its tree.
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

// Moves the root of the tree holding `joint` to `joint`, by repeated swaps of a
// root with one of its children along the path. Static offsets stay static
// (the old root gets the negated offset of the joint it now hangs under); the
// new root gets Xposition Yposition Zposition channels. A soft link of the old
// root moves to the new one. No-op when `joint` is already a root.
Result<Motion> shift_root(const Motion& motion, int joint);

}  // namespace gmr
