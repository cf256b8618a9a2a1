// Private to the server: Asio and protocol names, and the error reply.
#pragma once

#include <utility>  // std::exchange, which boost/asio/awaitable.hpp uses without including

#include <boost/asio.hpp>
#include <boost/asio/ssl.hpp>
#include <chrono>
#include <cstdint>
#include <string>
#include <string_view>
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

// A client-supplied string as it may go into a log line: in double quotes,
// with control characters, quotes, backslashes and bytes above 0x7e escaped
// (\n, \", \x1b), and at most `max` bytes of it followed by how many more
// there were. Client text can neither forge a log line, nor drive a
// terminal, nor flood the log.
std::string printable(std::string_view text, std::size_t max = 64);

// The host an address stands for in per-address limits: an IPv4 address
// itself (an IPv4-mapped IPv6 one as IPv4), an IPv6 address's /64 (one host
// is given 2^64 addresses; "2001:db8:1:2::/64"); text that is no address as
// it is.
std::string address_group(const std::string& address);

// Why multicast to `group` sent from the interface of `bound` would reach no
// listener, or empty when it can. Listeners (gmr discover, multicast
// subscribers) join the group on the interface this machine routes it to; a
// server bound to a loopback address sends on the loopback interface, so
// when the route goes elsewhere (a LAN interface, or nowhere) nobody hears.
std::string multicast_unreachable(const net::ip::address& bound, const net::ip::address_v4& group);

// Rate limit for the log lines one client can cause: at most `burst` per
// `period`; the others are counted, and the next line logged reports them.
class LogLimiter {
 public:
  explicit LogLimiter(std::size_t burst = 5, Clock::duration period = std::chrono::seconds(10))
      : burst_(burst), period_(period) {}
  // True when a line may be logged now. `suppressed` is then the number of
  // lines left out since the last one logged (reported with it).
  bool allow(std::uint64_t& suppressed);
  std::uint64_t pending() const { return suppressed_; }

 private:
  std::size_t burst_;
  Clock::duration period_;
  Clock::time_point window_start_{};
  std::size_t in_window_ = 0;
  std::uint64_t suppressed_ = 0;
};

// ServerMessage{error}.
pb::ServerMessage error_message(std::uint64_t request_id, pb::ErrorCode code, std::string text);
// Writes `refusal` (framed) to a connection the server will not serve, then
// closes it.
void refuse_socket(tcp::socket socket, const pb::ServerMessage& refusal);

}  // namespace gmr::server
