// Metrics: what gmr-server tells Prometheus on /metrics (docs/monitoring.md
// lists every family). Histograms and event counters live in a
// prometheus-cpp Registry and are updated where things happen; the figures
// the server keeps anyway (connections, streams, frames per transport) come
// in a MetricsSnapshot the server takes when a scrape asks, on the I/O thread.
#pragma once

#include <prometheus/counter.h>
#include <prometheus/family.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>

#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/markers/marker_frames.h"
#include "gmr/server/library.h"
#include "gmr/server/server.h"
#include "transport/latency_histogram.h"
#include "requests/services.h"
#include "transport/net.h"
#include "transport/outbox.h"

namespace gmr::server {

// The server's state as /metrics reports it, read at once on the control loop:
// what Server::stats() reports (without its sessions), and what only
// /metrics tells.
struct MetricsSnapshot {
  ServerStats server;
  bool ready = false;
  std::size_t library_motions = 0;
  std::map<std::string, std::size_t, std::less<>> open_connections;          // by transport
  std::map<std::string, std::uint64_t, std::less<>> accepted_connections;    // by transport
  std::map<std::string, ConnectionCounters, std::less<>> connection_totals;  // open and closed, by transport
  std::vector<std::size_t> lane_connections;                                 // per I/O thread (empty before start)
  std::vector<double> client_frame_wait_p99;  // per open connection sent frames (seconds), ascending
  std::size_t views = 0;
  std::map<std::string, std::size_t, std::less<>> subscriptions;  // by the transport their frames take
  std::uint64_t udp_bytes_sent = 0;
  std::uint64_t multicast_frames_sent = 0;
  std::size_t live_sources = 0;
  std::uint64_t live_frames_received = 0, live_frames_refused = 0, live_frames_over_rate = 0;
  std::uint64_t live_edit_replays = 0;
  MarkerFrameCounts live_markers;  // what live marker sources' solvers met
  std::uint64_t relay_announces_refused = 0;
  std::uint64_t library_reloads = 0;
  LibraryChanges library_changes;
};

class Metrics final : public RequestObserver {
 public:
  Metrics();

  // RequestObserver: requests answered and messages that did not parse
  // (counted as BAD_REQUEST).
  void request(std::string_view kind, Clock::duration took, pb::ErrorCode code) override;
  void unparsable_request() override;
  // One HTTP response (not a WebSocket upgrade) with this status.
  void http_response(unsigned status);

  // How long frames waited in a connection's queue before the write that
  // carried them completed, per transport ("tcp", "websocket").
  LatencyHistogram& frame_wait(std::string_view transport);
  // How late streams' ticks ran after their due time.
  LatencyHistogram& tick_lateness() { return tick_lateness_; }

  // The Prometheus text exposition format (0.0.4) of everything: the
  // registry's families, then the server's state `s`.
  std::string text(const MetricsSnapshot& s) const;

 private:
  std::shared_ptr<prometheus::Registry> registry_;
  prometheus::Family<prometheus::Counter>* requests_;
  prometheus::Family<prometheus::Counter>* request_errors_;
  prometheus::Family<prometheus::Counter>* http_responses_;
  prometheus::Histogram* request_seconds_;
  LatencyHistogram tick_lateness_;
  LatencyHistogram frame_wait_tcp_;
  LatencyHistogram frame_wait_ws_;
};

}  // namespace gmr::server
