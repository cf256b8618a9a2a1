// Server settings: every limit has a default and a gmr-server flag.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "gmr/server/auth.h"
#include "gmr/wire/framing.h"

namespace gmr::server {

struct ServerConfig {
  std::string bind_address = "127.0.0.1";  // loopback unless told to serve a network
  std::uint16_t port = 0;                  // TCP; 0 picks a free port (read it back with Server::tcp_port)
  int udp_port = -1;                       // -1: the TCP port number (any free port when port is 0); 0: any free port
  std::string server_name = "gmr-server";
  // HTTP (docs/viewer.md, docs/monitoring.md): the browser viewer, its
  // WebSocket, /metrics, /healthz and /readyz on a port of their own, on
  // bind_address. -1: no HTTP; 0: any free port (read it back with
  // Server::http_port).
  int http_port = -1;
  // The viewer's files (index.html, viewer.js, viewer.css) and Debian's
  // three.js (libjs-three), served at / and /three/.
  std::string web_root;
  std::string three_dir = "/usr/share/javascript/three";
  // HTTP connections open at once (a WebSocket counts as a client
  // connection instead, under max_connections), and how long one may sit
  // idle or take to send its request.
  // When every session is taken, a new connection takes the place of the
  // oldest one still waiting for a request (a health probe gets in while
  // silent sockets hold the rest). One address (IPv6: its /64) holds at
  // most max_http_sessions_per_address, and a request head must arrive
  // within http_head_timeout of the connection or the previous answer.
  std::size_t max_http_sessions = 64;
  std::size_t max_http_sessions_per_address = 16;
  std::chrono::milliseconds http_timeout{30000};
  std::chrono::milliseconds http_head_timeout{5000};
  // Host names (besides IP addresses, localhost and this machine's name, always allowed) the
  // WebSocket and /metrics answer to. A page whose host name comes to point
  // at this server (DNS rebinding) sends its own name as Host: refused.
  std::vector<std::string> http_allowed_hosts;
  // Origins (scheme://host:port, or "*") besides the server's own whose
  // pages may open the WebSocket. A browser sends its page's origin; any
  // site open in a browser on this host could otherwise drive the server.
  std::vector<std::string> http_allowed_origins;

  // Who may do what (docs/security.md). A client's Hello token gives its role
  // from `credentials` (an unknown token is refused); a client without a
  // token gets `anonymous`. No credentials: every client is anonymous.
  std::shared_ptr<const Credentials> credentials;
  Role anonymous = Role::kControl;
  // With credentials, the part of max_connections clients without a token
  // may hold between them (the rest is kept for token holders); 1: no bound.
  double anonymous_share = 0.25;
  // TLS on the TCP port (docs/security.md): a PEM certificate chain and its
  // private key. Both empty: plain TCP. With TLS the port speaks only TLS.
  std::string tls_certificate_file;
  std::string tls_key_file;

  // Threads that carry the sockets' work (docs/architecture.md, "Threads"):
  // TCP connections are spread over them, and each sends its frames (TCP
  // writes, UDP datagrams) from its own; one of them, the control loop, also
  // runs requests, views and streams. 0: one per CPU the process may run on.
  std::size_t io_threads = 0;

  std::uint32_t max_message_bytes = wire::kDefaultMaxMessageBytes;  // either direction
  std::size_t max_connections = 256;
  // Admission (docs/protocol.md, "Admission"): a connection must complete its
  // Hello within handshake_timeout (heartbeats do not count); at most
  // max_pending_handshakes connections wait for their Hello at once (a new
  // one past that pushes out the oldest); at most max_connections_per_address
  // from one IP address (0: no limit), so one host cannot take every slot.
  std::chrono::milliseconds handshake_timeout{5000};
  std::size_t max_pending_handshakes = 64;
  std::size_t max_connections_per_address = 64;
  std::size_t max_views_per_connection = 32;
  std::size_t max_subscriptions_per_connection = 32;
  // Live sources one connection may publish at once, and the joints of one.
  std::size_t max_publications_per_connection = 8;
  std::size_t max_live_joints = 4096;
  // Where live sources that ask to be recorded (Publish.record) are written
  // as .gmrb when they end; empty: recording is refused. A recording stops
  // growing at max_record_bytes of values (the file keeps what came before).
  std::string record_dir;
  std::size_t max_record_bytes = std::size_t{256} << 20;
  // The record budget (live/recordings.h): recordings under way hold at
  // most max_record_total_bytes together; those and the directory's files
  // at most max_record_dir_bytes (0: no such bound); and 256 MiB of the
  // disk stay free. A recording stops growing at a bound; a new one that
  // finds no room is refused.
  std::size_t max_record_total_bytes = std::size_t{1} << 30;
  std::size_t max_record_dir_bytes = std::size_t{8} << 30;
  // Multicast (docs/protocol.md, "Multicast"): shared streams a subscriber
  // asks for over TRANSPORT_MULTICAST go once per frame to this IPv4 group
  // and port, from the UDP socket; empty: multicast is refused. TTL 1 keeps
  // them on the local network segment.
  std::string multicast_group;
  std::uint16_t multicast_port = 7500;
  int multicast_ttl = 1;

  // Discovery (docs/protocol.md, "Discovery"): a beacon every
  // discovery_interval to this IPv4 multicast group and port, which `gmr
  // discover` listens to; empty: none. TTL multicast_ttl.
  std::string discovery_group;
  std::uint16_t discovery_port = 7501;
  std::chrono::milliseconds discovery_interval{1000};

  // Replicas (docs/deployment.md): live sources are
  // shared through this NATS server (nats://host:port); empty: none. Every
  // replica on the same subject serves every replica's live sources.
  std::string nats_url;
  std::string nats_subject = "gmr.live";
  // The NATS credentials (--nats-creds): a NATS .creds file (JWT and nkey
  // seed, as nsc writes it), or our own lines "user NAME" + "password
  // PASS", "token TOKEN", or "nkey PUBLIC" + "seed SEED" (docs/deployment.md).
  // Empty: none.
  std::string nats_credentials_file;
  // The secret every replica shares (--relay-secret-file, at least 32
  // characters): each relay message carries its HMAC-SHA256 under it, and
  // one whose MAC does not check is refused and counted. Empty: relay
  // messages are not authenticated (logged at start).
  std::string relay_secret;
  // A source of another replica not heard of for this long has ended (its
  // replica went away without saying so).
  std::chrono::milliseconds relay_timeout{3000};
  // At most this many sources of other replicas are tracked (served, or
  // refused and remembered); an announce past it is refused, as is one that
  // fails the checks a client's Publish gets.
  std::size_t max_remote_sources = 1024;
  // A connection that sends nothing (not even a heartbeat) for this long is closed.
  std::chrono::milliseconds idle_timeout{30000};
  // The server sends a heartbeat when it wrote nothing for this long. Half
  // the idle timeout: no client needs it to stay connected (the idle rule
  // counts what a client sends), and at 10,000 multicast subscribers a 5 s
  // interval was a third of the server's CPU (docs/performance.md).
  std::chrono::milliseconds heartbeat_interval{15000};
  // A write that makes no progress for this long means a dead client: closed.
  std::chrono::milliseconds write_timeout{20000};
  // A subscription whose frames wait this long behind a write in flight (TCP,
  // WebSocket), or whose UDP lane has not handed a datagram to the kernel for
  // this long, is congested: its stream computes nothing for it
  // (docs/protocol.md, "Slow clients").
  std::chrono::milliseconds congested_after{50};
  // Memory (docs/protocol.md, "Memory budget"). Replies held for a
  // connection (waiting or being written): above this the server stops
  // reading that connection's requests until they drain.
  std::size_t max_reply_queue_bytes = 1u << 20;
  // Frames waiting for a connection, all its subscriptions together (besides
  // frames_per_subscription): the oldest give way.
  std::size_t max_frame_bytes_per_connection = 1u << 20;
  // Everything all connections hold (replies, frames, writes in flight,
  // request bodies): above it no connection is read and frames that would
  // wait are dropped, until it drains. 0: no server-wide limit.
  std::size_t max_buffered_bytes = std::size_t{256} << 20;
  // The motions views hold beyond the library's own: an edited view owns a
  // copy (8 bytes per channel value, plus 8 for its float form). An edit
  // that would pass either limit is refused with RESOURCE_EXHAUSTED.
  std::size_t max_view_bytes_per_connection = std::size_t{64} << 20;
  std::size_t max_view_bytes = std::size_t{1} << 30;
  // A structural view edit (shift, split, join, set roots, strip dummies) of
  // a motion with more channel values than this is computed on the server's
  // edit thread, not the I/O thread, so other clients' frames never wait for
  // it; the editing connection's next requests wait. Below it the edit is done
  // at once (an edit costs about 0.15 us per value: 2,048 values, a quarter
  // second of a 60-channel skeleton at 120 Hz, take 0.3 ms). 0: every edit
  // goes to the edit thread.
  std::size_t edit_inline_values = 2048;
  // Frames waiting per subscription while a write is in flight; a newer frame
  // then replaces the oldest (latest wins) and the drop is counted. Small: it
  // only absorbs I/O-thread jitter, the kernel buffers absorb the rest.
  std::size_t frames_per_subscription = 4;
  // UDP datagrams handed to the kernel and not yet sent, per connection; above
  // this a frame is dropped and counted.
  std::size_t max_udp_datagrams_in_flight = 512;
  // SO_SNDBUF for accepted sockets (the kernel doubles it); a fixed size
  // bounds what the kernel holds per connection (autotuning would let it
  // grow to net.ipv4.tcp_wmem's maximum, 4 MiB). 0 keeps the system's
  // autotuning. Tests shrink it so a client that never reads fills it quickly.
  int socket_send_buffer = 256 * 1024;
  // TCP_NOTSENT_LOWAT for accepted sockets: at most this many bytes the
  // kernel has not sent yet; a write past them waits, and frames wait in the
  // connection's queue (latest wins, staleness bound) instead of the kernel's.
  // 0 keeps the system's setting (no limit).
  int socket_unsent_bytes = 16 * 1024;
  // A subscription's staleness bound when it asks for none (Subscribe.max_staleness_ms 0).
  std::chrono::milliseconds default_max_staleness{100};
  // Admission against what the server can send (docs/protocol.md,
  // "Admission"): the frames per second all subscriptions together may ask
  // for, each weighed by what its kind of frame costs (Admission::send_cost). A
  // subscription that would pass it is refused with RESOURCE_EXHAUSTED.
  // 0: no limit (load tests that mean to overload). The default is what one
  // I/O thread held at p99 <= 2 ms on the reference 2-core machine, in own
  // TCP streams' frames (docs/performance.md); measure yours with gmr-load.
  double send_budget = 108000;
  // Bytes of float forward kinematics kept for streams to share
  // (docs/performance.md, "FK blocks"): frames are computed 16 at a time, for
  // every stream that plays them; past this the least recently used go.
  // 0: none kept, each stream's frame computed on its own.
  std::size_t fk_cache_bytes = std::size_t{32} << 20;
  // Measure the budget at start instead (gmr-server's default, --send-budget
  // auto): send_budget becomes the reference figure scaled by how fast this
  // machine sends (server/src/calibrate.h), logged with the measurement.
  bool calibrate_send_budget = false;
  // How far a stream may fall behind its schedule (a stalled server) and
  // still catch up frame by frame; beyond it playback jumps to the frame due
  // now. Tests raise it so that a slow (sanitizer) build still sends every frame.
  std::chrono::milliseconds max_catch_up{250};
  // Own streams start on a grid of their period (StreamClock,
  // streams/stream_clock.h): at rate R on one of ceil(1 / (R * grid)) evenly
  // spaced points, taken in turn, so streams of one rate tick in that many
  // evenly filled groups and their sends leave in that many bursts a period
  // (docs/performance.md, "Own streams on a grid"). A start, resume or seek
  // waits less than a period and at most 10 ms (or less than the grid, when
  // that is coarser). 0: each stream ticks from the moment it starts.
  std::chrono::microseconds tick_grid{2000};
  // How long a graceful stop waits for replies to drain before closing.
  std::chrono::milliseconds shutdown_grace{2000};
};

// The relay secret in `path` (--relay-secret-file; ServerConfig::relay_secret):
// its first line without surrounding blanks, at least kMinRelaySecret
// characters. An error says which file and why.
inline constexpr std::size_t kMinRelaySecret = 32;
Result<std::string> read_relay_secret(const std::string& path);

}  // namespace gmr::server
