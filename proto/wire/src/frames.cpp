#include "gmr/wire/frames.h"

#include "gmr/wire/framing.h"

namespace gmr::wire {
namespace pb = ::gmr::stream::v1;
namespace {

void put_varint(std::string& out, std::uint64_t v) {
  while (v >= 0x80) {
    out.push_back(static_cast<char>(static_cast<std::uint8_t>(v) | 0x80));
    v >>= 7;
  }
  out.push_back(static_cast<char>(v));
}

// Field tags: (number << 3) | wire type (0 varint, 2 length-delimited).
constexpr std::uint64_t tag(int number, int wire_type) { return (static_cast<std::uint64_t>(number) << 3) | wire_type; }

std::string frame_ids(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id) {
  std::string ids;
  ids.reserve(24);
  put_varint(ids, tag(pb::Frame::kViewIdFieldNumber, 0));
  put_varint(ids, view_id);
  put_varint(ids, tag(pb::Frame::kSubscriptionIdFieldNumber, 0));
  put_varint(ids, subscription_id);
  put_varint(ids, tag(pb::Frame::kStreamIdFieldNumber, 0));
  put_varint(ids, stream_id);
  return ids;
}

}  // namespace

std::string encode_frame_body(const FrameContent& c) {
  pb::Frame f;
  f.set_skeleton_version(c.skeleton_version);
  f.set_frame_index(c.frame_index);
  f.set_motion_time(c.motion_time);
  f.set_sequence(c.sequence);
  f.set_server_send_time_ns(c.server_send_time_ns);
  if (c.float64) {
    f.mutable_positions_f64()->Add(c.positions_f64.begin(), c.positions_f64.end());
    f.mutable_orientations_f64()->Add(c.orientations_f64.begin(), c.orientations_f64.end());
    f.mutable_local_rotations_f64()->Add(c.local_rotations_f64.begin(), c.local_rotations_f64.end());
    f.mutable_local_translations_f64()->Add(c.local_translations_f64.begin(), c.local_translations_f64.end());
  } else {
    f.mutable_positions()->Add(c.positions.begin(), c.positions.end());
    f.mutable_orientations()->Add(c.orientations.begin(), c.orientations.end());
    f.mutable_local_rotations()->Add(c.local_rotations.begin(), c.local_rotations.end());
    f.mutable_local_translations()->Add(c.local_translations.begin(), c.local_translations.end());
  }
  return f.SerializeAsString();
}

void set_write_stamp(char* value, std::int64_t ns) {
  auto v = static_cast<std::uint64_t>(ns);
  for (int i = 0; i < 8; ++i, v >>= 8) value[i] = static_cast<char>(v & 0xff);  // fixed64: little-endian
}

void set_write_stamp(std::string& head, std::int64_t ns) { set_write_stamp(head.data() + head.size() - 8, ns); }

std::string frame_head_for(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id,
                           std::size_t body_size, bool length_prefix) {
  static_assert(pb::Frame::kServerWriteTimeNsFieldNumber < 16, "the stamp's tag is one byte");
  std::string ids = frame_ids(view_id, subscription_id, stream_id);
  put_varint(ids, tag(pb::Frame::kServerWriteTimeNsFieldNumber, 1));  // 64-bit
  ids.append(8, '\0');
  std::string head;
  head.reserve(kLengthPrefixBytes + 12 + ids.size());
  if (length_prefix) head.resize(kLengthPrefixBytes);
  put_varint(head, tag(pb::ServerMessage::kFrameFieldNumber, 2));
  put_varint(head, ids.size() + body_size);
  head += ids;
  if (length_prefix) {
    write_length_prefix(
        static_cast<std::uint32_t>(head.size() - kLengthPrefixBytes + body_size),
        std::span<std::uint8_t, kLengthPrefixBytes>(reinterpret_cast<std::uint8_t*>(head.data()), kLengthPrefixBytes));
  }
  return head;
}

std::string frame_message_for(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id,
                              std::string_view body, std::int64_t write_ns) {
  std::string out = frame_head_for(view_id, subscription_id, stream_id, body.size(), false);
  set_write_stamp(out, write_ns);
  out.append(body);
  return out;
}

namespace {

template <class Values>
Status unpack(const Values& positions, const Values& orientations, std::vector<Eigen::Vector3d>& out_positions,
              std::vector<Eigen::Quaterniond>& out_orientations) {
  if (positions.size() % 3 != 0) {
    return make_error(ErrorKind::kInvalidData,
                      std::to_string(positions.size()) + " position values are not whole xyz triples");
  }
  const auto n = static_cast<std::size_t>(positions.size() / 3);
  if (!orientations.empty() && static_cast<std::size_t>(orientations.size()) != 4 * n) {
    return make_error(ErrorKind::kInvalidData, std::to_string(orientations.size()) + " orientation values for " +
                                                   std::to_string(n) + " positions (expected 0 or " +
                                                   std::to_string(4 * n) + ")");
  }
  out_positions.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const int k = static_cast<int>(3 * i);
    out_positions[i] = Eigen::Vector3d(positions.Get(k), positions.Get(k + 1), positions.Get(k + 2));
  }
  out_orientations.resize(orientations.empty() ? 0 : n);
  for (std::size_t i = 0; i < out_orientations.size(); ++i) {
    const int k = static_cast<int>(4 * i);
    // Eigen's constructor takes w first.
    out_orientations[i] = Eigen::Quaterniond(orientations.Get(k + 3), orientations.Get(k), orientations.Get(k + 1),
                                             orientations.Get(k + 2));
  }
  return Ok{};
}

// Local rotations (x y z w) and translations (x y z) of n joints, or none.
template <class Values>
Status unpack_locals(const Values& rotations, const Values& translations, std::size_t n,
                     std::vector<Eigen::Quaterniond>& out_rotations, std::vector<Eigen::Vector3d>& out_translations) {
  if (rotations.empty() && translations.empty()) {
    out_rotations.clear();
    out_translations.clear();
    return Ok{};
  }
  if (static_cast<std::size_t>(rotations.size()) != 4 * n || static_cast<std::size_t>(translations.size()) != 3 * n) {
    return make_error(ErrorKind::kInvalidData,
                      std::to_string(rotations.size()) + " local rotation and " + std::to_string(translations.size()) +
                          " local translation values for " + std::to_string(n) + " positions (expected 0 and 0, or " +
                          std::to_string(4 * n) + " and " + std::to_string(3 * n) + ")");
  }
  out_rotations.resize(n);
  out_translations.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const int k = static_cast<int>(4 * i), t = static_cast<int>(3 * i);
    out_rotations[i] =
        Eigen::Quaterniond(rotations.Get(k + 3), rotations.Get(k), rotations.Get(k + 1), rotations.Get(k + 2));
    out_translations[i] = Eigen::Vector3d(translations.Get(t), translations.Get(t + 1), translations.Get(t + 2));
  }
  return Ok{};
}

}  // namespace

Result<FrameValues> decode_frame(const pb::Frame& f) {
  FrameValues d;
  d.view_id = f.view_id();
  d.subscription_id = f.subscription_id();
  d.stream_id = f.stream_id();
  d.skeleton_version = f.skeleton_version();
  d.frame_index = f.frame_index();
  d.motion_time = f.motion_time();
  d.sequence = f.sequence();
  d.server_send_time_ns = f.server_send_time_ns();
  d.server_write_time_ns = f.server_write_time_ns();
  d.float64 = f.positions_f64_size() > 0;
  Status s = d.float64 ? unpack(f.positions_f64(), f.orientations_f64(), d.positions, d.orientations)
                       : unpack(f.positions(), f.orientations(), d.positions, d.orientations);
  if (s.ok()) {
    s = d.float64 ? unpack_locals(f.local_rotations_f64(), f.local_translations_f64(), d.positions.size(),
                                  d.local_rotations, d.local_translations)
                  : unpack_locals(f.local_rotations(), f.local_translations(), d.positions.size(), d.local_rotations,
                                  d.local_translations);
  }
  if (!s.ok())
    return make_error(ErrorKind::kInvalidData, "frame " + std::to_string(d.frame_index) + ": " + s.error().message);
  return d;
}

Result<DecodedBlock> decode_block(const pb::FrameBlock& b) {
  DecodedBlock d;
  d.view_id = b.view_id();
  d.skeleton_version = b.skeleton_version();
  d.begin = b.begin();
  d.end = b.end();
  d.joints.assign(b.joints().begin(), b.joints().end());
  if (auto s = unpack(b.positions(), b.orientations(), d.positions, d.orientations); !s.ok()) return s.error();
  if (auto s = unpack_locals(b.local_rotations(), b.local_translations(), d.positions.size(), d.local_rotations,
                             d.local_translations);
      !s.ok()) {
    return s.error();
  }
  const std::uint64_t frames = d.end >= d.begin ? d.end - d.begin : 0;
  if (d.end < d.begin || d.positions.size() != frames * d.joints.size()) {
    return make_error(ErrorKind::kInvalidData, std::to_string(d.positions.size()) + " positions for frames [" +
                                                   std::to_string(d.begin) + ", " + std::to_string(d.end) + ") of " +
                                                   std::to_string(d.joints.size()) + " joints");
  }
  return d;
}

}  // namespace gmr::wire
