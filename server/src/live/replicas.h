// Replicas: the live sources several gmr-server replicas share through NATS
// (relay.h; docs/deployment.md). A source published on one replica is
// announced on the subject, its frames follow, and every other replica
// serves it as a live source of its own list, to its own clients, through
// their own views. Announces repeat every second: a replica started later
// learns of running sources, and a source whose replica stopped talking
// (killed) ends after cfg.relay_timeout.
//
// Everything another replica sends is hostile until checked: an announce
// gets a Publish's checks (announcement.h) and at most
// cfg.max_remote_sources are tracked; frames are checked as published ones.
// On the control loop.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <span>
#include <string>

#include "gmr/server/config.h"
#include "live/live_directory.h"
#include "live/live_source.h"
#include "live/relay.h"
#include "transport/net.h"

namespace gmr::server {

class Replicas {
 public:
  Replicas(net::io_context& io, const ServerConfig& cfg, LiveDirectory& directory);
  ~Replicas();

  // Connects to cfg.nats_url (nothing when it is empty); throws
  // std::runtime_error when the options are bad.
  void start();
  // No more messages are handled or sent, and the re-announce timer stops.
  void stop();
  // Closes the NATS connection (after the control loop has ended).
  void close();

  // A source published here: tell the other replicas (nothing without NATS).
  void announce(const LiveSource& source);
  void frame(const LiveSource& source, std::span<const double> values);
  void end(const LiveSource& source, const std::string& reason);

  // A message from another replica (the relay posts it to the control loop).
  void on_relay(relay_pb::LiveRelay m);

  std::uint64_t announces_refused() const { return announces_refused_; }
  // Relay messages refused before parsing (NatsRelay::refused): 0 without NATS.
  std::uint64_t messages_refused() const { return relay_ ? relay_->refused() : 0; }
  // Whether the relay reaches NATS now (false without one).
  bool relay_connected() const { return relay_ && relay_->connected(); }
  std::size_t remote_sources() const { return remote_.size(); }

 private:
  void tick();

  net::io_context& io_;
  const ServerConfig& cfg_;
  LiveDirectory& directory_;
  std::unique_ptr<NatsRelay> relay_;
  std::unique_ptr<net::steady_timer> timer_;
  bool stopped_ = false;
  struct RemoteSource {
    std::shared_ptr<LiveSource> source;  // null: ignored (its name is taken here)
    Clock::time_point heard;
  };
  // Other replicas' sources, by origin and serial: at most cfg.max_remote_sources.
  std::map<std::string, RemoteSource> remote_;
  std::uint64_t announces_refused_ = 0;  // invalid, or past max_remote_sources
  LogLimiter log_limit_;                 // lines other replicas' messages may put in the log
};

}  // namespace gmr::server
