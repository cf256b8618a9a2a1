// NatsRelay: live sources shared between gmr-server replicas through a NATS
// server (Debian's nats-server; the C client libnats). The replica whose
// connection publishes a source sends its announce, frames and end on one
// subject; every other replica consumes them and serves the source to its
// own clients, with their own views, as if it were published there. NATS
// does the delivery; there is no clustering of our own.
//
// libnats runs its own threads: messages are checked and parsed there and
// posted to the server's io_context, so the server's state stays on the I/O
// thread. A NATS server that goes away is logged and reconnected to,
// forever; frames meanwhile are not relayed (they are live: nothing waits
// for them).
//
// What arrives on the subject is hostile until checked: with a shared
// secret each message's HMAC-SHA256 must check (a publisher without it is
// refused and counted), an origin's messages must move forward in sequence
// (a captured message replayed later is refused), and at most
// kMaxMessagesInFlight wait for the I/O thread (a flood is dropped and
// counted, never queued without bound).
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <string>

#include "gmr/core/error.h"
#include "gmr/relay/v1/relay.pb.h"
#include "gmr/server/config.h"
#include "transport/net.h"

struct __natsConnection;
struct __natsOptions;
struct __natsSubscription;

namespace gmr::server {

namespace relay_pb = ::gmr::relay::v1;

class NatsRelay {
 public:
  using Handler = std::function<void(relay_pb::LiveRelay)>;
  struct Options {
    std::string url, subject;
    std::string origin;            // this replica's id (messages carrying it are its own and ignored)
    std::string credentials_file;  // ServerConfig::nats_credentials_file
    std::string secret;            // ServerConfig::relay_secret
  };
  static constexpr std::size_t kMaxMessagesInFlight = 8192;
  static constexpr std::size_t kMaxOrigins = 4096;
  NatsRelay(net::io_context& io, Options options, Handler on_message);
  ~NatsRelay();
  NatsRelay(const NatsRelay&) = delete;
  NatsRelay& operator=(const NatsRelay&) = delete;

  // Connects (or keeps trying in the background when the NATS server is not
  // there yet) and subscribes. Fails only on bad options (the URL).
  Status start();
  // Sends `m` (origin set here); dropped, and counted, while disconnected.
  void send(relay_pb::LiveRelay m);
  // Unsubscribes and closes; no handler runs after it returns.
  void stop();

  const std::string& origin() const { return options_.origin; }
  std::uint64_t sent() const { return sent_; }
  std::uint64_t received() const { return received_; }
  std::uint64_t dropped() const { return dropped_; }
  // Messages refused before parsing: unauthenticated (no MAC, or a wrong
  // one), unparsable, out of sequence, or past kMaxMessagesInFlight.
  std::uint64_t refused() const;
  // Whether NATS is connected now (not while reconnecting, nor once it
  // refused this replica).
  bool connected() const;

  struct Shared;  // relay.cpp: what libnats's threads reach

 private:
  // --nats-creds on `opts` (docs/deployment.md); an error names the file and line.
  Status apply_credentials(__natsOptions* opts);
  net::io_context& io_;
  Options options_;
  std::uint64_t next_sequence_ = 1;
  std::shared_ptr<Shared> shared_;
  __natsConnection* connection_ = nullptr;
  __natsSubscription* subscription_ = nullptr;
  std::atomic<std::uint64_t> sent_{0}, received_{0}, dropped_{0};
};

}  // namespace gmr::server
