// Join trees (paper 4.1.3): a split-off root goes back under its soft-link parent.
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

// What a join found about the offset it recovered.
struct JoinReport {
  double offset_spread = 0.0;         // largest distance of a frame's recovered offset from their mean
  bool translation_channels = false;  // true when the offset varied and became per-frame channels
};
// Demotes root `root` back under its soft-link parent P: per frame
// R = W_P^-1 W_root, t = W_root^-1 (P_root - P_P). When t is constant (spread
// at most 1e-9 x skeleton_size) it becomes the static offset (its mean);
// otherwise it becomes Xposition Yposition Zposition channels and
// translation_channels is set. Fails for a joint that is not a root, the last
// root of the skeleton, a root with no soft link, or one whose soft link
// points into its own tree.
Result<Motion> join_tree(const Motion& motion, int root, JoinReport* out_report = nullptr);

}  // namespace gmr
