// TCP framing: every message is a 4-byte big-endian length followed by that
// many bytes of a serialized ClientMessage or ServerMessage.
//
//   +--------+--------+--------+--------+------------------ ... --+
//   |  length (uint32, big-endian)      |  protobuf bytes (length) |
//   +--------+--------+--------+--------+------------------ ... --+
//
// A length above the receiver's cap is refused before any byte of the body is
// read or buffered, and the connection is closed: framing errors cannot be
// recovered from (the next byte boundary is unknown).
#pragma once

#include <google/protobuf/message_lite.h>

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "gmr/core/error.h"

namespace gmr::wire {

// The protocol version spoken by this build. A Hello with a different major
// version is refused (see docs/protocol.md).
inline constexpr std::uint32_t kProtocolVersion = 1;

inline constexpr std::size_t kLengthPrefixBytes = 4;
// Default cap on one message (either direction): 4 MiB, enough for a query of
// ~700 frames of a 31-joint skeleton with orientations in float64.
inline constexpr std::uint32_t kDefaultMaxMessageBytes = 4u << 20;

// Reads the big-endian length at the start of `prefix` (kLengthPrefixBytes).
std::uint32_t read_length_prefix(std::span<const std::uint8_t, kLengthPrefixBytes> prefix);
// Writes `length` big-endian into `out`.
void write_length_prefix(std::uint32_t length, std::span<std::uint8_t, kLengthPrefixBytes> out);

// Ok when `length` <= `max_bytes`; otherwise an error naming both numbers.
Status check_length(std::uint64_t length, std::uint32_t max_bytes);

// Prefix + serialized `message`. Fails when the message is larger than
// `max_bytes` (nothing is produced then).
Result<std::string> frame_message(const google::protobuf::MessageLite& message,
                                  std::uint32_t max_bytes = kDefaultMaxMessageBytes);
// Prefix + already serialized bytes (which the caller sized).
std::string frame_bytes(std::string_view serialized);

}  // namespace gmr::wire
