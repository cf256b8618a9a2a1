// SHA-256 (OpenSSL): what auth compares tokens by, and what a live view's
// edits are keyed by (streams/live_key.h).
#pragma once

#include <array>
#include <cstdint>
#include <string_view>

namespace gmr::server {

std::array<std::uint8_t, 32> sha256(std::string_view text);

}  // namespace gmr::server
