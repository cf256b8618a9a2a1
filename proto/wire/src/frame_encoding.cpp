#include "gmr/wire/frame_encoding.h"

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
  const int n = static_cast<int>(c.positions.size());
  if (c.float64) {
    auto* p = f.mutable_positions_f64();
    p->Reserve(3 * n);
    for (const auto& v : c.positions) { p->AddAlreadyReserved(v.x()); p->AddAlreadyReserved(v.y()); p->AddAlreadyReserved(v.z()); }
    auto* o = f.mutable_orientations_f64();
    o->Reserve(4 * static_cast<int>(c.orientations.size()));
    for (const auto& q : c.orientations) {
      o->AddAlreadyReserved(q.x()); o->AddAlreadyReserved(q.y()); o->AddAlreadyReserved(q.z()); o->AddAlreadyReserved(q.w());
    }
  } else {
    auto* p = f.mutable_positions();
    p->Reserve(3 * n);
    for (const auto& v : c.positions) {
      p->AddAlreadyReserved(static_cast<float>(v.x()));
      p->AddAlreadyReserved(static_cast<float>(v.y()));
      p->AddAlreadyReserved(static_cast<float>(v.z()));
    }
    auto* o = f.mutable_orientations();
    o->Reserve(4 * static_cast<int>(c.orientations.size()));
    for (const auto& q : c.orientations) {
      o->AddAlreadyReserved(static_cast<float>(q.x())); o->AddAlreadyReserved(static_cast<float>(q.y()));
      o->AddAlreadyReserved(static_cast<float>(q.z())); o->AddAlreadyReserved(static_cast<float>(q.w()));
    }
  }
  return f.SerializeAsString();
}

std::string frame_head_for(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id,
                           std::size_t body_size, bool length_prefix) {
  const std::string ids = frame_ids(view_id, subscription_id, stream_id);
  std::string head;
  put_varint(head, tag(pb::ServerMessage::kFrameFieldNumber, 2));
  put_varint(head, ids.size() + body_size);
  head += ids;
  if (!length_prefix) return head;
  std::string out(kLengthPrefixBytes, '\0');
  write_length_prefix(static_cast<std::uint32_t>(head.size() + body_size),
                      std::span<std::uint8_t, kLengthPrefixBytes>(reinterpret_cast<std::uint8_t*>(out.data()),
                                                                   kLengthPrefixBytes));
  return out + head;
}

std::string frame_message_for(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id,
                              std::string_view body) {
  const std::string ids = frame_ids(view_id, subscription_id, stream_id);
  std::string out;
  out.reserve(ids.size() + body.size() + 8);
  put_varint(out, tag(pb::ServerMessage::kFrameFieldNumber, 2));
  put_varint(out, ids.size() + body.size());
  out += ids;
  out.append(body);
  return out;
}

std::string framed_frame_message_for(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id,
                                     std::string_view body) {
  return frame_bytes(frame_message_for(view_id, subscription_id, stream_id, body));
}

}  // namespace gmr::wire
