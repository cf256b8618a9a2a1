// Server settings: every limit has a default and a gmr-server flag.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

#include "gmr/wire/framing.h"

namespace gmr::server {

struct ServerConfig {
  std::string bind_address = "127.0.0.1";  // loopback unless told to serve a network
  std::uint16_t port = 0;                  // TCP; 0 picks a free port (read it back with Server::tcp_port)
  int udp_port = -1;                       // -1: the TCP port number (any free port when port is 0); 0: any free port
  std::string server_name = "gmr-server";

  std::uint32_t max_message_bytes = wire::kDefaultMaxMessageBytes;  // either direction
  std::size_t max_connections = 256;
  std::size_t max_views_per_connection = 32;
  std::size_t max_subscriptions_per_connection = 32;
  // A connection that sends nothing (not even a heartbeat) for this long is closed.
  std::chrono::milliseconds idle_timeout{30000};
  // The server sends a heartbeat when it wrote nothing for this long.
  std::chrono::milliseconds heartbeat_interval{5000};
  // A write that makes no progress for this long means a dead client: closed.
  std::chrono::milliseconds write_timeout{20000};
  // Replies waiting to be written, per connection: above this the server stops
  // reading that connection's requests until they drain (frames are not counted:
  // they are latest-frame-wins, one per subscription).
  std::size_t max_reply_queue_bytes = 2 * static_cast<std::size_t>(wire::kDefaultMaxMessageBytes);
  // Frames waiting per subscription while a write is in flight; a newer frame
  // then replaces the oldest (latest wins) and the drop is counted. Small: it
  // only absorbs I/O-thread jitter, the kernel buffers absorb the rest.
  std::size_t frames_per_subscription = 4;
  // UDP datagrams handed to the kernel and not yet sent, per connection; above
  // this a frame is dropped and counted.
  std::size_t max_udp_datagrams_in_flight = 512;
  // SO_SNDBUF for accepted sockets; 0 keeps the system default. Tests shrink it
  // so a client that never reads fills it quickly.
  int socket_send_buffer = 0;
  // How far a stream may fall behind its schedule (a stalled server) and
  // still catch up frame by frame; beyond it playback jumps to the frame due
  // now. Tests raise it so that a slow (sanitizer) build still sends every frame.
  std::chrono::milliseconds max_catch_up{250};
  // How long a graceful stop waits for replies to drain before closing.
  std::chrono::milliseconds shutdown_grace{2000};
};

}  // namespace gmr::server
