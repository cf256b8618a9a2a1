// Shared by the libFuzzer harnesses: what to do with a motion a reader
// accepted (exercise what users do next), and a check that aborts, so the
// fuzzer records the input, when a documented property fails.
#pragma once

#include <Eigen/Core>
#include <cstdio>
#include <cstdlib>
#include <string_view>
#include <vector>

#include "gmr/motion/motion.h"
#include "gmr/ops/convert.h"
#include "gmr/view/viewpoint.h"

namespace gmr::fuzz {

inline void require(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "property failed: %s\n", what);
    std::abort();
  }
}

// The first and last frame's positions, in the motion's own convention and
// converted to pre-rotation (what the server serves).
inline void exercise(const Motion& m) {
  require(m.validate().ok(), "a motion a reader returns is valid");
  if (m.frame_count == 0 || m.skeleton.empty()) return;
  std::vector<Eigen::Vector3d> pos(m.skeleton.size());
  std::vector<Eigen::Matrix3d> rot(m.skeleton.size());
  view_frame(m, -1, 0, pos, rot);
  view_frame(m, -1, m.frame_count - 1, pos, rot);
  if (auto pre = to_pre_rotation(m); pre.ok()) {
    view_frame(*pre, 0, pre->frame_count - 1, pos, rot);
  }
}

}  // namespace gmr::fuzz
