// Pushed frames, encoded once per stream tick and shared by every subscriber.
//
// A Frame's per-subscriber fields (view_id, subscription_id, stream_id) have
// numbers 1..3; everything else (numbers >= 16) is the same for every
// subscriber of a stream. Protobuf parses concatenated encodings as one
// message, so a subscriber's bytes are a few varints followed by the shared
// body: the expensive part (positions) is encoded once.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "gmr/stream/v1/stream.pb.h"

namespace gmr::wire {

struct FrameContent {
  std::uint32_t skeleton_version = 0;
  std::uint64_t frame_index = 0;
  double motion_time = 0.0;
  std::uint64_t sequence = 0;
  std::int64_t server_send_time_ns = 0;
  std::span<const Eigen::Vector3d> positions;       // one per joint sent
  std::span<const Eigen::Quaterniond> orientations; // empty, or one per joint sent
  bool float64 = false;
};

// The shared body: serialized Frame fields >= 16.
std::string encode_frame_body(const FrameContent& content);

// A whole serialized ServerMessage{frame: Frame{ids + body}} (no length prefix).
std::string frame_message_for(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id,
                              std::string_view body);

// The bytes that go before a shared body of `body_size` bytes to make it a
// whole ServerMessage (with the TCP length prefix when `length_prefix`).
std::string frame_head_for(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id,
                           std::size_t body_size, bool length_prefix);

// Same as frame_message_for, with the TCP length prefix in front.
std::string framed_frame_message_for(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id,
                                     std::string_view body);

}  // namespace gmr::wire
