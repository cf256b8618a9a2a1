// A view of a motion: which joints are roots, whether dummy joints are
// removed, and whose frame the positions are given in (gmr/view/viewpoint.h).
// `gmr positions` builds one from a ViewSpec; the server's per-client views
// are edited step by step but compute frames with the same view_frame.
//
//   source (BVH or GMR) --to_pre_rotation--> set_roots --> strip_dummies --> MotionView
//   view_positions(MotionView): world positions, or p' = W_v^T (p - P_v) with --relative-to
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"
#include "gmr/ops/strip_dummies.h"

namespace gmr {

struct ViewSpec {
  std::vector<std::string> roots;  // joint names to be the roots; empty: keep the source's roots
  bool strip_dummies = false;      // remove zero-length joints (strip_dummies) after setting roots
  std::string relative_to;         // joint whose frame positions are given in; empty: world
};

struct MotionView {
  Motion motion;                      // pre-rotation, with the roots set and dummies removed
  int viewer = -1;                    // index of relative_to in motion.skeleton; -1: world coordinates
  std::vector<RemovedJoint> removed;  // what strip_dummies removed
  std::vector<int> order;             // joints of `motion` in the source's joint order (removed ones left out)
};

// Builds the view. Fails with a one-line reason for: an unknown joint name (in
// roots or relative_to; a relative_to joint that strip_dummies removed is
// named as such), a joint listed twice, a root set that leaves a connected
// skeleton without a root, or an invalid source motion.
Result<MotionView> apply_view(const Motion& source, const ViewSpec& spec);

// Positions of frames [begin, end) (clamped), frame-major with
// view.order.size() joints per frame in view.order: world coordinates, or in
// the viewer's frame when view.viewer >= 0.
std::vector<Eigen::Vector3d> view_positions(const MotionView& view, std::size_t begin, std::size_t end);

// The joint names of view_positions() rows as a skeleton of unlinked joints,
// for write_positions_csv_rows().
Skeleton view_names(const MotionView& view);

}  // namespace gmr
