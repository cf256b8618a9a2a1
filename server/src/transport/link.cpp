#include "transport/link.h"

#include <spdlog/spdlog.h>

#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "gmr/wire/framing.h"
#include "transport/connection_log.h"

namespace gmr::server {

ConnectionLimits connection_limits(const ServerConfig& cfg) {
  ConnectionLimits l;
  l.max_message_bytes = cfg.max_message_bytes;
  l.max_reply_queue_bytes = cfg.max_reply_queue_bytes;
  l.max_frame_bytes = cfg.max_frame_bytes_per_connection;
  l.frames_per_key = cfg.frames_per_subscription;
  l.idle_timeout = cfg.idle_timeout;
  l.handshake_timeout = cfg.handshake_timeout;
  l.heartbeat_interval = cfg.heartbeat_interval;
  l.write_timeout = cfg.write_timeout;
  l.congested_after = cfg.congested_after;
  l.socket_send_buffer = cfg.socket_send_buffer;
  l.socket_unsent_bytes = cfg.socket_unsent_bytes;
  return l;
}

void tune_socket(tcp::socket& socket, const ConnectionLimits& limits, std::uint64_t id) {
  boost::system::error_code ec;
  socket.set_option(tcp::no_delay(true), ec);
  if (limits.socket_send_buffer > 0) {
    socket.set_option(net::socket_base::send_buffer_size(limits.socket_send_buffer), ec);
  }
  if (limits.socket_unsent_bytes > 0) {
    // Bytes the kernel may hold that it has not sent: past them a write
    // waits, so frames wait in the connection's queue, where latest-wins and
    // the staleness bound apply, rather than in the kernel, where they would
    // reach a client that stalled seconds late (docs/protocol.md, "Staleness").
    const int lowat = limits.socket_unsent_bytes;
    if (::setsockopt(socket.native_handle(), IPPROTO_TCP, TCP_NOTSENT_LOWAT, &lowat, sizeof lowat) != 0) {
      spdlog::debug("conn {}: TCP_NOTSENT_LOWAT: {}", id, std::strerror(errno));
    }
  }
}

std::chrono::milliseconds watchdog_period(const ConnectionLimits& l, bool established) {
  using std::chrono::milliseconds;
  auto shortest = std::min({l.heartbeat_interval, l.idle_timeout, l.write_timeout});
  if (!established && l.handshake_timeout.count() > 0) shortest = std::min(shortest, l.handshake_timeout);
  return std::max(milliseconds(10), shortest / 4);
}

namespace {
// `t` rounded up to a multiple of a quarter of `period` (from the clock's epoch).
Clock::time_point round_up_to_grain(Clock::time_point t, Clock::duration period) {
  const Clock::duration grain = std::max<Clock::duration>(period / 4, std::chrono::milliseconds(1));
  return Clock::time_point((t.time_since_epoch() + grain - Clock::duration(1)) / grain * grain);
}
}  // namespace

Clock::time_point watchdog_due(const ConnectionLimits& l, bool established, Clock::time_point now) {
  const Clock::duration period = watchdog_period(l, established);
  return round_up_to_grain(now + period, period);
}

Clock::time_point watchdog_next(const LinkTimes& t, Clock::time_point last_write, bool ready, bool polled,
                                const ConnectionLimits& l, Clock::time_point now) {
  const Clock::duration period = watchdog_period(l, t.established);
  if (polled) return round_up_to_grain(now + period, period);
  using std::chrono::milliseconds;
  milliseconds reach = std::max(l.write_timeout, l.idle_timeout);
  for (const milliseconds m : {l.write_timeout, l.idle_timeout}) {
    if (m.count() > 0) reach = std::min(reach, m);
  }
  Clock::time_point next = now + std::max<Clock::duration>(period, reach);
  // A verdict is "longer than the limit": one tick of the clock past it.
  const auto consider = [&](Clock::time_point deadline, milliseconds limit) {
    if (limit.count() > 0) next = std::min(next, deadline + limit + Clock::duration(1));
  };
  if (!t.established) consider(t.started, l.handshake_timeout);
  consider(std::max(t.last_read, t.last_frames_written), l.idle_timeout);
  if (t.established && !t.holding) consider(t.last_held, l.idle_timeout);
  if (t.writing) consider(t.write_started, l.write_timeout);
  // No heartbeat goes out while a write is in flight, but one due later
  // still wakes the tick: the write (a heartbeat over TLS or WebSocket,
  // written asynchronously) is likely done by then.
  const Clock::time_point beat = last_write + l.heartbeat_interval + Clock::duration(1);
  if (ready && l.heartbeat_interval.count() > 0 && (!t.writing || beat > now)) next = std::min(next, beat);
  return round_up_to_grain(std::max(next, now + milliseconds(1)), period);
}

std::string watchdog_verdict(const LinkTimes& t, const ConnectionLimits& lim, Clock::time_point now, std::uint64_t id) {
  if (!t.established && lim.handshake_timeout.count() > 0 && now - t.started > lim.handshake_timeout) {
    log_connection(spdlog::level::warn, "conn {}: no Hello within {} ms", id, lim.handshake_timeout.count());
    return "no Hello in time";
  }
  // A client that only listens to a subscription is not idle while its
  // frames are written: a dead one stops taking them, and the write timeout
  // below closes it. Heartbeats the server writes do not count.
  if (now - t.last_read > lim.idle_timeout && now - t.last_frames_written > lim.idle_timeout) {
    log_connection(spdlog::level::warn, "conn {}: idle for more than {} ms", id, lim.idle_timeout.count());
    return "idle timeout";
  }
  // Heartbeats alone do not keep a slot: a connection that holds nothing
  // and has made no request for the idle timeout goes (before, anonymous
  // heartbeating connections from a few addresses held every slot).
  if (t.established && !t.holding && now - t.last_held > lim.idle_timeout) {
    spdlog::debug("conn {}: no view or source held and no request for {} ms", id, lim.idle_timeout.count());
    return "idle timeout: no view or source held";
  }
  if (t.writing && now - t.write_started > lim.write_timeout) {
    log_connection(spdlog::level::warn, "conn {}: a write made no progress for {} ms: the client is not reading", id,
                   lim.write_timeout.count());
    return "write timeout";
  }
  return {};
}

std::string heartbeat_message() {
  pb::ServerMessage hb;
  hb.mutable_heartbeat()->set_client_time_ns(0);
  return wire::frame_message(hb).value();
}

}  // namespace gmr::server
