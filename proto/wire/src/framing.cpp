#include "gmr/wire/framing.h"

#include <string>

namespace gmr::wire {

std::uint32_t read_length_prefix(std::span<const std::uint8_t, kLengthPrefixBytes> p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | std::uint32_t{p[3]};
}

void write_length_prefix(std::uint32_t length, std::span<std::uint8_t, kLengthPrefixBytes> out) {
  out[0] = static_cast<std::uint8_t>(length >> 24);
  out[1] = static_cast<std::uint8_t>(length >> 16);
  out[2] = static_cast<std::uint8_t>(length >> 8);
  out[3] = static_cast<std::uint8_t>(length);
}

Status check_length(std::uint64_t length, std::uint32_t max_bytes) {
  if (length > max_bytes) {
    return make_error("message of " + std::to_string(length) + " bytes exceeds the limit of " +
                      std::to_string(max_bytes) + " bytes");
  }
  return Ok{};
}

std::string frame_bytes(std::string_view serialized) {
  std::string out(kLengthPrefixBytes + serialized.size(), '\0');
  write_length_prefix(
      static_cast<std::uint32_t>(serialized.size()),
      std::span<std::uint8_t, kLengthPrefixBytes>(reinterpret_cast<std::uint8_t*>(out.data()), kLengthPrefixBytes));
  out.replace(kLengthPrefixBytes, serialized.size(), serialized);
  return out;
}

Result<std::string> frame_message(const google::protobuf::MessageLite& message, std::uint32_t max_bytes) {
  const std::size_t size = message.ByteSizeLong();
  if (auto s = check_length(size, max_bytes); !s.ok()) return s.error();
  std::string out(kLengthPrefixBytes + size, '\0');
  auto* data = reinterpret_cast<std::uint8_t*>(out.data());
  write_length_prefix(static_cast<std::uint32_t>(size), std::span<std::uint8_t, kLengthPrefixBytes>(data, 4));
  if (!message.SerializeToArray(data + kLengthPrefixBytes, static_cast<int>(size))) {
    return make_error("could not serialize a " + message.GetTypeName());
  }
  return out;
}

}  // namespace gmr::wire
