// What one client (and one other replica) can make the server do: a
// sequence of requests into a RequestHandler serving the built-in library,
// and of NATS relay messages into the server, with no sockets. Any sequence
// gives replies and refusals, never a crash, an exception out of the
// handler, or unbounded memory; when the connection ends, everything it
// held is given back (views' bytes, the send budget, its live sources).
//
// Input: records of [kind byte][length, 2 bytes little-endian][that many
// bytes]. An even kind sends the bytes as a request (a ClientMessage's
// encoding, as read off the connection); an odd kind parses them as a
// gmr.relay.v1.LiveRelay from one of four replicas (kind / 2 % 4).
// requests_seeds.cpp writes the seeds: the requests a session makes.
#include <spdlog/spdlog.h>

#include <google/protobuf/stubs/logging.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>

#include "fuzz_util.h"
#include "gmr/relay/v1/relay.pb.h"
#include "gmr/server/library.h"
#include "requests/request_handler.h"
#include "server_parts.h"

namespace {

using gmr::fuzz::require;
namespace server = gmr::server;

// An Outbox that forgets what it is given, checking it is a framed message.
class NullOutbox final : public server::Outbox {
 public:
  std::uint64_t id() const override { return 1; }
  bool stopped() const override { return false; }
  bool closing() const override { return closing_; }
  void send(std::string framed) override { require(framed.size() >= 4, "a reply is framed"); }
  bool push_frame(std::uint32_t, const gmr::wire::FrameHead& head, std::shared_ptr<const std::string> body,
                  std::chrono::steady_clock::duration, std::chrono::steady_clock::time_point) override {
    require(body != nullptr && head.size() + body->size() >= 4, "a frame is framed");
    return true;
  }
  void discard_frames(std::uint32_t) override {}
  void send_frames_now(std::uint32_t) override {}
  std::uint64_t end_frames(std::uint32_t) override { return 0; }
  void close_after_reply() override { closing_ = true; }
  void stop(const std::string&) override { closing_ = true; }
  void finish() override { closing_ = true; }
  void count_udp_frame_sent(std::chrono::steady_clock::duration) override {}
  void count_udp_frame_dropped() override {}
  void count_frame_dropped(std::uint64_t) override {}
  void count_frame_skipped(std::uint64_t) override {}
  server::ConnectionCounters counters() const override { return {}; }

 private:
  bool closing_ = false;
};

// The built-in library, each motion cut to its first frames: an edit
// transforms every frame, and the fuzzer is after the handler's paths.
const std::vector<server::LibraryEntry>& library() {
  static const auto lib = [] {
    auto entries = server::builtin_library();
    for (auto& e : entries) {
      auto m = std::make_shared<gmr::Motion>(*e.motion);
      m->frame_count = std::min<std::size_t>(m->frame_count, 6);
      m->values.resize(m->frame_count * m->stride());
      e.motion = std::move(m);
    }
    return entries;
  }();
  return lib;
}

server::ServerConfig config() {
  server::ServerConfig cfg;
  cfg.anonymous = gmr::server::Role::kPublish;  // every request is allowed: the handler's checks are what is fuzzed
  cfg.edit_inline_values = std::numeric_limits<std::size_t>::max();  // no edit thread: one input, one run
  cfg.max_live_joints = 256;
  return cfg;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  spdlog::set_level(spdlog::level::off);
  google::protobuf::SetLogHandler(nullptr);  // its line per string that is not UTF-8
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  gmr::test::ServerParts impl(config(), library());
  auto outbox = std::make_shared<NullOutbox>();
  auto handler = std::make_shared<server::RequestHandler>(impl.services, outbox);
  handler->start();
  static const char* const kOrigins[] = {"replica-a", "replica-b", "replica-c", "replica-d"};
  for (std::size_t i = 0; i + 3 <= size;) {
    const std::uint8_t kind = data[i];
    const std::size_t n = std::min<std::size_t>(data[i + 1] | (data[i + 2] << 8), size - i - 3);
    const std::string body(reinterpret_cast<const char*>(data + i + 3), n);
    i += 3 + n;
    if (kind % 2 == 0) {
      if (outbox->closing()) continue;  // the connection would read no more
      handler->on_message(body);
    } else {
      gmr::relay::v1::LiveRelay m;
      if (!m.ParseFromString(body)) continue;
      m.set_origin(kOrigins[kind / 2 % 4]);
      impl.replicas.on_relay(std::move(m));
    }
    impl.io.poll();  // what the requests posted (no timer is due: time is not an input)
  }
  handler->on_stop();
  impl.io.poll();
  require(impl.admission.view_bytes() == 0, "a closed connection's views give their bytes back");
  require(impl.admission.committed_mhz() == 0, "a closed connection's subscriptions give their send budget back");
  for (const auto& [name, source] : impl.catalog.live_sources()) {
    require(!source->origin().empty(), "a closed connection's live sources end");
  }
  return 0;
}
