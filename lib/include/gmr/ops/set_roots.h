// Any set of roots: joins, shifts and splits to reach exactly that set.
// Like every operation in gmr/ops, it fails without touching its input for a
// post-rotation motion, an invalid one (Motion::validate) or a joint index
// out of range (ErrorKind::kNotFound). Results keep parents before children
// (joints may be reordered, stably); names never change. Computed rotations
// are stored as Euler channels (decompose_euler, continuous over frames).
// docs/operations.md has the details; docs/gmr-math.md the formulas.
#pragma once

#include <span>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

// Moves from the current roots to exactly the roots `roots`: joins every
// soft-linked root back, keeps the root of each tree when it is in the set and
// otherwise moves it (shift) to the joint of the set nearest to it (ties:
// smallest name), then splits at every other joint of the set. World
// positions never depend on the path. Local data depend only on the connected
// skeleton, its tree roots after the joins, and the set: any configuration
// reached from a motion by set_roots with sets that contain its roots (or by
// splits and joins) gives the same result as set_roots on the motion itself,
// and set_roots back to the original roots restores the original local data.
// Fails for an empty set, a joint listed twice, a connected skeleton (hard
// edges and soft links) with no joint in the set, or soft links that form a
// cycle.
Result<Motion> set_roots(const Motion& motion, std::span<const int> roots);

}  // namespace gmr
