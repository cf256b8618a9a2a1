// A pushed frame as plain values: what gmr::wire decodes a Frame into and
// what the C++ client hands to its callbacks. No protobuf types, so the
// client's public header can include it.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

namespace gmr::wire {

struct FrameValues {
  std::uint32_t view_id = 0;
  std::uint32_t subscription_id = 0;
  std::uint64_t stream_id = 0;
  std::uint32_t skeleton_version = 0;
  std::uint64_t frame_index = 0;
  double motion_time = 0.0;
  std::uint64_t sequence = 0;
  std::int64_t server_send_time_ns = 0;          // at encoding (system_clock ns)
  std::int64_t server_write_time_ns = 0;         // when it was handed to the kernel (0: not stamped)
  bool float64 = false;                          // the precision it travelled in
  std::vector<Eigen::Vector3d> positions;        // one per joint sent
  std::vector<Eigen::Quaterniond> orientations;  // empty, or one per joint sent
  // Local transforms (relative to the parent's frame), when subscribed: empty,
  // or one per joint sent.
  std::vector<Eigen::Quaterniond> local_rotations;
  std::vector<Eigen::Vector3d> local_translations;
};

}  // namespace gmr::wire
