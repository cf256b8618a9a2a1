#include "gmr/wire/frames.h"

#include <algorithm>
#include <bit>
#include <cstring>

#include "gmr/wire/framing.h"

namespace gmr::wire {
namespace pb = ::gmr::stream::v1;
namespace {

// Appends `v` as a varint at `out`; returns the end.
char* put_varint(char* out, std::uint64_t v) {
  while (v >= 0x80) {
    *out++ = static_cast<char>(static_cast<std::uint8_t>(v) | 0x80);
    v >>= 7;
  }
  *out++ = static_cast<char>(v);
  return out;
}

std::size_t varint_size(std::uint64_t v) {
  std::size_t n = 1;
  for (; v >= 0x80; v >>= 7) ++n;
  return n;
}

// Field tags: (number << 3) | wire type (0 varint, 1 64-bit, 2 length-delimited).
constexpr std::uint64_t tag(int number, int wire_type) { return (static_cast<std::uint64_t>(number) << 3) | wire_type; }

}  // namespace

namespace {

// The body's fields as protobuf writes them (by field number; zeros and empty
// lists left out; packed lists little-endian), at `out`, which has room for
// max_body_size(): a frame is encoded per stream tick, and building a
// pb::Frame to serialize it copies every value and allocates three times.
// One pass: the room is a bound, not a count (a count is a second pass).
class BodyWriter {
 public:
  explicit BodyWriter(char* out) : p_(out) {}
  char* end() const { return p_; }

  void varint_field(int number, std::uint64_t v) {
    if (v == 0) return;
    p_ = put_varint(p_, tag(number, 0));
    p_ = put_varint(p_, v);
  }
  void double_field(int number, double v) {
    std::uint64_t raw = 0;
    std::memcpy(&raw, &v, sizeof raw);
    if (raw == 0) return;  // +0.0 only, as protobuf
    p_ = put_varint(p_, tag(number, 1));
    std::memcpy(p_, &raw, sizeof raw);
    p_ += sizeof raw;
  }
  template <class T>
  void packed_field(int number, std::span<const T> v) {
    if (v.empty()) return;
    p_ = put_varint(p_, tag(number, 2));
    p_ = put_varint(p_, v.size_bytes());
    std::memcpy(p_, v.data(), v.size_bytes());
    p_ += v.size_bytes();
  }

 private:
  char* p_;
};

// Room for any body of `c`: each tag and varint at its widest.
std::size_t max_body_size(const FrameContent& c) {
  constexpr std::size_t kTag = 5, kVarint = 10;  // a field number's tag is a varint32
  std::size_t n = 5 * (kTag + kVarint) + kTag + sizeof(double);
  const auto packed = [&](auto span) { n += span.empty() ? 0 : kTag + kVarint + span.size_bytes(); };
  if (c.float64) {
    packed(c.positions_f64);
    packed(c.orientations_f64);
    packed(c.local_rotations_f64);
    packed(c.local_translations_f64);
  } else {
    packed(c.positions);
    packed(c.orientations);
    packed(c.local_rotations);
    packed(c.local_translations);
  }
  return n;
}

void write_body(BodyWriter& w, const FrameContent& c) {
  static_assert(std::endian::native == std::endian::little, "packed floats are copied as they are in memory");
  w.varint_field(pb::Frame::kSkeletonVersionFieldNumber, c.skeleton_version);
  w.varint_field(pb::Frame::kFrameIndexFieldNumber, c.frame_index);
  w.double_field(pb::Frame::kMotionTimeFieldNumber, c.motion_time);
  w.varint_field(pb::Frame::kSequenceFieldNumber, c.sequence);
  w.varint_field(pb::Frame::kServerSendTimeNsFieldNumber, static_cast<std::uint64_t>(c.server_send_time_ns));
  if (c.float64) {
    w.packed_field(pb::Frame::kPositionsF64FieldNumber, c.positions_f64);
    w.packed_field(pb::Frame::kOrientationsF64FieldNumber, c.orientations_f64);
    w.packed_field(pb::Frame::kLocalRotationsF64FieldNumber, c.local_rotations_f64);
    w.packed_field(pb::Frame::kLocalTranslationsF64FieldNumber, c.local_translations_f64);
  } else {
    w.packed_field(pb::Frame::kPositionsFieldNumber, c.positions);
    w.packed_field(pb::Frame::kOrientationsFieldNumber, c.orientations);
    w.packed_field(pb::Frame::kLocalRotationsFieldNumber, c.local_rotations);
    w.packed_field(pb::Frame::kLocalTranslationsFieldNumber, c.local_translations);
  }
}

}  // namespace

std::string encode_frame_body(const FrameContent& c) {
  // write_body writes the fields in field-number order, as protobuf does.
  using F = pb::Frame;
  static_assert(F::kSkeletonVersionFieldNumber < F::kFrameIndexFieldNumber &&
                F::kFrameIndexFieldNumber < F::kMotionTimeFieldNumber &&
                F::kMotionTimeFieldNumber < F::kSequenceFieldNumber &&
                F::kSequenceFieldNumber < F::kServerSendTimeNsFieldNumber &&
                F::kServerSendTimeNsFieldNumber < F::kPositionsFieldNumber &&
                F::kPositionsFieldNumber < F::kOrientationsFieldNumber &&
                F::kOrientationsFieldNumber < F::kLocalRotationsFieldNumber &&
                F::kLocalRotationsFieldNumber < F::kLocalTranslationsFieldNumber &&
                F::kServerSendTimeNsFieldNumber < F::kPositionsF64FieldNumber &&
                F::kPositionsF64FieldNumber < F::kOrientationsF64FieldNumber &&
                F::kOrientationsF64FieldNumber < F::kLocalRotationsF64FieldNumber &&
                F::kLocalRotationsF64FieldNumber < F::kLocalTranslationsF64FieldNumber);
  std::string out(max_body_size(c), '\0');
  BodyWriter writer(out.data());
  write_body(writer, c);
  out.resize(static_cast<std::size_t>(writer.end() - out.data()));
  return out;
}

void set_write_stamp(char* value, std::int64_t ns) {
  auto v = static_cast<std::uint64_t>(ns);
  for (int i = 0; i < 8; ++i, v >>= 8) value[i] = static_cast<char>(v & 0xff);  // fixed64: little-endian
}

FrameHead frame_head_for(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id,
                         std::size_t body_size, bool length_prefix) {
  static_assert(pb::Frame::kViewIdFieldNumber < 16 && pb::Frame::kSubscriptionIdFieldNumber < 16 &&
                    pb::Frame::kStreamIdFieldNumber < 16 && pb::Frame::kServerWriteTimeNsFieldNumber < 16,
                "each id's tag is one byte");
  static_assert(pb::ServerMessage::kFrameFieldNumber < 2048, "ServerMessage.frame's tag is at most two bytes");
  const std::size_t ids_size =
      3 + varint_size(view_id) + varint_size(subscription_id) + varint_size(stream_id) + kWriteStampBytes;
  FrameHead head;
  char* const begin = head.bytes_.data();
  char* p = begin + (length_prefix ? kLengthPrefixBytes : 0);
  p = put_varint(p, tag(pb::ServerMessage::kFrameFieldNumber, 2));
  p = put_varint(p, ids_size + body_size);
  p = put_varint(p, tag(pb::Frame::kViewIdFieldNumber, 0));
  p = put_varint(p, view_id);
  p = put_varint(p, tag(pb::Frame::kSubscriptionIdFieldNumber, 0));
  p = put_varint(p, subscription_id);
  p = put_varint(p, tag(pb::Frame::kStreamIdFieldNumber, 0));
  p = put_varint(p, stream_id);
  p = put_varint(p, tag(pb::Frame::kServerWriteTimeNsFieldNumber, 1));  // 64-bit
  std::fill_n(p, 8, '\0');
  p += 8;
  head.size_ = static_cast<std::uint8_t>(p - begin);
  if (length_prefix) {
    write_length_prefix(
        static_cast<std::uint32_t>(head.size_ - kLengthPrefixBytes + body_size),
        std::span<std::uint8_t, kLengthPrefixBytes>(reinterpret_cast<std::uint8_t*>(begin), kLengthPrefixBytes));
  }
  return head;
}

std::string frame_message_for(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id,
                              std::string_view body, std::int64_t write_ns) {
  FrameHead head = frame_head_for(view_id, subscription_id, stream_id, body.size(), false);
  head.set_write_stamp(write_ns);
  std::string out;
  out.reserve(head.size() + body.size());
  out.append(head.view());
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

FrameFields frame_fields(const pb::Frame& f) {
  FrameFields r;
  r.view_id = f.view_id();
  r.subscription_id = f.subscription_id();
  r.stream_id = f.stream_id();
  r.server_write_time_ns = f.server_write_time_ns();
  r.skeleton_version = f.skeleton_version();
  r.frame_index = f.frame_index();
  r.motion_time = f.motion_time();
  r.sequence = f.sequence();
  r.server_send_time_ns = f.server_send_time_ns();
  auto packed = [](const auto& list) {
    using T = std::decay_t<decltype(*list.data())>;
    return Packed<T>(list.data(), static_cast<std::size_t>(list.size()));
  };
  r.positions = packed(f.positions());
  r.orientations = packed(f.orientations());
  r.local_rotations = packed(f.local_rotations());
  r.local_translations = packed(f.local_translations());
  r.positions_f64 = packed(f.positions_f64());
  r.orientations_f64 = packed(f.orientations_f64());
  r.local_rotations_f64 = packed(f.local_rotations_f64());
  r.local_translations_f64 = packed(f.local_translations_f64());
  return r;
}

namespace {

// Protobuf's wire format, read as protobuf reads it, for the fields a frame
// has; anything it would read otherwise (or refuse) makes read() false.
class FrameReader {
 public:
  explicit FrameReader(std::string_view bytes) : p_(bytes.data()), end_(bytes.data() + bytes.size()) {}

  // The ServerMessage's one field: the frame, to the end of the bytes.
  bool read_message(FrameFields& out) {
    std::uint64_t t = 0, n = 0;
    if (!varint(t, 5) || t != tag(pb::ServerMessage::kFrameFieldNumber, 2) || !varint(n, 5) || n != left()) {
      return false;
    }
    return read_frame(out);
  }

 private:
  bool read_frame(FrameFields& out) {
    using F = pb::Frame;
    std::uint32_t lists_seen = 0;  // a list in two pieces is appended by protobuf: not done here
    while (p_ != end_) {
      std::uint64_t t = 0;
      if (!varint(t, 5) || t > 0xffffffffu || (t >> 3) == 0) return false;
      const auto number = static_cast<int>(t >> 3);
      const auto wire_type = static_cast<int>(t & 7);
      std::uint64_t v = 0;
      bool ok = true;
      switch (t) {
        case tag(F::kViewIdFieldNumber, 0):
          ok = uint32(out.view_id);
          break;
        case tag(F::kSubscriptionIdFieldNumber, 0):
          ok = uint32(out.subscription_id);
          break;
        case tag(F::kStreamIdFieldNumber, 0):
          ok = varint(out.stream_id);
          break;
        case tag(F::kServerWriteTimeNsFieldNumber, 1):
          ok = fixed64(v);
          out.server_write_time_ns = static_cast<std::int64_t>(v);
          break;
        case tag(F::kSkeletonVersionFieldNumber, 0):
          ok = uint32(out.skeleton_version);
          break;
        case tag(F::kFrameIndexFieldNumber, 0):
          ok = varint(out.frame_index);
          break;
        case tag(F::kMotionTimeFieldNumber, 1):
          ok = fixed64(v);
          std::memcpy(&out.motion_time, &v, sizeof v);
          break;
        case tag(F::kSequenceFieldNumber, 0):
          ok = varint(out.sequence);
          break;
        case tag(F::kServerSendTimeNsFieldNumber, 0):
          ok = varint(v);
          out.server_send_time_ns = static_cast<std::int64_t>(v);
          break;
        case tag(F::kPositionsFieldNumber, 2):
          ok = list(number, lists_seen, out.positions);
          break;
        case tag(F::kOrientationsFieldNumber, 2):
          ok = list(number, lists_seen, out.orientations);
          break;
        case tag(F::kLocalRotationsFieldNumber, 2):
          ok = list(number, lists_seen, out.local_rotations);
          break;
        case tag(F::kLocalTranslationsFieldNumber, 2):
          ok = list(number, lists_seen, out.local_translations);
          break;
        case tag(F::kPositionsF64FieldNumber, 2):
          ok = list(number, lists_seen, out.positions_f64);
          break;
        case tag(F::kOrientationsF64FieldNumber, 2):
          ok = list(number, lists_seen, out.orientations_f64);
          break;
        case tag(F::kLocalRotationsF64FieldNumber, 2):
          ok = list(number, lists_seen, out.local_rotations_f64);
          break;
        case tag(F::kLocalTranslationsF64FieldNumber, 2):
          ok = list(number, lists_seen, out.local_translations_f64);
          break;
        default:
          // A list's values one by one (unpacked): protobuf appends them.
          if (number >= F::kPositionsFieldNumber && number <= F::kLocalTranslationsF64FieldNumber) return false;
          // Any other field, or a known one of another wire type, is an
          // unknown field to protobuf: skipped.
          ok = skip(wire_type);
      }
      if (!ok) return false;
    }
    return true;
  }

  std::size_t left() const { return static_cast<std::size_t>(end_ - p_); }

  // A value: at most 10 bytes and 64 bits (protobuf drops bits past 64: not
  // done here). Tags and lengths: at most 5 bytes, as protobuf reads them.
  bool varint(std::uint64_t& v, int max_bytes = 10) {
    v = 0;
    for (int i = 0; i < max_bytes; ++i) {
      if (p_ == end_) return false;
      const auto b = static_cast<std::uint8_t>(*p_++);
      if (i == 9 && b > 1) return false;
      v |= static_cast<std::uint64_t>(b & 0x7f) << (7 * i);
      if (b < 0x80) return true;
    }
    return false;
  }
  // A uint32 field (protobuf keeps the low 32 bits of a longer value: not done here).
  bool uint32(std::uint32_t& v) {
    std::uint64_t w = 0;
    if (!varint(w) || w > 0xffffffffu) return false;
    v = static_cast<std::uint32_t>(w);
    return true;
  }
  bool fixed64(std::uint64_t& v) {
    if (left() < sizeof v) return false;
    std::memcpy(&v, p_, sizeof v);  // little-endian, as the host (static_assert in write_body)
    p_ += sizeof v;
    return true;
  }
  bool length(std::uint64_t& n) { return varint(n, 5) && n <= left(); }
  template <class T>
  bool list(int number, std::uint32_t& seen, Packed<T>& out) {
    const std::uint32_t bit = 1u << (number - pb::Frame::kPositionsFieldNumber);
    std::uint64_t n = 0;
    if ((seen & bit) != 0 || !length(n) || n % sizeof(T) != 0) return false;
    seen |= bit;
    out = Packed<T>(p_, n / sizeof(T));
    p_ += n;
    return true;
  }
  bool skip(int wire_type) {
    std::uint64_t n = 0;
    switch (wire_type) {
      case 0:
        return varint(n);
      case 1:
        n = 8;
        break;
      case 2:
        if (!varint(n, 5)) return false;
        break;
      case 5:
        n = 4;
        break;
      default:
        return false;  // groups (3, 4) and the unused 6, 7
    }
    if (n > left()) return false;
    p_ += n;
    return true;
  }

  const char* p_;
  const char* end_;
};

}  // namespace

bool read_frame_message(std::string_view message, FrameFields& out) {
  out = FrameFields{};
  return FrameReader(message).read_message(out);
}

Status unpack_frame(const FrameFields& f, FrameValues& d) {
  d.view_id = f.view_id;
  d.subscription_id = f.subscription_id;
  d.stream_id = f.stream_id;
  d.skeleton_version = f.skeleton_version;
  d.frame_index = f.frame_index;
  d.motion_time = f.motion_time;
  d.sequence = f.sequence;
  d.server_send_time_ns = f.server_send_time_ns;
  d.server_write_time_ns = f.server_write_time_ns;
  d.float64 = !f.positions_f64.empty();
  Status s = d.float64 ? unpack(f.positions_f64, f.orientations_f64, d.positions, d.orientations)
                       : unpack(f.positions, f.orientations, d.positions, d.orientations);
  if (s.ok()) {
    s = d.float64 ? unpack_locals(f.local_rotations_f64, f.local_translations_f64, d.positions.size(),
                                  d.local_rotations, d.local_translations)
                  : unpack_locals(f.local_rotations, f.local_translations, d.positions.size(), d.local_rotations,
                                  d.local_translations);
  }
  if (!s.ok())
    return make_error(ErrorKind::kInvalidData, "frame " + std::to_string(d.frame_index) + ": " + s.error().message);
  return Ok{};
}

Result<FrameValues> decode_frame(const pb::Frame& f) {
  FrameValues d;
  if (auto s = unpack_frame(frame_fields(f), d); !s.ok()) return s.error();
  return d;
}

bool same_bits(const FrameValues& a, const FrameValues& b) {
  auto same = [](const auto& x, const auto& y) {
    return x.size() == y.size() && (x.empty() || std::memcmp(x.data(), y.data(), x.size() * sizeof x[0]) == 0);
  };
  return a.view_id == b.view_id && a.subscription_id == b.subscription_id && a.stream_id == b.stream_id &&
         a.skeleton_version == b.skeleton_version && a.frame_index == b.frame_index &&
         std::memcmp(&a.motion_time, &b.motion_time, sizeof a.motion_time) == 0 && a.sequence == b.sequence &&
         a.server_send_time_ns == b.server_send_time_ns && a.server_write_time_ns == b.server_write_time_ns &&
         a.float64 == b.float64 && same(a.positions, b.positions) && same(a.orientations, b.orientations) &&
         same(a.local_rotations, b.local_rotations) && same(a.local_translations, b.local_translations);
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
