// Beacon: discovery beacons. A server started with --discovery-group says,
// every cfg.discovery_interval, on a multicast group, who it is and where it
// listens; `gmr discover` hears them. A documented UDP beacon in the manner
// of NatNet's rather than DNS-SD: see docs/protocol.md, "Discovery", for why.
#pragma once

#include <functional>
#include <memory>

#include "gmr/server/config.h"
#include "transport/net.h"

namespace gmr::server {

class Beacon {
 public:
  // `describe` says what the next beacon announces (read when it is sent).
  Beacon(net::io_context& io, const ServerConfig& cfg, std::function<pb::Beacon()> describe);
  // Starts sending from `bound`'s interface (nothing without
  // cfg.discovery_group). Throws std::runtime_error for a bad group.
  void start(const net::ip::address& bound);
  void stop();

 private:
  void send();

  net::io_context& io_;
  const ServerConfig& cfg_;
  std::function<pb::Beacon()> describe_;
  net::ip::udp::endpoint group_;
  std::unique_ptr<net::ip::udp::socket> socket_;
  std::unique_ptr<net::steady_timer> timer_;
  bool stopped_ = false;
  bool send_failed_ = false;  // a failed send was logged
};

}  // namespace gmr::server
