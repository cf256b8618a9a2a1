#include "http/metrics.h"

#include <prometheus/client_metric.h>
#include <prometheus/metric_family.h>
#include <prometheus/text_serializer.h>

#include <map>
#include <sstream>

#include "transport/connection_log.h"

namespace gmr::server {

namespace {

using prometheus::ClientMetric;
using prometheus::MetricFamily;
using prometheus::MetricType;

// Seconds: from 10 us (a request, a frame on an idle loopback) to 1 s.
const prometheus::Histogram::BucketBoundaries kLatencyBuckets = {1e-5, 2.5e-5, 5e-5,   1e-4, 2.5e-4, 5e-4, 1e-3, 2.5e-3,
                                                                 5e-3, 1e-2,   2.5e-2, 5e-2, 0.1,    0.25, 1.0};

// Families built from the server's state at scrape time.
class Families {
 public:
  // One sample of family `name` (made on first use, with `help` and `type`).
  void add(const std::string& name, const std::string& help, MetricType type, double value,
           std::vector<ClientMetric::Label> labels = {}) {
    auto [it, fresh] = index_.try_emplace(name, families_.size());
    if (fresh) families_.push_back(MetricFamily{name, help, type, {}});
    ClientMetric m;
    m.label = std::move(labels);
    if (type == MetricType::Counter) {
      m.counter.value = value;
    } else {
      m.gauge.value = value;
    }
    families_[it->second].metric.push_back(std::move(m));
  }
  std::vector<MetricFamily>& families() { return families_; }

 private:
  std::vector<MetricFamily> families_;
  std::map<std::string, std::size_t> index_;
};

std::string code_label(pb::ErrorCode code) {
  std::string name = pb::ErrorCode_Name(code);
  constexpr std::string_view kPrefix = "ERROR_CODE_";
  if (name.rfind(kPrefix, 0) == 0) name.erase(0, kPrefix.size());
  return name.empty() ? std::to_string(static_cast<int>(code)) : name;
}

}  // namespace

Metrics::Metrics()
    : registry_(std::make_shared<prometheus::Registry>()),
      tick_lateness_(kLatencyBuckets),
      frame_wait_tcp_(kLatencyBuckets),
      frame_wait_ws_(kLatencyBuckets) {
  requests_ = &prometheus::BuildCounter()
                   .Name("gmr_requests_total")
                   .Help("Requests answered, by kind (heartbeats not counted)")
                   .Register(*registry_);
  request_errors_ = &prometheus::BuildCounter()
                         .Name("gmr_request_errors_total")
                         .Help("Requests refused, by the protocol's error code")
                         .Register(*registry_);
  http_responses_ = &prometheus::BuildCounter()
                         .Name("gmr_http_responses_total")
                         .Help("HTTP responses (the viewer's files, /metrics, /healthz, /readyz), by status")
                         .Register(*registry_);
  request_seconds_ = &prometheus::BuildHistogram()
                          .Name("gmr_request_duration_seconds")
                          .Help("Time the server took to answer a request")
                          .Register(*registry_)
                          .Add({}, kLatencyBuckets);
}

void Metrics::request(std::string_view kind, Clock::duration took, pb::ErrorCode code) {
  requests_->Add({{"request", std::string(kind)}}).Increment();
  request_seconds_->Observe(std::chrono::duration<double>(took).count());
  if (code != pb::ERROR_CODE_UNSPECIFIED) request_errors_->Add({{"code", code_label(code)}}).Increment();
}

void Metrics::unparsable_request() {
  request_errors_->Add({{"code", code_label(pb::ERROR_CODE_BAD_REQUEST)}}).Increment();
}

void Metrics::http_response(unsigned status) { http_responses_->Add({{"status", std::to_string(status)}}).Increment(); }

LatencyHistogram& Metrics::frame_wait(std::string_view transport) {
  return transport == "websocket" ? frame_wait_ws_ : frame_wait_tcp_;
}

std::string Metrics::text(const MetricsSnapshot& s) const {
  Families f;
  using T = MetricType;
  f.add("gmr_ready", "1 once the library has loaded and the server takes clients", T::Gauge, s.ready ? 1 : 0);
  f.add("gmr_library_motions", "Motions in the library", T::Gauge, static_cast<double>(s.library_motions));

  // Connections and what their clients hold.
  auto count = [](const auto& map, std::string_view key) -> double {
    const auto it = map.find(key);
    return it == map.end() ? 0.0 : static_cast<double>(it->second);
  };
  for (const char* transport : {"tcp", "websocket"}) {
    f.add("gmr_connections", "Open client connections", T::Gauge, count(s.open_connections, transport),
          {{"transport", transport}});
  }
  for (const char* transport : {"tcp", "websocket"}) {
    f.add("gmr_connections_accepted_total", "Client connections accepted", T::Counter,
          count(s.accepted_connections, transport), {{"transport", transport}});
  }
  if (!s.lane_connections.empty()) {
    f.add("gmr_io_threads", "Threads the sockets' work runs on, the control loop included (--io-threads)", T::Gauge,
          static_cast<double>(s.lane_connections.size()));
    for (std::size_t lane = 0; lane < s.lane_connections.size(); ++lane) {
      f.add("gmr_io_thread_connections",
            "TCP connections whose socket work runs on each I/O thread (0: the control loop)", T::Gauge,
            static_cast<double>(s.lane_connections[lane]), {{"thread", std::to_string(lane)}});
    }
  }
  f.add("gmr_connections_refused_total", "Connections refused for a connection limit (TCP and WebSocket)", T::Counter,
        static_cast<double>(s.server.connections_refused));
  f.add("gmr_hellos_refused_total", "Hellos refused for their token", T::Counter,
        static_cast<double>(s.server.hellos_refused));
  f.add("gmr_log_lines_suppressed_total",
        "Log lines about connections left out past the server-wide budget (50 a second)", T::Counter,
        static_cast<double>(connection_log().suppressed_total()));
  f.add("gmr_views", "Views clients hold", T::Gauge, static_cast<double>(s.views));
  for (const char* transport : {"tcp", "udp", "websocket"}) {
    f.add("gmr_subscriptions", "Subscriptions, by the transport their frames take", T::Gauge,
          count(s.subscriptions, transport), {{"transport", transport}});
  }
  f.add("gmr_subscriptions_refused_total", "Subscriptions refused for the send budget", T::Counter,
        static_cast<double>(s.server.subscriptions_refused));
  f.add("gmr_publications_refused_total", "Live sources refused for the send budget (their declared rate)", T::Counter,
        static_cast<double>(s.server.publications_refused));
  f.add("gmr_streams", "Streams (one kinematics and one encoding per tick, shared by their subscribers)", T::Gauge,
        static_cast<double>(s.server.streams));
  f.add("gmr_committed_frames_per_second", "Frames per second all subscriptions ask for (against the send budget)",
        T::Gauge, s.server.committed_frames_per_second);
  f.add("gmr_send_budget_frames_per_second", "Frames per second subscriptions may ask for in all (0: no limit)",
        T::Gauge, s.server.send_budget);

  // Frames: computed and encoded once per stream, then sent per subscriber.
  f.add("gmr_frames_computed_total", "Forward-kinematics runs for streams", T::Counter,
        static_cast<double>(s.server.frames_computed));
  f.add("gmr_fk_blocks_computed_total", "Float-path kinematics computed for streams, 16 frames at a time", T::Counter,
        static_cast<double>(s.server.fk_blocks_computed));
  f.add("gmr_fk_block_hits_total", "Float-path frames streams read from kinematics already computed", T::Counter,
        static_cast<double>(s.server.fk_block_hits));
  f.add("gmr_fk_block_bytes", "Bytes of float-path kinematics kept for streams to share", T::Gauge,
        static_cast<double>(s.server.fk_block_bytes));
  f.add("gmr_frames_encoded_total", "Frame encodings (one per stream and tick)", T::Counter,
        static_cast<double>(s.server.frames_encoded));
  f.add("gmr_frames_skipped_total", "Frames skipped because the server was late (per subscriber)", T::Counter,
        static_cast<double>(s.server.frames_skipped));
  std::map<std::string, ConnectionCounters> by_transport;
  for (const auto& [transport, t] : s.connection_totals) {
    auto& own = by_transport[transport];
    own.frames_sent = t.frames_sent - t.udp_frames_sent;
    own.frames_dropped = t.frames_dropped - t.udp_frames_dropped;
    own.frames_stale = t.frames_stale;
    own.bytes_sent = t.bytes_sent;
    own.bytes_received = t.bytes_received;
    by_transport["udp"].frames_sent += t.udp_frames_sent;
    by_transport["udp"].frames_dropped += t.udp_frames_dropped;
  }
  for (const char* transport : {"tcp", "udp", "websocket"}) {
    const ConnectionCounters& t = by_transport[transport];
    f.add("gmr_frames_sent_total", "Frames sent to subscribers", T::Counter, static_cast<double>(t.frames_sent),
          {{"transport", transport}});
    f.add("gmr_frames_dropped_total", "Frames given up for a subscriber (a newer one replaced it, a bound, or its age)",
          T::Counter, static_cast<double>(t.frames_dropped), {{"transport", transport}});
  }
  for (const char* transport : {"tcp", "websocket"}) {
    const ConnectionCounters& t = by_transport[transport];
    f.add("gmr_frames_stale_total", "Of the frames dropped: waited past their subscriber's staleness bound", T::Counter,
          static_cast<double>(t.frames_stale), {{"transport", transport}});
    f.add("gmr_bytes_sent_total", "Bytes written to client connections", T::Counter, static_cast<double>(t.bytes_sent),
          {{"transport", transport}});
    f.add("gmr_bytes_received_total", "Bytes read from client connections", T::Counter,
          static_cast<double>(t.bytes_received), {{"transport", transport}});
  }
  f.add("gmr_bytes_sent_total", "Bytes written to client connections", T::Counter,
        static_cast<double>(s.udp_bytes_sent), {{"transport", "udp"}});  // with multicast: one UDP port
  // The tail per client: each open connection's own p99 wait (from its
  // stream's fan-out to the write), and across the clients the median, the
  // worst 1% and the worst of those: a burst that always makes the same
  // clients wait shows here, where the all-frames histogram hides it.
  const auto& p99 = s.client_frame_wait_p99;
  f.add("gmr_clients_sent_frames", "Open connections that have been sent frames (of a stream, not multicast)", T::Gauge,
        static_cast<double>(p99.size()));
  if (!p99.empty()) {
    const auto at = [&](double q) { return p99[static_cast<std::size_t>(q * static_cast<double>(p99.size() - 1))]; };
    const char* help =
        "Each client's p99 wait of its frames in the server (fan-out start to write, power-of-two buckets of "
        "microseconds), across the clients: the median, the worst 1% and the worst";
    f.add("gmr_client_frame_wait_p99_seconds", help, T::Gauge, at(0.5), {{"clients", "median"}});
    f.add("gmr_client_frame_wait_p99_seconds", help, T::Gauge, at(0.99), {{"clients", "worst_1_percent"}});
    f.add("gmr_client_frame_wait_p99_seconds", help, T::Gauge, p99.back(), {{"clients", "worst"}});
  }
  f.add("gmr_multicast_frames_sent_total", "Frames sent to the multicast group (once each, whatever the receivers)",
        T::Counter, static_cast<double>(s.multicast_frames_sent));
  f.add("gmr_live_sources", "Live sources: motions published by clients or relayed from replicas", T::Gauge,
        static_cast<double>(s.live_sources));
  f.add("gmr_live_frames_received_total", "Frames published to live sources and accepted", T::Counter,
        static_cast<double>(s.live_frames_received));
  f.add("gmr_live_frames_refused_total", "Frames published to live sources and refused (wrong size, not finite)",
        T::Counter, static_cast<double>(s.live_frames_refused));
  f.add("gmr_live_frames_over_rate_total",
        "Frames published to live sources faster than their declared rate, dropped (a burst of a second passes)",
        T::Counter, static_cast<double>(s.live_frames_over_rate));
  f.add("gmr_live_edit_replays_total",
        "Live views' edit lists replayed on published frames (views with equal edits share one replay a frame)",
        T::Counter, static_cast<double>(s.live_edit_replays));
  f.add("gmr_live_marker_points_missing_total", "Marker points the frames of live marker sources lacked", T::Counter,
        static_cast<double>(s.live_markers.missing));
  f.add("gmr_live_marker_parts_held_total",
        "Body parts of live marker sources that held their last pose for want of markers", T::Counter,
        static_cast<double>(s.live_markers.held));
  f.add("gmr_live_marker_points_outliers_total",
        "Marker points of live marker sources their part's fit left out as outliers (a swapped or stray label)",
        T::Counter, static_cast<double>(s.live_markers.outliers));
  f.add("gmr_live_marker_frames_unsolved_total",
        "Frames of live marker sources left unsolved (a body part not fitted yet)", T::Counter,
        static_cast<double>(s.live_markers.refused));
  f.add("gmr_library_reloads_total", "Library reloads (files under --library changed, or SIGHUP)", T::Counter,
        static_cast<double>(s.library_reloads));
  const char* kChangeHelp = "Library motions a reload added, read again (changed on disk) or removed";
  f.add("gmr_library_changes_total", kChangeHelp, T::Counter, static_cast<double>(s.library_changes.added),
        {{"change", "added"}});
  f.add("gmr_library_changes_total", kChangeHelp, T::Counter, static_cast<double>(s.library_changes.changed),
        {{"change", "changed"}});
  f.add("gmr_library_changes_total", kChangeHelp, T::Counter, static_cast<double>(s.library_changes.removed),
        {{"change", "removed"}});
  f.add("gmr_relay_announces_refused_total",
        "Live sources other replicas announced and this one refused (invalid, or past --max-remote-sources)",
        T::Counter, static_cast<double>(s.relay_announces_refused));
  f.add("gmr_relay_messages_refused_total",
        "Relay messages refused before they were read: no MAC or a wrong one (no relay secret), unparsable, "
        "out of sequence (replayed), or past the messages waiting for the server",
        T::Counter, static_cast<double>(s.server.relay_messages_refused));
  f.add("gmr_relay_connected", "1 when the relay reaches NATS (--nats), 0 while it does not or was refused", T::Gauge,
        s.server.relay_connected ? 1.0 : 0.0);
  f.add("gmr_record_bytes", "Bytes of the record budget that recordings under way hold (--max-record-total-bytes)",
        T::Gauge, static_cast<double>(s.server.record_bytes));
  f.add("gmr_recordings_refused_total", "Recordings refused: no room in the record budget", T::Counter,
        static_cast<double>(s.server.recordings_refused));
  f.add("gmr_recordings_cut_total",
        "Recordings that stopped growing at a bound (their own, the budget's, a write error)", T::Counter,
        static_cast<double>(s.server.recordings_cut));
  f.add("gmr_udp_datagrams_rejected_total", "UDP datagrams that were not a valid registration or confirm", T::Counter,
        static_cast<double>(s.server.udp_rejected));
  f.add("gmr_buffered_bytes", "Bytes all connections hold (replies, frames, writes, request bodies)", T::Gauge,
        static_cast<double>(s.server.buffered_bytes));
  f.add("gmr_view_bytes", "Motion bytes edited views and live sources own", T::Gauge,
        static_cast<double>(s.server.view_bytes));

  auto families = registry_->Collect();
  // The histograms filled per frame and per tick, without prometheus-cpp's lock.
  families.push_back(MetricFamily{"gmr_tick_lateness_seconds",
                                  "How late a stream's tick ran after it was due",
                                  T::Histogram,
                                  {tick_lateness_.collect()}});
  families.push_back(MetricFamily{
      "gmr_frame_wait_seconds",
      "From a frame queued for a connection to the end of the write that carried it (the oldest frame of each write)",
      T::Histogram,
      {frame_wait_tcp_.collect({{"transport", "tcp"}}), frame_wait_ws_.collect({{"transport", "websocket"}})}});
  for (auto& family : f.families()) families.push_back(std::move(family));
  std::ostringstream out;
  prometheus::TextSerializer().Serialize(out, families);
  return out.str();
}

}  // namespace gmr::server
