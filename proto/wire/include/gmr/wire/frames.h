// Frames both ways: pushed frames encoded once per stream tick and shared by
// every subscriber (server), and pushed frames and query batches decoded into
// plain values (client).
//
// A Frame's per-subscriber fields (view_id, subscription_id, stream_id) have
// numbers 1..3; everything else (numbers >= 16) is the same for every
// subscriber of a stream. Protobuf parses concatenated encodings as one
// message, so a subscriber's bytes are a few varints followed by the shared
// body: the expensive part (positions) is encoded once. The head ends with
// the write stamp (field 4, 9 bytes of fixed size), filled in place as the
// frame leaves:
//
//   [length prefix] ServerMessage.frame tag+length | ids | write stamp | shared body
//   `-------------------- frame_head_for --------------------------'  (encoded once)
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/wire/frame_head.h"
#include "gmr/wire/frame_values.h"
#include "gmr/stream/v1/stream.pb.h"

namespace gmr::wire {

// What a stream tick sends. float32 frames carry `positions` (3 floats per
// joint) and `orientations` (4 per joint, x y z w, or empty); float64 frames
// the *_f64 spans instead.
struct FrameContent {
  std::uint32_t skeleton_version = 0;
  std::uint64_t frame_index = 0;
  double motion_time = 0.0;
  std::uint64_t sequence = 0;
  std::int64_t server_send_time_ns = 0;
  bool float64 = false;
  std::span<const float> positions;
  std::span<const float> orientations;
  std::span<const double> positions_f64;
  std::span<const double> orientations_f64;
  // Local transforms: 4 values (x y z w) and 3 per joint, or empty.
  std::span<const float> local_rotations;
  std::span<const float> local_translations;
  std::span<const double> local_rotations_f64;
  std::span<const double> local_translations_f64;
};

// The shared body: serialized Frame fields >= 16.
std::string encode_frame_body(const FrameContent& content);

// A whole serialized ServerMessage{frame: Frame{ids + write stamp + body}}
// (no length prefix), stamped `write_ns`.
std::string frame_message_for(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id,
                              std::string_view body, std::int64_t write_ns = 0);

// A packed list of floats or doubles where it lies: in a pb::Frame's
// RepeatedField, or in a message's bytes as they came (unaligned,
// little-endian, as protobuf writes them).
template <class T>
class Packed {
 public:
  Packed() = default;
  Packed(const void* data, std::size_t count) : data_(static_cast<const char*>(data)), count_(count) {}
  std::size_t size() const { return count_; }
  bool empty() const { return count_ == 0; }
  T Get(std::size_t i) const {
    T v;
    std::memcpy(&v, data_ + i * sizeof(T), sizeof(T));
    return v;
  }

 private:
  const char* data_ = nullptr;
  std::size_t count_ = 0;
};

// A pushed frame's fields, its lists where they lie (valid while the pb::Frame
// or the bytes they were read from are).
struct FrameFields {
  std::uint32_t view_id = 0;
  std::uint32_t subscription_id = 0;
  std::uint64_t stream_id = 0;
  std::int64_t server_write_time_ns = 0;
  std::uint32_t skeleton_version = 0;
  std::uint64_t frame_index = 0;
  double motion_time = 0.0;
  std::uint64_t sequence = 0;
  std::int64_t server_send_time_ns = 0;
  Packed<float> positions, orientations, local_rotations, local_translations;
  Packed<double> positions_f64, orientations_f64, local_rotations_f64, local_translations_f64;
};

FrameFields frame_fields(const stream::v1::Frame& frame);

// Reads a serialized ServerMessage holding a pushed frame and nothing else,
// as servers write them (frame_head_for and a body), without protobuf: true
// with `out` filled, with exactly the values protobuf would parse. False for
// anything else (another message, a request id beside the frame, a list
// written unpacked or in two pieces, a value protobuf would truncate, bytes
// that do not parse): parse those with protobuf, which decides.
bool read_frame_message(std::string_view message, FrameFields& out);

// The frame's values into `out`, reusing its lists' storage (a subscriber
// decodes every frame into the same FrameValues). Fails (kInvalidData) when
// the value counts do not form whole positions and quaternions, or the
// orientations or local transforms are neither absent nor one per position;
// `out` is then unspecified.
Status unpack_frame(const FrameFields& frame, FrameValues& out);

// A pushed frame as values, from whichever precision it carries; fails as
// unpack_frame.
Result<FrameValues> decode_frame(const stream::v1::Frame& frame);

// Whether two frames hold the same values bit for bit (NaNs too, and -0 is
// not 0): what two ways of decoding the same bytes must give.
bool same_bits(const FrameValues& a, const FrameValues& b);

// A query's frames as values: frame-major, joints.size() per frame.
struct DecodedBlock {
  std::uint32_t view_id = 0;
  std::uint32_t skeleton_version = 0;
  std::uint32_t begin = 0, end = 0;
  std::vector<int> joints;
  std::vector<Eigen::Vector3d> positions;
  std::vector<Eigen::Quaterniond> orientations;     // empty unless asked for
  std::vector<Eigen::Quaterniond> local_rotations;  // empty unless asked for
  std::vector<Eigen::Vector3d> local_translations;
};
// Fails (kInvalidData) when the counts do not match (end - begin) x joints.
Result<DecodedBlock> decode_block(const stream::v1::FrameBlock& batch);

}  // namespace gmr::wire
