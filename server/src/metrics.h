// Metrics: what gmr-server tells Prometheus on /metrics (docs/monitoring.md
// lists every family). Histograms and event counters live in a
// prometheus-cpp Registry and are updated where things happen; the figures
// the server keeps anyway (connections, streams, frames per transport) are
// read from its state when a scrape asks, on the I/O thread.
#pragma once

#include <prometheus/counter.h>
#include <prometheus/family.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>

#include <memory>
#include <string>
#include <string_view>

#include "gmr/server/server.h"
#include "net.h"

namespace gmr::server {

class Metrics {
 public:
  Metrics();

  // One request answered: its kind (the ClientMessage field's name), how
  // long the server took, and its error code (ERROR_CODE_UNSPECIFIED: none).
  void request(std::string_view kind, Clock::duration took, pb::ErrorCode code);
  // A message that did not parse as a ClientMessage (counted as BAD_REQUEST).
  void unparsable_request();
  // One HTTP response (not a WebSocket upgrade) with this status.
  void http_response(unsigned status);

  // How long frames waited in a connection's queue before the write that
  // carried them completed, per transport ("tcp", "websocket").
  prometheus::Histogram& frame_wait(std::string_view transport);
  // How late streams' ticks ran after their due time.
  prometheus::Histogram& tick_lateness() { return *tick_lateness_; }

  // The Prometheus text exposition format (0.0.4) of everything: the
  // registry's families, then the server's state read now. On the I/O thread.
  std::string text(Server::Impl& server) const;

 private:
  std::shared_ptr<prometheus::Registry> registry_;
  prometheus::Family<prometheus::Counter>* requests_;
  prometheus::Family<prometheus::Counter>* request_errors_;
  prometheus::Family<prometheus::Counter>* http_responses_;
  prometheus::Histogram* request_seconds_;
  prometheus::Histogram* tick_lateness_;
  prometheus::Histogram* frame_wait_tcp_;
  prometheus::Histogram* frame_wait_ws_;
};

}  // namespace gmr::server
