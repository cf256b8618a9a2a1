// A motion: a skeleton, a frame time, and every frame's channel values.
//
// Two local-transform conventions live side by side (see docs/gmr-format.md):
//
//   post-rotation (BVH, ASF/AMC):  L_j = [R_j | t_j]       j's rotation moves its children
//   pre-rotation  (GMR):           L_j = [R_j | R_j t_j]   j's rotation moves j itself
//
// For both, a root's world transform is [R_root | t_root]: its (effective)
// offset is its world position, the G_r of the paper.
// t_j is the joint's effective offset: its static OFFSET with each component
// that has a position channel replaced by that channel's value.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/skeleton/skeleton.h"

namespace gmr {

enum class Convention : std::uint8_t {
  kPostRotation,  // BVH and ASF/AMC as they are in their files
  kPreRotation,   // GMR
};

struct Motion {
  Skeleton skeleton;
  Convention convention = Convention::kPreRotation;
  double frame_time = 0.0;  // seconds per frame; 0 when unknown
  std::size_t frame_count = 0;
  std::vector<double> values;  // frame-major: values[f * stride() + c]

  std::size_t stride() const { return static_cast<std::size_t>(skeleton.channel_count()); }
  std::span<const double> frame(std::size_t f) const {
    return std::span<const double>(values).subspan(f * stride(), stride());
  }
  std::span<double> frame(std::size_t f) { return std::span<double>(values).subspan(f * stride(), stride()); }

  // Channel values of joint j in frame f (same order as its channels).
  std::span<const double> joint_values(std::size_t f, int j) const {
    return frame(f).subspan(static_cast<std::size_t>(skeleton.channel_offset(j)), skeleton.joint(j).channels.size());
  }

  // R_j of frame f: j's rotation channels composed in listed order (degrees).
  Eigen::Matrix3d local_rotation(std::size_t f, int j) const;
  // t_j of frame f: j's offset with its position channels substituted.
  Eigen::Vector3d local_offset(std::size_t f, int j) const;

  // Checks that values has frame_count * stride() finite entries and that
  // frame_time is finite and not negative.
  Status validate() const;

  double duration() const { return frame_time * static_cast<double>(frame_count); }
};

}  // namespace gmr
