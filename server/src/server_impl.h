// Private to the server library: the state shared by sessions and streams,
// and small helpers. Everything here is touched only on the I/O thread.
#pragma once

#include <spdlog/spdlog.h>

#include <array>
#include <boost/asio.hpp>
#include <chrono>
#include <cstdint>
#include <future>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <unordered_map>

#include "gmr/server/server.h"
#include "gmr/server/view.h"
#include "gmr/stream/v1/stream.pb.h"

namespace gmr::server {


namespace net = boost::asio;
namespace pb = ::gmr::stream::v1;
using tcp = net::ip::tcp;
using udp = net::ip::udp;
using Clock = std::chrono::steady_clock;
// Stream parameters: beyond these the schedule arithmetic loses meaning (or
// one stream could monopolise the I/O thread).
constexpr double kMinSpeed = 1e-3, kMaxSpeed = 1000.0;
constexpr double kMinRateHz = 1e-2, kMaxRateHz = 10000.0;

class Session;
class Stream;


// Everything the server shares between sessions. Touched only on the I/O thread.
struct Server::Impl {
  ServerConfig cfg;
  std::vector<LibraryEntry> library;
  std::map<std::string, std::size_t, std::less<>> by_name;

  net::io_context io;
  tcp::acceptor acceptor{io};
  udp::socket udp_socket{io};
  std::thread thread;
  std::uint16_t tcp_port = 0;
  std::uint16_t udp_port = 0;
  bool started = false;
  bool stopping = false;
  std::promise<void> stopped;
  std::shared_future<void> stopped_future = stopped.get_future().share();

  std::uint64_t next_session_id = 1;
  std::map<std::uint64_t, std::weak_ptr<Session>> sessions;
  std::unordered_map<std::uint64_t, std::weak_ptr<Session>> tokens;
  std::map<std::string, std::weak_ptr<Stream>> shared_streams;
  std::map<std::uint64_t, std::weak_ptr<Stream>> streams;
  std::uint64_t next_stream_id = 1;
  std::mt19937_64 rng{std::random_device{}()};
  // Per library entry: the float form its unedited views share, while any
  // view holds it (compiled on first use by a float32 stream; freed with the
  // last view, so memory follows what is being streamed).
  std::vector<std::weak_ptr<const CompiledForm>> compiled_forms;

  std::uint64_t frames_computed = 0;
  std::uint64_t frames_computed_float = 0;  // of those, by the float path (float32 streams)
  std::uint64_t frames_encoded = 0;
  std::uint64_t udp_rejected = 0;
  std::uint64_t connections_refused = 0;

  std::unique_ptr<net::steady_timer> grace_timer;  // while stopping
  std::array<char, 2048> udp_buffer{};
  udp::endpoint udp_sender;

  void accept_loop();
  void udp_loop();
  // Forgets streams no subscription holds any more (the maps keep weak pointers).
  void prune_streams() {
    std::erase_if(streams, [](const auto& kv) { return kv.second.expired(); });
    std::erase_if(shared_streams, [](const auto& kv) { return kv.second.expired(); });
  }
  void begin_stop();
  // The shared float form of library entry `entry` (made when no view holds one).
  std::shared_ptr<const CompiledForm> compiled_form(std::size_t entry) {
    if (compiled_forms.size() != library.size()) compiled_forms.resize(library.size());
    auto c = compiled_forms[entry].lock();
    if (!c) {
      c = std::make_shared<const CompiledForm>(library[entry].motion);
      compiled_forms[entry] = c;
    }
    return c;
  }
  ServerStats snapshot() const;
};

namespace detail {

inline std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

inline pb::ServerMessage error_message(std::uint64_t request_id, pb::ErrorCode code, std::string text) {
  pb::ServerMessage m;
  m.set_request_id(request_id);
  m.mutable_error()->set_code(code);
  m.mutable_error()->set_message(std::move(text));
  return m;
}

struct RequestError {
  pb::ErrorCode code;
  std::string message;
};

}  // namespace detail

using detail::error_message;
using detail::now_ns;
using detail::RequestError;

}  // namespace gmr::server
