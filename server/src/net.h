// Private to the server: Asio and protocol names, and the error reply.
#pragma once

#include <utility>  // std::exchange, which boost/asio/awaitable.hpp uses without including

#include <boost/asio.hpp>
#include <chrono>
#include <cstdint>
#include <string>
#include <variant>

#include "gmr/core/error.h"
#include "gmr/stream/v1/stream.pb.h"

namespace gmr::server {

namespace net = boost::asio;
namespace pb = ::gmr::stream::v1;
using tcp = net::ip::tcp;
using udp = net::ip::udp;
using Clock = std::chrono::steady_clock;

// Wall-clock time for Frame.server_send_time_ns.
std::int64_t now_ns();

// A request the server refuses: the protocol's error code and why.
struct Refusal {
  pb::ErrorCode code = pb::ERROR_CODE_INTERNAL;
  std::string message;
};
// What a request gets: its reply, or a refusal (errors are values, never
// thrown).
using Reply = std::variant<pb::ServerMessage, Refusal>;

// A refusal whose code follows the error's kind (wire::error_code_for).
Refusal refusal(const Error& error);
// ServerMessage{error}.
pb::ServerMessage error_message(std::uint64_t request_id, pb::ErrorCode code, std::string text);

}  // namespace gmr::server
